"""The dispatcher: a background thread of the app (never the request path) that claims
due deliveries and sends them on a small thread pool, one attempt per claim."""

from __future__ import annotations

import logging
import os
import random
import socket
import threading
import time
import uuid
from concurrent.futures import ThreadPoolExecutor

import httpx
from sqlalchemy.orm import Session, sessionmaker

from app.config import Settings
from app.store.db import transaction
from app.store.models import utcnow
from app.store.webhook_models import WebhookSubscription
from app.webhooks import queue, signing
from app.webhooks.errors import SecretKeyError
from app.webhooks.queue import AttemptResult, Claimed
from app.webhooks.secret_box import SecretBox
from app.webhooks.sender import make_client, send
from app.webhooks.status import AttemptOutcome
from app.webhooks.targets import Resolver, static_resolver, system_resolver

log = logging.getLogger("ltaa.webhooks")


def dispatcher_id(name: str | None) -> str:
    return f"{name or socket.gethostname()}:{os.getpid()}:{uuid.uuid4().hex[:8]}"


def resolver_from(settings: Settings) -> Resolver:
    if settings.test_webhook_resolve:
        log.warning(
            "test seam on: LTAA_TEST_WEBHOOK_RESOLVE answers DNS for some webhook hosts (%s)",
            settings.test_webhook_resolve,
        )
        return static_resolver(settings.test_webhook_resolve)
    return system_resolver


class Dispatcher:
    def __init__(
        self,
        *,
        settings: Settings,
        sessions: sessionmaker[Session],
        box: SecretBox,
        resolver: Resolver | None = None,
    ) -> None:
        self._settings = settings
        self._sessions = sessions
        self._box = box
        self._resolver = resolver or resolver_from(settings)
        self.owner = dispatcher_id(settings.worker_name)
        self._rng = random.Random()
        self._pool = ThreadPoolExecutor(
            max_workers=settings.webhook_concurrency, thread_name_prefix="ltaa-webhook"
        )
        self._client: httpx.Client = make_client(settings.webhook_timeout_s)
        self._stopped = threading.Event()
        self._wake = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="ltaa-webhooks", daemon=True)
        self._in_flight = 0
        self._lock = threading.Lock()

    # -- lifecycle ---------------------------------------------------------------------

    def start(self) -> None:
        with transaction(self._sessions) as session:
            if session.get_bind().dialect.name == "sqlite":
                released = queue.release_all_claims(session=session)
                if released:
                    log.info(
                        "retrying %d webhook delivery(ies) in flight at the last stop", released
                    )
        self._thread.start()

    def wake(self) -> None:
        """Look for due deliveries now rather than at the next poll."""
        self._wake.set()

    def close(self) -> None:
        """Stop claiming; attempts in flight finish (bounded by the HTTP timeout)."""
        self._stopped.set()
        self._wake.set()
        if self._thread.is_alive():
            self._thread.join()
        self._pool.shutdown(wait=True)
        self._client.close()

    # -- the loop ----------------------------------------------------------------------

    def _loop(self) -> None:
        while not self._stopped.is_set():
            try:
                claimed = self.poll_once()
            except Exception:
                log.exception(
                    "webhook dispatch failed; retrying in %.1f s", self._settings.webhook_poll_s
                )
                claimed = 0
            if claimed == 0:
                self._wake.wait(self._settings.webhook_poll_s)
                self._wake.clear()

    def _free_slots(self) -> int:
        with self._lock:
            return self._settings.webhook_concurrency - self._in_flight

    def poll_once(self) -> int:
        """Claim up to the free slots and start their attempts; how many were claimed."""
        free = self._free_slots()
        if free <= 0 or self._stopped.is_set():
            return 0
        with transaction(self._sessions) as session:
            claimed = queue.claim_due(
                session=session,
                owner=self.owner,
                claim_s=self._settings.webhook_claim_s,
                limit=free,
            )
        for item in claimed:
            with self._lock:
                self._in_flight += 1
            self._pool.submit(self._attempt_and_release, item)
        return len(claimed)

    def _attempt_and_release(self, claimed: Claimed) -> None:
        try:
            self.attempt(claimed)
        except Exception:
            # The claim expires and the delivery is tried again; nothing is lost.
            log.exception("webhook delivery %s: attempt crashed", claimed.id)
        finally:
            with self._lock:
                self._in_flight -= 1
            self._wake.set()

    def attempt(self, claimed: Claimed) -> str | None:
        """Send one claimed delivery and record the attempt; the delivery's new status."""
        with self._sessions() as session:
            subscription = session.get(WebhookSubscription, claimed.subscription_id)
            url = subscription.url if subscription is not None else ""
            ciphertexts = queue.live_ciphertexts(
                session=session, subscription_id=claimed.subscription_id
            )
        body = claimed.payload.encode("utf-8")
        try:
            secrets = [self._box.decrypt(c) for c in ciphertexts]
        except SecretKeyError as exc:
            result = AttemptResult(AttemptOutcome.SECRET_ERROR, utcnow(), 0.0, error=str(exc))
        else:
            # Signed afresh for each attempt: receivers reject stale timestamps.
            headers = signing.headers(secrets, claimed.id, int(time.time()), body)
            result = send(
                self._client,
                url=url,
                body=body,
                headers=headers,
                resolver=self._resolver,
                allow_private=self._settings.webhook_allow_private,
                max_response_bytes=self._settings.webhook_max_response_bytes,
                timeout_s=self._settings.webhook_timeout_s,
            )
        delay = queue.next_delay(self._settings.webhook_retry_delays_s, claimed.attempt, self._rng)
        with transaction(self._sessions) as session:
            status = queue.record_attempt(
                session=session, claimed=claimed, owner=self.owner, result=result, delay_s=delay
            )
        level = logging.INFO if result.outcome is AttemptOutcome.DELIVERED else logging.WARNING
        log.log(
            level,
            "webhook %s attempt %d: %s%s -> %s",
            claimed.id,
            claimed.attempt,
            result.outcome.value,
            f" ({result.error})" if result.error else "",
            status or "claim lost to another process",
        )
        return status
