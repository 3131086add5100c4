"""Server logs: one JSON object per line (LTAA_LOG_FORMAT=json, the default) or plain text.

Records carry the run id and task index of the work they were logged from: `bind()` and
`log_context()` put them in a context variable that a handler filter copies onto each
record. A LangGraph node runs in its own copy of the context, so a `bind()` inside a node
ends with the node.
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from contextvars import ContextVar
from types import MappingProxyType
from typing import Any, TextIO

from pythonjsonlogger.core import RESERVED_ATTRS
from pythonjsonlogger.json import JsonFormatter

from app.config import Settings

CONTEXT_FIELDS = ("run_id", "task_index")
_EMPTY: Mapping[str, Any] = MappingProxyType({})
_context: ContextVar[Mapping[str, Any]] = ContextVar("ltaa_log_context", default=_EMPTY)
_OURS = "_ltaa_handler"
# The LLM SDKs' HTTP clients (httpx2 under openai and anthropic, httpx under the webhook
# sender) log every request URL at INFO: a line per LLM call or delivery that says nothing
# the trace and the delivery rows do not. Their warnings and errors still come through.
QUIET_LIBRARIES = ("httpx", "httpx2", "openai", "anthropic")


def bind(**fields: Any) -> None:
    """Attach fields to every record logged later in the current context."""
    _context.set({**_context.get(), **fields})


@contextmanager
def log_context(**fields: Any) -> Iterator[None]:
    token = _context.set({**_context.get(), **fields})
    try:
        yield
    finally:
        _context.reset(token)


class ContextFilter(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        for name, value in _context.get().items():
            if not hasattr(record, name):  # an explicit `extra=` wins
                setattr(record, name, value)
        return True


class AccessFields(logging.Filter):
    """uvicorn's access records keep method, path and status in `args`: make them fields."""

    def filter(self, record: logging.LogRecord) -> bool:
        if (
            record.name == "uvicorn.access"
            and isinstance(record.args, tuple)
            and len(record.args) == 5
        ):
            client, method, path, _, status = record.args
            record.client, record.method, record.path, record.status = (
                client,
                method,
                path,
                status,
            )
        return True


class TextFormatter(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        line = super().format(record)
        context = " ".join(
            f"{name}={getattr(record, name)}"
            for name in CONTEXT_FIELDS
            if getattr(record, name, None) is not None
        )
        return f"{line} [{context}]" if context else line


class StderrHandler(logging.StreamHandler[TextIO]):
    """Writes to whatever sys.stderr is *now* (test runners swap it between tests)."""

    @property
    def stream(self) -> TextIO:
        return sys.stderr

    @stream.setter
    def stream(self, _: TextIO) -> None:
        pass


def make_formatter(fmt: str) -> logging.Formatter:
    if fmt == "json":
        return JsonFormatter(
            "{levelname}{name}{message}",
            style="{",
            timestamp="time",
            rename_fields={"levelname": "level", "name": "logger"},
            # uvicorn's ANSI-coloured copy of each message
            reserved_attrs=[*RESERVED_ATTRS, "color_message"],
        )
    return TextFormatter("%(asctime)s %(levelname)s %(name)s: %(message)s")


def configure_logging(settings: Settings) -> None:
    """Install the one handler on the root logger (replacing a previous one of ours)."""
    root = logging.getLogger()
    for old in [h for h in root.handlers if getattr(h, _OURS, False)]:
        root.removeHandler(old)
    handler = StderrHandler()
    setattr(handler, _OURS, True)
    handler.setFormatter(make_formatter(settings.log_format))
    handler.addFilter(ContextFilter())
    handler.addFilter(AccessFields())
    root.addHandler(handler)
    root.setLevel(settings.log_level)
    for name in QUIET_LIBRARIES:
        logging.getLogger(name).setLevel(logging.WARNING)
    if settings.log_format == "json":
        # uvicorn's own text handlers would interleave non-JSON lines: send its records
        # through the root handler instead.
        for name in ("uvicorn", "uvicorn.error", "uvicorn.access"):
            logger = logging.getLogger(name)
            logger.handlers.clear()
            logger.propagate = True
