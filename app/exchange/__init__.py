"""Schedules in and out: the files site schedulers keep (docs/exchange.md).

Readers turn a Microsoft Project XML (MSPDI) or a Primavera P6 (XER) file into a draft
instance in the shape a request sends; the writer turns a plan into MSPDI that MS Project,
ProjectLibre and P6 open. Pure functions over bytes and domain objects, in Python (no Java
at run time; the tests check both directions against MPXJ). They import only the domain.
"""

from __future__ import annotations

from app.exchange.errors import ExchangeError
from app.exchange.model import Draft
from app.exchange.mspdi_write import write_mspdi
from app.exchange.rates import fill_rates
from app.exchange.read import detect_format, read_mspdi, read_schedule, read_xer

__all__ = [
    "Draft",
    "ExchangeError",
    "detect_format",
    "fill_rates",
    "read_mspdi",
    "read_schedule",
    "read_xer",
    "write_mspdi",
]
