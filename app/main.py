"""The application factory: `uvicorn app.main:create_app --factory`."""

from __future__ import annotations

import importlib.metadata
import tomllib
from collections.abc import AsyncIterator
from contextlib import AsyncExitStack, asynccontextmanager
from pathlib import Path

from fastapi import FastAPI

from app.api.errors import BodySizeLimit, install_error_handlers
from app.api.routes import allocate, catalog, health
from app.config import Settings, get_settings


def app_version() -> str:
    try:
        return importlib.metadata.version("ltaa")
    except importlib.metadata.PackageNotFoundError:
        # Running from a checkout that was never pip-installed: pyproject.toml is the truth.
        pyproject = Path(__file__).resolve().parent.parent / "pyproject.toml"
        if pyproject.is_file():
            return str(tomllib.loads(pyproject.read_text())["project"]["version"])
        return "unknown"


@asynccontextmanager
async def lifespan(app: FastAPI) -> AsyncIterator[None]:
    settings: Settings = app.state.settings
    settings.data_dir.mkdir(parents=True, exist_ok=True)
    # Long-lived resources (database engine, checkpointer, run worker) are opened here and
    # register their cleanup on the stack, so shutdown closes them in reverse order even
    # when a later one fails to start.
    async with AsyncExitStack() as resources:
        app.state.resources = resources
        yield


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or get_settings()
    app = FastAPI(
        title="LTAA allocation service",
        summary="Phase-adaptive task allocation for heterogeneous construction robots",
        version=app_version(),
        lifespan=lifespan,
    )
    app.state.settings = settings
    install_error_handlers(app)
    app.add_middleware(BodySizeLimit, max_bytes=settings.max_body_bytes)
    for module in (health, catalog, allocate):
        app.include_router(module.router)
    return app
