"""Sign-offs as the record holds them: annotations of a completed run naming the signer, the
statement and the chain heads they signed (made by app.reviews.signoff)."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime

from sqlalchemy.orm import Session

from app.domain.annotations import AnnotationKind
from app.store import repository as repo
from app.store.models import RunAnnotation, as_utc


@dataclass(frozen=True)
class SignOff:
    signer: str
    at: datetime
    heads: dict[str, str | None]
    statement: str

    @classmethod
    def of(cls, row: RunAnnotation) -> SignOff:
        detail = row.detail or {}
        return cls(
            signer=str(detail["signer"]),
            at=as_utc(datetime.fromisoformat(detail["at"])),
            heads=dict(detail["heads"]),
            statement=str(detail["statement"]),
        )


def signoffs(*, session: Session, run_id: str) -> list[SignOff]:
    return [
        SignOff.of(row)
        for row in repo.annotations_page(
            session=session, run_id=run_id, kind=AnnotationKind.SIGNOFF.value
        )
    ]
