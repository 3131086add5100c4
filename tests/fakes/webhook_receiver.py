"""A real webhook receiver on loopback: records every request; scripted answers."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

from standardwebhooks import Webhook

from tests.support.polling import eventually


@dataclass
class Received:
    path: str
    headers: dict[str, str]
    body: bytes
    at: float  # when it was answered
    started: float  # when it arrived
    # What the library made of it on arrival (a payload, or the error it raised), when the
    # receiver knew the secret then; None otherwise.
    checked: dict[str, Any] | Exception | None = None


@dataclass
class Receiver:
    port: int
    received: list[Received] = field(default_factory=list)
    # status codes to answer, in order; once used up, 204 for everything
    script: list[int] = field(default_factory=list)
    delay_s: float = 0.0  # before answering: widens the window in which an attempt is in flight
    endless_body: bool = False  # answer 200 with a body that never ends (until disconnected)
    drip_s: float = 0.0  # with endless_body: the pause between chunks
    lock: threading.Lock = field(default_factory=threading.Lock)
    # The subscription's secret, once known: a real receiver verifies each request as it
    # arrives, so the library's five-minute timestamp tolerance is measured from arrival,
    # not from the end of a test that ran for longer than that.
    secret: str | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/hooks"

    def ids(self) -> set[str]:
        with self.lock:
            return {r.headers["webhook-id"] for r in self.received}

    def snapshot(self) -> list[Received]:
        with self.lock:
            return list(self.received)

    def wait_for(
        self, predicate: Callable[[list[Received]], bool], *, what: str, timeout: float = 30
    ) -> list[Received]:
        return eventually(
            self.snapshot,
            until=predicate,
            what=f"the receiver got {what}",
            timeout=timeout,
            interval=0.05,
        )

    def verified(self, secret: str) -> list[dict[str, Any]]:
        """Every request's body, each verified with the standardwebhooks library: on arrival
        where the receiver knew `secret` then (`receiver.secret`), else now."""
        wh = Webhook(secret)
        out = []
        for r in self.snapshot():
            checked = r.checked if self.secret == secret else None
            if isinstance(checked, Exception):
                raise checked
            out.append(checked if checked is not None else wh.verify(r.body, r.headers))
        return out


def _handler(receiver: Receiver) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        protocol_version = "HTTP/1.1"

        def do_POST(self) -> None:
            length = int(self.headers.get("content-length") or 0)
            body = self.rfile.read(length)
            if len(body) < length:
                # The sender died mid-request (a test's SIGKILL): the request never arrived
                # whole, so a real receiver's framework drops it unanswered, and the sender,
                # having no answer, sends it again. Not a delivery, and not one to verify.
                self.close_connection = True
                return
            started = time.time()
            if receiver.delay_s:
                time.sleep(receiver.delay_s)
            headers = {k.lower(): v for k, v in self.headers.items()}
            checked: dict[str, Any] | Exception | None = None
            if receiver.secret is not None:
                try:
                    checked = Webhook(receiver.secret).verify(body, headers)
                except Exception as exc:  # kept and raised by verified(): the test fails there
                    checked = exc
            with receiver.lock:
                receiver.received.append(
                    Received(self.path, headers, body, time.time(), started, checked)
                )
                code = receiver.script.pop(0) if receiver.script else 204
            if receiver.endless_body:
                self._endless()
                return
            self.send_response(code)
            self.send_header("content-length", "0")
            self.end_headers()

        def _endless(self) -> None:
            self.send_response(200)
            self.send_header("transfer-encoding", "chunked")
            self.end_headers()
            chunk = b"x" * (16 if receiver.drip_s else 8192)
            try:
                while True:
                    self.wfile.write(b"%x\r\n%s\r\n" % (len(chunk), chunk))
                    self.wfile.flush()
                    time.sleep(receiver.drip_s)
            except OSError:
                self.close_connection = True

        def log_message(self, *args: Any) -> None:
            pass

    return Handler


@contextmanager
def running_receiver(
    port: int = 0, script: list[int] | None = None, delay_s: float = 0.0
) -> Iterator[Receiver]:
    server = ThreadingHTTPServer(("127.0.0.1", port), _handler(Receiver(0)))
    receiver = Receiver(int(server.server_address[1]), script=list(script or []), delay_s=delay_s)
    server.RequestHandlerClass = _handler(receiver)
    thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.05})
    thread.start()
    try:
        yield receiver
    finally:
        server.shutdown()
        server.server_close()
        thread.join()
