"""The readers' entry points: a file's bytes to a `Draft`, the format named or detected."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

from app.exchange.draft import build_draft
from app.exchange.errors import ExchangeError
from app.exchange.model import Draft
from app.exchange.mspdi_read import read_mspdi_project
from app.exchange.xer_read import read_xer_project

Format = Literal["mspdi", "xer"]
FORMATS: tuple[Format, ...] = ("mspdi", "xer")
# What else people upload, told by its first bytes, so the error says what was found.
_SIGNATURES = (
    (
        b"\xd0\xcf\x11\xe0",
        "a binary MS Project .mpp file (an OLE container): save it from "
        "MS Project as XML (MSPDI) and import that",
    ),
    (b"PK\x03\x04", "a ZIP archive (an .xlsx or a zipped schedule?)"),
    (b"%PDF", "a PDF document"),
)
EXPECTED = "an MSPDI file (MS Project XML) or an XER file (Primavera P6)"


def read_mspdi(
    data: bytes,
    *,
    features_field: str | None = None,
    default_features: Sequence[str] | str | None = None,
) -> Draft:
    return build_draft(read_mspdi_project(data, features_field), default_features=default_features)


def read_xer(
    data: bytes,
    *,
    features_field: str | None = None,
    default_features: Sequence[str] | str | None = None,
) -> Draft:
    return build_draft(read_xer_project(data, features_field), default_features=default_features)


def _head(data: bytes) -> bytes:
    head = data[:4096]
    for bom in (b"\xef\xbb\xbf",):
        if head.startswith(bom):
            head = head[len(bom) :]
    return head.lstrip()


def found(data: bytes) -> str:
    """What the first bytes look like, for an error message."""
    head = _head(data)
    if not head:
        return "an empty body"
    for signature, what in _SIGNATURES:
        if data.startswith(signature):
            return what
    if head[:1] in (b"{", b"["):
        return "JSON (post it to /allocate or /runs as it is)"
    if head.startswith(b"<"):
        return "XML"
    text = head[:24].decode("utf-8", errors="replace")
    return f"text starting {text!r}"


def detect_format(data: bytes, content_type: str | None = None) -> Format:
    """The format of a file by its first bytes, else by its Content-Type; ExchangeError
    saying what was expected and what was found when neither tells."""
    head = _head(data)
    if head.startswith(b"ERMHDR"):
        return "xer"
    if head.startswith(b"<"):
        return "mspdi"
    media = (content_type or "").split(";")[0].strip().lower()
    if media in ("application/vnd.ms-project+xml", "application/xml", "text/xml"):
        return "mspdi"
    if media in ("application/x-xer", "application/vnd.primavera.xer"):
        return "xer"
    raise ExchangeError(
        f"expected {EXPECTED}; found {found(data)}. Name the format with ?format=mspdi|xer "
        "if the file is one of them",
        code="wrong_format",
    )


def read_schedule(
    data: bytes,
    *,
    format: Format | None = None,
    content_type: str | None = None,
    features_field: str | None = None,
    default_features: Sequence[str] | str | None = None,
) -> Draft:
    """A draft from a schedule file of the named format, or of the one its bytes show."""
    kind = format or detect_format(data, content_type)
    if kind not in FORMATS:
        raise ExchangeError(
            f"format {kind!r} is not one the service reads; use mspdi or xer",
            code="wrong_format",
            field="format",
        )
    if format is not None:
        # Named: the body must be that format; say what it is instead if it is not.
        head = _head(data)
        looks = "xer" if head.startswith(b"ERMHDR") else "mspdi" if head.startswith(b"<") else None
        if looks != kind:
            what = "an XER file" if looks == "xer" else found(data)
            wanted = "an XER file (Primavera P6)" if kind == "xer" else "an MSPDI file (XML)"
            raise ExchangeError(
                f"expected {wanted} as format={kind} says; found {what}",
                code="wrong_format",
            )
    reader = read_mspdi if kind == "mspdi" else read_xer
    try:
        return reader(data, features_field=features_field, default_features=default_features)
    except ExchangeError:
        raise
    except (ValueError, KeyError, IndexError, TypeError) as exc:
        # A value the readers did not foresee (a number that is not one, say): still the
        # file's fault, so a 422 naming it rather than a 500.
        raise ExchangeError(
            f"the {kind} file could not be read: {type(exc).__name__}: {exc}", code="malformed"
        ) from None
