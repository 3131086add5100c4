"""What is recorded about a run after it finished: the kinds of row in its annotation chain.

A completed run's decisions and events never change; records made later (sign-offs now;
execution reports and `superseded_by` to come) go to a third, append-only chain of their
own, outside the heads a sign-off signs.
"""

from __future__ import annotations

from enum import StrEnum


class AnnotationKind(StrEnum):
    SIGNOFF = "signoff"
    EXECUTION_REPORTED = "execution_reported"
    SUPERSEDED_BY = "superseded_by"
