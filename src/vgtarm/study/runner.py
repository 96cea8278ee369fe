"""Run a study's points on Dask: a local cluster sized to the cores by default, or a given scheduler.

The runner is generic: it sends ``execute(inputs, files) -> (summary, error)`` for every point
not stored yet, and stores each result as it arrives (:class:`~vgtarm.study.store.Store`), on
the client, so workers need no shared file system. ``execute`` must be a module-level function
(workers import it by name) that returns a failed run as a summary with ``success`` False and an
error name instead of raising; ``check(inputs, files)`` refuses bad inputs before any run starts.
"""

from __future__ import annotations

import logging
import os
import signal
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..machine import usable_cpus
from .spec import Point, Study, Value
from .store import Store

#: ``execute(inputs, files) -> (summary, error)``: error "" for a successful run.
Execute = Callable[[Mapping[str, Value], Mapping[str, str]], tuple[dict[str, Any], str]]
Check = Callable[[Mapping[str, Value], Mapping[str, str]], None]


@dataclass(frozen=True)
class StudyRun:
    """What :func:`run_study` did: the table's rows, counts and the wall time (s)."""

    rows: list[dict[str, Any]]
    points: int
    skipped: int
    executed: int
    failed: int
    lost: tuple[str, ...]
    wall_time_s: float
    folder: Path


def check_study(study: Study, check: Check) -> list[Point]:
    """The study's points, after ``check`` accepted each distinct configuration (seed aside)."""
    points = study.points()
    seen: set[str] = set()
    for point in points:
        key = repr(sorted((k, v) for k, v in point.inputs.items() if k != "seed"))
        if key not in seen:
            seen.add(key)
            check(point.inputs, study.files)
    return points


def run_study(
    study: Study,
    out: str | Path,
    execute: Execute,
    *,
    check: Check | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: bool = True,
) -> StudyRun:
    """Run every point of ``study`` not yet stored in ``out``; write the results tables.

    Args:
        study: a validated study (:func:`~vgtarm.study.spec.load_study`).
        out: the results folder; runs already stored there are not run again.
        execute: runs one point on a worker (see the module's docstring).
        check: validates a point's inputs before any run starts (raises InputError/ConfigError).
        scheduler: address of a running Dask scheduler (``tcp://host:port``); None starts a
            local cluster of ``workers`` processes (default: one per core), one thread each.
        progress: show a progress bar (runs done, failed, time left).
    """
    if workers is not None and not (isinstance(workers, int) and workers >= 1):
        raise InputError(f"workers = {workers!r}: expected a whole number >= 1")
    start = time.perf_counter()
    points = check_study(study, check) if check is not None else study.points()
    store = Store(out)
    store.prepare()
    done = store.done()
    todo = [p for p in points if p.id not in done]
    failed = sum(1 for row in store.rows([p for p in points if p.id in done]) if not row.get("success"))
    lost: list[str] = []
    executed = 0
    if todo:
        from tqdm import tqdm

        with (
            _client(scheduler, workers) as client,
            tqdm(
                total=len(points), initial=len(points) - len(todo), unit="run", disable=not progress, desc=study.name
            ) as bar,
        ):
            from distributed import as_completed

            bar.set_postfix(failed=failed)
            files = client.scatter(dict(study.files), broadcast=True) if study.files else {}
            store.note("submit", [p.id for p in todo])
            futures = {
                client.submit(_run_point, execute, p.inputs, files, key=f"vgtarm-run-{p.id}", pure=False): p
                for p in todo
            }
            for future in as_completed(futures):
                point = futures[future]
                if future.status != "finished":
                    lost.append(point.id)  # a worker died too often: not stored, retried next time
                    continue
                summary, error = future.result()
                store.write({"id": point.id, "inputs": point.inputs, "summary": summary, "error": error})
                executed += 1
                failed += 0 if summary.get("success") else 1
                bar.set_postfix(failed=failed)
                bar.update(1)
    rows = store.rows(points)
    store.write_tables(rows)
    return StudyRun(
        rows,
        len(points),
        len(points) - len(todo),
        executed,
        failed,
        tuple(lost),
        time.perf_counter() - start,
        store.folder,
    )


def _run_point(execute: Execute, inputs: Mapping[str, Value], files: Mapping[str, str]) -> tuple[dict[str, Any], str]:
    return execute(inputs, files)


class _client:
    """A Dask client on ``scheduler``, or on a local cluster it starts and stops."""

    def __init__(self, scheduler: str | None, workers: int | None) -> None:
        self.scheduler, self.workers = scheduler, workers
        self.cluster: Any = None
        self.client: Any = None

    def __enter__(self) -> Any:
        from distributed import Client, LocalCluster

        if self.scheduler is not None:
            try:
                self.client = Client(self.scheduler, timeout=10)
            except OSError as exc:
                raise InputError(f"--scheduler {self.scheduler!r}: cannot connect: {exc}") from None
            return self.client
        # The worker processes start with SIGINT ignored (inherited through exec), so a terminal's
        # Ctrl-C, sent to the whole process group, reaches only this process, which stops them
        # (no traceback from each worker). Meanwhile SIGINT is also blocked here: a Ctrl-C during
        # the start stays pending (Linux never discards a blocked signal) and arrives below.
        posix = hasattr(signal, "pthread_sigmask") and threading.current_thread() is threading.main_thread()
        blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT}) if posix else set()
        handler = signal.signal(signal.SIGINT, signal.SIG_IGN) if posix else None
        try:
            self.cluster = LocalCluster(
                n_workers=self.workers or usable_cpus(),
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.ERROR,
                env={"VGTARM_THREADS": "1"},  # the workers fill the CPUs; no GA threads on top
            )
        finally:
            if posix:
                signal.signal(signal.SIGINT, signal.default_int_handler if handler is None else handler)
                signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
        self.client = Client(self.cluster)
        return self.client

    def __exit__(self, kind: type[BaseException] | None, *exc: object) -> None:
        if kind is not None and issubclass(kind, KeyboardInterrupt) and self.cluster is not None:
            self._kill_workers()  # Ctrl-C: the runs under way are lost anyway; do not wait for them
        if self.client is not None:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()

    def _kill_workers(self) -> None:
        """Kill the local cluster's worker processes at once (a graceful close waits a second or
        more for workers busy in compiled code); the close that follows then finds them gone."""
        for nanny in list(self.cluster.workers.values()):
            pid = getattr(nanny, "pid", None)  # the worker process a nanny watches
            if isinstance(pid, int) and pid > 0:
                try:
                    os.kill(pid, signal.SIGKILL)
                except OSError:  # already gone
                    pass
