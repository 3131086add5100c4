"""The rates a revision plans with (docs/estimates.md#using-the-estimates): inherited `rates` and
`durations` (or the request's), and `use_learned {robots?}` changes, over the fleet the other
changes left.

The configured rates go on through a lineage: a parent that planned with learned ones
recorded its configured ones, and a `set_rates` change in the revision configures anew.
Learned and sampled rates are the site's estimates when the revision is made, never the
parent's numbers: a revision is a new plan, made with what the site knows now.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

from sqlalchemy.orm import Session

from app.domain.errors import DomainError
from app.domain.estimates import Basis, DurationSource, RateSource, configured_rates
from app.runs.spec import RunSpec
from app.store import site_repository as site_repo
from app.store.models import utcnow

USE_LEARNED = "use_learned"


def _learned_robots(changes: Sequence[Mapping[str, Any]], fleet: Sequence[str]) -> list[str] | None:
    """The robots `use_learned` changes name (every robot when one names none); None when
    there is no such change. An unknown robot is a 422 naming it."""
    named: list[str] = []
    found = False
    for i, change in enumerate(changes):
        if change["type"] != USE_LEARNED:
            continue
        found = True
        robots = change.get("robots")
        if not robots:
            return list(fleet)
        for j, robot in enumerate(robots):
            if robot not in fleet:
                raise DomainError(
                    f"changes.{i}.robots.{j}",
                    f"unknown robot '{robot}'; the fleet is {', '.join(fleet)}",
                    code="unknown_robot",
                )
            named.append(robot)
    return named if found else None


def _without_reconfigured(
    record: Mapping[str, Any] | None, changes: Sequence[Mapping[str, Any]]
) -> dict[str, Any] | None:
    """The parent's record less the rates this revision's `set_rates` configure anew."""
    if not record:
        return None
    robots = {r: dict(rates) for r, rates in record.get("robots", {}).items()}
    for change in changes:
        if change["type"] == "set_rates" and change["robot"] in robots:
            for feature in change["success"]:
                robots[change["robot"]].pop(feature, None)
    return {**record, "robots": robots}


def revision_spec(
    *,
    session: Session,
    spec: RunSpec,
    changes: Sequence[Mapping[str, Any]],
    rates: RateSource | None,
    durations: DurationSource | None,
    strength: float,
) -> tuple[RunSpec, list[dict[str, Any]]]:
    """The revision's spec with the rates it plans with, and the fleet changes that says
    (one per robot whose rates were learned or sampled)."""
    spec = replace(
        spec,
        rates=(rates or RateSource(spec.rates)).value,
        durations=(durations or DurationSource(spec.durations)).value,
        learned=_without_reconfigured(spec.learned, changes),
    )
    fleet = [str(r["name"]) for r in spec.instance_data["robots"]]
    only = _learned_robots(changes, fleet)
    source = RateSource(spec.rates)
    if source == RateSource.CONFIGURED and only is not None:
        source = RateSource.LEARNED
    elif source != RateSource.CONFIGURED:
        only = None  # the whole fleet learns
    if source == RateSource.CONFIGURED and spec.durations == DurationSource.CONFIGURED:
        robots = configured_rates(spec.instance_data["robots"], spec.learned)
        data = {**spec.instance_data, "robots": robots}
        return replace(spec, instance_data=data, learned=None), []
    as_of = utcnow().isoformat()
    counts = site_repo.site_counts(session=session, site=spec.site)
    spec = spec.with_site_estimates(
        counts, strength=strength, as_of=as_of, source=source, only=only
    )
    assert spec.learned is not None
    learned = []
    for robot, rates_of in spec.learned["robots"].items():
        bases = {r["basis"] for r in rates_of.values()}
        if bases & {Basis.LEARNED, Basis.SAMPLED, Basis.PRIOR}:
            learned.append(
                {
                    "robot": robot,
                    "change": f"{source.value}_rates",
                    "success": {f: r["used"] for f, r in rates_of.items()},
                }
            )
    return spec, learned
