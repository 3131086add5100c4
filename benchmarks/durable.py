"""Measure durable runs the way the server executes them: the real RunWorker, the app tables
through SQLAlchemy (WAL, synchronous=NORMAL) and the compact SQLite checkpointer.
"""

from __future__ import annotations

import sqlite3
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from app.config import Settings
from app.domain.models import Instance
from app.runs import service
from app.runs.factory import make_worker
from app.runs.spec import RunSpec
from app.store import repository as repo
from app.store.db import make_engine, make_session_factory
from app.store.migrate import upgrade_head


@dataclass(frozen=True)
class DurableMeasure:
    n_tasks: int
    warmup_seconds: list[float]  # runs before the timed ones (first run of a fresh worker)
    seconds: list[float]  # wall time from create_run to the run's completion
    # CPU seconds of this process (all threads) over the same span: wall time well above it
    # means the run waited for a CPU other processes held, or for the disk.
    cpu_seconds: list[float]
    # Of the first run alone, in a fresh data directory:
    checkpoint_main_bytes: int  # the checkpoint file as the run left it
    checkpoint_wal_bytes: int  # its -wal file as the run left it
    checkpoint_after_wal_checkpoint: int  # the file after PRAGMA wal_checkpoint(TRUNCATE)
    app_db_bytes: int  # ltaa.db + its -wal as left (decisions, attempts, prompts, events)

    @property
    def per_task(self) -> float:
        return self.checkpoint_after_wal_checkpoint / self.n_tasks


def _size(path: Path) -> int:
    return path.stat().st_size if path.exists() else 0


def _wal(path: Path) -> Path:
    return path.with_name(path.name + "-wal")


def _checkpoint_wal(path: Path) -> None:
    """Fold the -wal into the file. Our own connection: the worker is idle between runs,
    and its saver's connection is an implementation detail."""
    conn = sqlite3.connect(str(path))
    try:
        busy, _, _ = conn.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchone()
    finally:
        conn.close()
    if busy:
        raise RuntimeError(f"could not checkpoint the WAL of {path}: a reader held it")


def measure_durable(
    instance: Instance, *, mode: str = "balanced", runs: int = 1, warmup: int = 0
) -> DurableMeasure:
    """warmup + runs rules runs, one after another, in one fresh data directory."""
    with tempfile.TemporaryDirectory(prefix="ltaa-bench-") as tmp:
        settings = Settings(data_dir=Path(tmp), auto_resume=False)
        upgrade_head(settings.db_url)
        engine = make_engine(settings.db_url)
        sessions = make_session_factory(engine)
        worker = make_worker(settings=settings, sessions=sessions)
        cp = Path(settings.checkpoint_file)
        db = Path(tmp) / "ltaa.db"
        times: list[float] = []
        cpu: list[float] = []
        sizes: tuple[int, int, int, int] | None = None
        try:
            for _ in range(warmup + runs):
                spec = RunSpec.for_instance(instance, mode=mode, reasoner="rules")
                start, cpu_start = time.perf_counter(), time.process_time()
                run = service.create_run(
                    sessions=sessions, worker=worker, settings=settings, spec=spec
                )
                worker.wait(run.id)
                times.append(time.perf_counter() - start)
                cpu.append(time.process_time() - cpu_start)
                with sessions() as session:
                    stored = repo.get_run(session=session, run_id=run.id)
                    status = stored.status if stored is not None else "missing"
                if status != "completed":
                    raise RuntimeError(f"benchmark run ended {status}, not completed")
                if sizes is None:
                    main, wal = _size(cp), _size(_wal(cp))
                    app = _size(db) + _size(_wal(db))
                    _checkpoint_wal(cp)
                    sizes = (main, wal, _size(cp), app)
        finally:
            worker.close()
            engine.dispose()
    assert sizes is not None
    return DurableMeasure(instance.n_tasks, times[:warmup], times[warmup:], cpu[warmup:], *sizes)


@dataclass(frozen=True)
class StorageMeasure:
    """Checkpoint storage of one durable run, sampled while it ran."""

    n_tasks: int
    seconds: float
    samples: int
    peak_bytes: int  # largest file + -wal seen
    peak_file_bytes: int
    peak_wal_bytes: int
    final_bytes: int  # file + -wal once the run completed


class _Sampler:
    """Samples a checkpoint file's size (file + -wal) on its own thread until stopped."""

    def __init__(self, path: Path, interval_s: float) -> None:
        self.path, self.interval_s = path, interval_s
        self.samples = 0
        self.peak = self.peak_file = self.peak_wal = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="storage-sampler", daemon=True)

    def _loop(self) -> None:
        while not self._stop.wait(self.interval_s):
            self.sample()

    def sample(self) -> None:
        main, wal = _size(self.path), _size(_wal(self.path))
        self.samples += 1
        self.peak = max(self.peak, main + wal)
        self.peak_file = max(self.peak_file, main)
        self.peak_wal = max(self.peak_wal, wal)

    def __enter__(self) -> _Sampler:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()
        self.sample()


def measure_storage(
    instance: Instance, *, mode: str = "balanced", interval_s: float = 0.05
) -> StorageMeasure:
    """One rules run in a fresh data directory, the checkpoint file sampled as it runs."""
    with tempfile.TemporaryDirectory(prefix="ltaa-bench-") as tmp:
        settings = Settings(data_dir=Path(tmp), auto_resume=False)
        upgrade_head(settings.db_url)
        engine = make_engine(settings.db_url)
        sessions = make_session_factory(engine)
        worker = make_worker(settings=settings, sessions=sessions)
        cp = Path(settings.checkpoint_file)
        try:
            spec = RunSpec.for_instance(instance, mode=mode, reasoner="rules")
            with _Sampler(cp, interval_s) as sampler:
                start = time.perf_counter()
                run = service.create_run(
                    sessions=sessions, worker=worker, settings=settings, spec=spec
                )
                worker.wait(run.id)
                seconds = time.perf_counter() - start
            with sessions() as session:
                stored = repo.get_run(session=session, run_id=run.id)
                if stored is None or stored.status != "completed":
                    raise RuntimeError("storage benchmark run did not complete")
            final = _size(cp) + _size(_wal(cp))
        finally:
            worker.close()
            engine.dispose()
    return StorageMeasure(
        instance.n_tasks,
        seconds,
        sampler.samples,
        sampler.peak,
        sampler.peak_file,
        sampler.peak_wal,
        final,
    )
