"""What POST /schedules/import and the console's import page (app.console.imports) call: a
site's schedule file read into a draft (app.exchange), its robots given a site's learned
rates when one is named (app.sites; docs/exchange.md#rates-from-a-site)."""

from __future__ import annotations

from typing import Literal

from sqlalchemy.orm import Session, sessionmaker

from app.exchange import Draft, fill_rates, read_schedule
from app.sites import service as site_service


def import_draft(
    data: bytes,
    *,
    sessions: sessionmaker[Session],
    prior_strength: float,
    format: Literal["mspdi", "xer"] | None,
    features_field: str | None,
    default_features: str | None,
    site: str | None,
    content_type: str | None = None,
) -> Draft:
    """The file's draft (an ExchangeError refuses it whole); with `site`, each robot the site
    knows by name takes its learned rates (an unknown site: SiteNotFoundForImport, a 404)."""
    draft = read_schedule(
        data,
        format=format,
        content_type=content_type,
        features_field=features_field,
        default_features=default_features,
    )
    if site is None:
        return draft
    rates = site_service.site_rates(sessions=sessions, site=site, strength=prior_strength)
    return fill_rates(draft, rates, site=site)
