"""A real server (scripts/serve.sh under uvicorn) and a real headless Chromium (Debian's
package, driven by Playwright) for the console's browser tests.

`playwright install` cannot download a browser here; the tests launch /usr/bin/chromium,
which .ci/run installs when it is missing.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import urlsplit

import pytest
from playwright.sync_api import Browser, BrowserContext, Page, Playwright, Request, sync_playwright

from tests.support.polling import eventually
from tests.support.server import Server

CHROMIUM = Path("/usr/bin/chromium")
SUPERVISOR_KEY = "browser-supervisor-key-7Gm2Qx9Lp4"
CLIENT_KEY = "browser-client-key-4Rt8Vn1Kc6Zs"
KEYS = f"{SUPERVISOR_KEY}:supervisor,{CLIENT_KEY}:client"

# Browser tests are marked where they are (tests/console/test_*_browser.py).


# Package scope, not session: the sync API keeps an event loop running in the main thread
# while it is open, and later tests (tests/runs/test_load.py) call asyncio.run there.
@pytest.fixture(scope="package")
def playwright() -> Iterator[Playwright]:
    if not CHROMIUM.exists():
        pytest.fail(f"{CHROMIUM} is missing: apt-get install -y chromium (.ci/run does this)")
    with sync_playwright() as p:
        yield p


@pytest.fixture(scope="package")
def browser(playwright: Playwright) -> Iterator[Browser]:
    browser = playwright.chromium.launch(executable_path=str(CHROMIUM), args=["--no-sandbox"])
    yield browser
    browser.close()


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    srv = Server(tmp_path_factory.mktemp("console"), env={"LTAA_API_KEYS": KEYS})
    srv.start()
    yield srv
    srv.stop()


@dataclass
class RequestLog:
    urls: list[str] = field(default_factory=list)

    def record(self, request: Request) -> None:
        self.urls.append(request.url)

    def outside_loopback(self) -> list[str]:
        out = []
        for url in self.urls:
            parts = urlsplit(url)
            if parts.scheme in ("data", "about", "blob"):
                continue
            if parts.hostname not in ("127.0.0.1", "localhost", "::1"):
                out.append(url)
        return out


@pytest.fixture
def requests_seen() -> RequestLog:
    return RequestLog()


@pytest.fixture
def context(browser: Browser, requests_seen: RequestLog) -> Iterator[BrowserContext]:
    ctx = browser.new_context(accept_downloads=True)
    ctx.on("request", requests_seen.record)
    yield ctx
    ctx.close()


@pytest.fixture
def page(context: BrowserContext) -> Page:
    page = context.new_page()
    page.set_default_timeout(15_000)
    return page


def sign_in(page: Page, server: Server, key: str = SUPERVISOR_KEY, then: str = "/console") -> None:
    page.goto(f"{server.url}/console/login?next={then}")
    page.get_by_label("Supervisor API key").fill(key)
    # Until the page the form leads to has loaded: a check run at once (axe, a locator on
    # the old page) would race the navigation on a busy machine.
    with page.expect_navigation():
        page.get_by_role("button", name="Sign in").click()


def start_run(server: Server, **body: object) -> str:
    instance: dict[str, object] = {} if "tasks" in body else {"scenario": "baseline"}
    with server.client() as c:
        created = c.post(
            "/runs",
            json={**instance, "mode": "balanced", "reasoner": "rules", **body},
            headers={"X-API-Key": CLIENT_KEY},
        )
    assert created.status_code == 202, created.text
    return str(created.json()["id"])


def wait_status(
    server: Server, run_id: str, status: str = "completed", timeout: float = 90
) -> None:
    with server.client() as c:
        eventually(
            lambda: c.get(f"/runs/{run_id}", headers={"X-API-Key": CLIENT_KEY}).json(),
            until=lambda state: state["status"] == status,
            timeout=timeout,
            what=f"run {run_id} became {status}",
        )


def tasks(n: int) -> dict[str, object]:
    """A request body of n tasks on the baseline robots' features: a run long enough to
    watch (the rules reasoner decides a task in a few milliseconds)."""
    features = [["heavy"], ["careful"], ["dexterous"], ["heavy", "careful"]]
    robots = [
        {"name": "heavy", "success": {"heavy": 0.95, "careful": 0.4, "dexterous": 0.3}},
        {"name": "precise", "success": {"heavy": 0.5, "careful": 0.9, "dexterous": 0.7}},
        {"name": "nimble", "success": {"heavy": 0.3, "careful": 0.6, "dexterous": 0.95}},
    ]
    return {
        "tasks": [
            {"id": f"T{i}", "name": f"task {i}", "features": features[i % 4]} for i in range(n)
        ],
        "robots": robots,
    }
