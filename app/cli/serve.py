"""`ltaa serve` and the server's maintenance commands."""

from __future__ import annotations

import os
from typing import Annotated

import typer

from app.cli.root import apply_migrations, cli
from app.config import get_settings


@cli.command()
def serve(
    host: Annotated[str | None, typer.Option(help="Bind address [default: LTAA_HOST]")] = None,
    port: Annotated[int | None, typer.Option(help="Port [default: LTAA_PORT]")] = None,
) -> None:
    """Apply database migrations, then serve the HTTP API with uvicorn."""
    import uvicorn  # only this command needs the server

    if host is not None:
        # create_app reads LTAA_HOST to refuse an exposed address without API keys.
        os.environ["LTAA_HOST"] = host
    settings = get_settings()
    apply_migrations(settings)
    uvicorn.run(
        "app.asgi:create_app", factory=True, host=host or settings.host, port=port or settings.port
    )


@cli.command("reencrypt-webhook-secrets")
def reencrypt_webhook_secrets() -> None:
    """Re-encrypt every webhook secret under the first key of LTAA_SECRET_KEY (after a
    server key rotation: new key first, old key after it; then drop the old key)."""
    from app.store.db import make_engine, make_session_factory
    from app.webhooks.errors import SecretKeyError
    from app.webhooks.secret_box import SecretBox
    from app.webhooks.service import reencrypt_secrets

    settings = get_settings()
    apply_migrations(settings)
    raw = settings.secret_key.get_secret_value() if settings.secret_key else None
    engine = make_engine(settings.db_url)
    try:
        box = SecretBox.from_setting(raw, settings.data_dir)
        count = reencrypt_secrets(sessions=make_session_factory(engine), box=box)
    except SecretKeyError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(code=1) from None
    finally:
        engine.dispose()
    typer.echo(f"re-encrypted {count} webhook secret(s) under the first key")
