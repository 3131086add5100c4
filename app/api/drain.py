"""Begin draining the moment the server is told to stop, not once uvicorn gets round to it.

On SIGTERM/SIGINT uvicorn first waits for every open response to finish and only then runs
the lifespan shutdown that drains the run worker. An event stream (GET /runs/{id}/events)
lasts as long as its run, so one watcher kept the server, and the runs, going until the
run completed. While the lifespan is open, `drain_on_signal` chains onto uvicorn's handler:
the signal also schedules `on_signal` on the event loop (runs stop at their next node
boundary, streams end), so uvicorn's wait for open responses ends at once.
"""

from __future__ import annotations

import asyncio
import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType

SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextmanager
def drain_on_signal(on_signal: Callable[[], None]) -> Iterator[None]:
    """Within the running event loop: SIGINT/SIGTERM also call `on_signal` (on the loop).

    Only chains onto a handler already installed (uvicorn's); with the default handler,
    or off the main thread (TestClient), it changes nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    loop = asyncio.get_running_loop()
    previous = {sig: signal.getsignal(sig) for sig in SIGNALS}

    def handler(sig: int, frame: FrameType | None) -> None:
        # A signal handler may interrupt code holding any lock: only schedule the work
        # (call_soon_threadsafe is safe here), then let the server's own handler run.
        loop.call_soon_threadsafe(on_signal)
        chained = previous[signal.Signals(sig)]
        if callable(chained):
            chained(sig, frame)

    ours = [sig for sig, prev in previous.items() if callable(prev)]
    for sig in ours:
        signal.signal(sig, handler)
    try:
        yield
    finally:
        for sig in ours:
            if signal.getsignal(sig) is handler:
                signal.signal(sig, previous[sig])
