"""The one error the exchange raises: a file that cannot be read as a schedule."""

from __future__ import annotations

from app.domain.errors import DomainError


class ExchangeError(DomainError):
    """A schedule file refused whole (nothing is half imported). A DomainError, so the HTTP
    layer answers 422 with `field` and the message; `code` tells the kinds apart:
    `wrong_format`, `unsafe_xml`, `malformed`, `link_cycle`."""

    QUERY = ("format", "features_field", "default_features")

    def __init__(self, message: str, *, code: str, field: str = "") -> None:
        super().__init__(field, message, code=code)
        # Where the fault is: the file (the body itself, or a part of it such as `links`),
        # or a query parameter that does not fit it.
        self.location = "query" if field in self.QUERY else "body"
