"""The XER container: Primavera P6's tab-separated tables.

A line is a record: `ERMHDR` (the header), `%T name` (a table begins), `%F fields...`
(its columns), `%R values...` (a row), `%E` (the end). Written here, not taken from the
GPL-3.0 `xerparser`: the format is this small, and the tests read MPXJ's XER files.
"""

from __future__ import annotations

from app.exchange.errors import ExchangeError

Table = list[dict[str, str]]


def decode(data: bytes) -> str:
    """P6 writes XER in the exporting machine's code page; UTF-8 first, then Windows-1252
    (P6's usual), so a name with an accent reads as it was typed either way."""
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return data.decode("cp1252", errors="replace")


def parse_tables(data: bytes) -> dict[str, Table]:
    text = decode(data)
    if not text.startswith("ERMHDR"):
        raise ExchangeError(
            "expected a Primavera P6 XER file (its first line starts with ERMHDR); found "
            f"{text[:20]!r}",
            code="wrong_format",
        )
    tables: dict[str, Table] = {}
    rows: Table | None = None
    fields: list[str] = []
    for number, line in enumerate(text.splitlines(), start=1):
        kind, _, rest = line.partition("\t")
        if kind == "%T":
            rows = tables.setdefault(rest.strip(), [])
            fields = []
        elif kind == "%F":
            fields = rest.split("\t")
        elif kind == "%R":
            if rows is None or not fields:
                raise ExchangeError(
                    f"line {number} of the XER file is a row (%R) before any table (%T) or "
                    "field list (%F)",
                    code="malformed",
                )
            rows.append(dict(zip(fields, rest.split("\t"), strict=False)))
        elif kind == "%E":
            break
    return tables
