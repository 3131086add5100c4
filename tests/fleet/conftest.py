"""Until the tests mirror app/ (one fixture module for all), the API client fixtures."""

from tests.api.conftest import client, make_client, migrated_store

__all__ = ["client", "make_client", "migrated_store"]
