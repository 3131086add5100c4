"""XML parsed the safe way: no DTD, so no entity can read a file or expand without bound.

defusedxml's parser refuses a document type declaration before any entity in it is
defined, so an XXE file ("<!ENTITY x SYSTEM 'file:///etc/passwd'>") reads nothing and a
"billion laughs" file is refused at its first line instead of expanding to gigabytes.
MSPDI files never carry a DTD, so nothing a scheduler writes is refused.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

from defusedxml import DefusedXmlException
from defusedxml.ElementTree import fromstring

from app.exchange.errors import ExchangeError


def parse_xml(data: bytes) -> ET.Element:
    try:
        return fromstring(data, forbid_dtd=True, forbid_entities=True, forbid_external=True)
    except DefusedXmlException as exc:
        raise ExchangeError(
            "the XML declares a document type or entities (found "
            f"{type(exc).__name__}); MSPDI files have none, and they are refused because an "
            "entity can read files from the server or expand without bound. Save the "
            "schedule again from MS Project as XML",
            code="unsafe_xml",
        ) from None
    except ET.ParseError as exc:
        line, column = exc.position
        raise ExchangeError(
            f"the file is not well-formed XML (line {line}, column {column}): "
            f"{str(exc).split(':')[0]}",
            code="malformed",
        ) from None
