"""The console's browser tests: a real server and a real headless Chromium, from
tests/support/browser.py (package-scoped here, so the browser closes with this package)."""

from tests.support.browser import browser, context, page, playwright, requests_seen, server

__all__ = ["browser", "context", "page", "playwright", "requests_seen", "server"]
