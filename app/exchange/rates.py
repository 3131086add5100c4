"""A draft's robots given a site's learned rates (`?site=`, docs/exchange.md#rates-from-a-site).

Pure: the caller reads the site's estimates (app.sites over the store, or GET
/sites/{site}/estimates over HTTP) and hands them here as {robot: {feature: rate}}, so the
same rule fills the rates for the API, the console and the CLI.
"""

from __future__ import annotations

from collections.abc import Mapping

from app.exchange.model import Draft

# Rates are probabilities; more digits than this are noise from the posterior's arithmetic.
_DIGITS = 4


def fill_rates(draft: Draft, rates: Mapping[str, Mapping[str, float]], *, site: str) -> Draft:
    """The draft with each robot the site knows by name given the site's rates for the
    features its tasks need (a robot's other features are not the draft's business), and
    `source.rates` saying which robots and features were filled and which were not."""
    needed = {f for t in draft.tasks for f in t["features"]}
    robots = []
    filled: list[str] = []
    unknown: list[str] = []
    missing: dict[str, list[str]] = {}
    for robot in draft.robots:
        known = rates.get(robot["name"])
        if known is None:
            unknown.append(robot["name"])
            robots.append(robot)
            continue
        success = {
            f: round(float(rate), _DIGITS) for f, rate in sorted(known.items()) if f in needed
        }
        filled.append(robot["name"])
        gaps = sorted(needed - set(success))
        if gaps:
            missing[robot["name"]] = gaps
        robots.append({**robot, "success": {**robot["success"], **success}})
    source = {
        **draft.source,
        "rates": {
            "site": site,
            "filled": filled,
            "not_on_site": unknown,
            "features_without_rate": missing,
            "why": (
                "each robot the site knows by name takes the site's learned rate (posterior "
                "mean) for the draft's features; a robot or feature the site has no estimate "
                "for stays without a rate (it cannot be planned for that feature): fill those "
                "before posting the draft"
            ),
        },
    }
    return Draft(draft.tasks, robots, draft.start, source, draft.skipped)
