"""XML parsed the safe way: no DTD, so no entity can read a file or expand without bound.

defusedxml is the gate: its parser reads the prolog, where a document type declaration
must stand if there is one, with DTDs, entities and external references forbidden, so an
XXE file (`<!ENTITY x SYSTEM "file:///etc/passwd">`) reads nothing and a "billion laughs"
file is refused at its declaration instead of expanding to gigabytes. Once the root
element starts, no DTD can follow (expat refuses a misplaced one), and without a DTD
there are no entities but XML's five, so the C-accelerated ElementTree parser builds the
tree: defusedxml's own tree builder is pure Python, about three times slower, which put a
10,000-task MSPDI file (23 MB) over the 2 s budget (docs/exchange.md). MSPDI files never
carry a DTD, so nothing a scheduler writes is refused.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

from defusedxml import DefusedXmlException
from defusedxml.ElementTree import DefusedXMLParser

from app.exchange.errors import ExchangeError

_CHUNK = 64 * 1024


class _RootReached(Exception):
    """The prolog is over: the gate has seen all of it."""


class _StopAtRoot(ET.TreeBuilder):
    def start(self, tag: str, attrs: dict[str, str]) -> ET.Element:
        raise _RootReached


def _unsafe(exc: Exception) -> ExchangeError:
    return ExchangeError(
        "the XML declares a document type or entities (found "
        f"{type(exc).__name__}); MSPDI files have none, and they are refused because an "
        "entity can read files from the server or expand without bound. Save the "
        "schedule again from MS Project as XML",
        code="unsafe_xml",
    )


def _malformed(exc: ET.ParseError) -> ExchangeError:
    line, column = exc.position
    return ExchangeError(
        f"the file is not well-formed XML (line {line}, column {column}): {str(exc).split(':')[0]}",
        code="malformed",
    )


def _check_prolog(data: bytes) -> None:
    gate = DefusedXMLParser(
        target=_StopAtRoot(), forbid_dtd=True, forbid_entities=True, forbid_external=True
    )
    try:
        for offset in range(0, len(data), _CHUNK):
            gate.feed(data[offset : offset + _CHUNK])
        gate.close()
    except _RootReached:
        return
    except DefusedXmlException as exc:
        raise _unsafe(exc) from None
    except ET.ParseError as exc:
        raise _malformed(exc) from None


def parse_xml(data: bytes) -> ET.Element:
    _check_prolog(data)
    try:
        return ET.fromstring(data)
    except ET.ParseError as exc:
        raise _malformed(exc) from None
