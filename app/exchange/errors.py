"""The one error the exchange raises: a file that cannot be read as a schedule."""

from __future__ import annotations

from app.domain.errors import DomainError


class ExchangeError(DomainError):
    """A schedule file refused whole (nothing is half imported). A DomainError, so the HTTP
    layer answers 422 with `field` and the message; `code` tells the kinds apart:
    `wrong_format`, `unsafe_xml`, `malformed`, `link_cycle`."""

    def __init__(self, message: str, *, code: str, field: str = "body") -> None:
        super().__init__(field, message, code=code)
