"""The webhook endpoints' dependency: the app-table sessions, the secret box and the
dispatcher, opened by the app at start-up (app.main)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from fastapi import Depends, Request
from sqlalchemy.orm import Session, sessionmaker

from app.webhooks.dispatcher import Dispatcher
from app.webhooks.secret_box import SecretBox


@dataclass(frozen=True)
class WebhooksContext:
    sessions: sessionmaker[Session]
    box: SecretBox
    dispatcher: Dispatcher | None  # None while dispatch is off (LTAA_WEBHOOK_DISPATCH)


async def _context(request: Request) -> WebhooksContext:
    webhooks: WebhooksContext = request.app.state.webhooks
    return webhooks


WebhooksDep = Annotated[WebhooksContext, Depends(_context)]
