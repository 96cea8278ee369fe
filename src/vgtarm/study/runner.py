"""Run a study's points on Dask: a local cluster sized to the cores by default, or a given scheduler.

The runner is generic: it sends ``execute(inputs, files) -> (summary, error)`` for every point
not stored yet, and stores each result as it arrives (:class:`~vgtarm.study.store.Store`), on
the client, so workers need no shared file system. ``execute`` must be a module-level function
(workers import it by name) that returns a failed run as a summary with ``success`` False and an
error name instead of raising; ``check(inputs, files)`` refuses bad inputs before any run starts.

Before the results folder is created, a given scheduler's address is checked
(:func:`scheduler_address`) and connected to within :data:`CONNECT_TIMEOUT`, or the local
cluster is started; a failure is one line and leaves no folder behind. The local cluster is
started from a thread that blocks SIGINT: Dask's threads, and the worker processes they start,
inherit the blocked signal (a signal mask survives ``exec``), so the terminal's Ctrl-C reaches
only this process, which stays interruptible during the start and stops the workers at once.
Dask's workers end by themselves, at once, when this process dies (a pipe from it closes).
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib.util
import ipaddress
import logging
import multiprocessing
import os
import re
import signal
import sys
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from multiprocessing import resource_tracker
from pathlib import Path
from typing import Any

from .. import checks
from ..errors import InputError, cut, shown
from ..machine import usable_cpus
from ..markup import html_table, mpl_text
from .spec import Point, Study, Value
from .store import Store, table_columns

#: ``execute(inputs, files) -> (summary, error)``: error "" for a successful run.
Execute = Callable[[Mapping[str, Value], Mapping[str, str]], tuple[dict[str, Any], str]]
Check = Callable[[Mapping[str, Value], Mapping[str, str]], None]

#: Longest wait (s) for a given scheduler to answer before the study is refused.
CONNECT_TIMEOUT = 10.0
#: Dask's protocols a scheduler may be reached by (``inproc://`` lives inside one process only).
SCHEDULER_SCHEMES = ("tcp", "tls", "ws", "wss")
_ADDRESS = re.compile(r"(?:(?P<scheme>[A-Za-z][A-Za-z0-9+.-]*)://)?(?P<host>\[[^\]]*\]|[^:/\[\]]*):(?P<port>[0-9]+)")
_LABEL = r"[A-Za-z0-9_](?:[A-Za-z0-9_-]{0,61}[A-Za-z0-9_])?"
_HOST_NAME = re.compile(rf"(?=.{{1,253}}$){_LABEL}(?:\.{_LABEL})*\.?")


#: Rows of a study shown in a notebook.
SHOWN_ROWS = 50


@dataclass(frozen=True)
class StudyRun:
    """What :func:`run_study` did: the table's rows, counts and the wall time (s).

    Attributes:
        rows: the results table, one row (a dict of column to value) per stored run, in the
            study's order: ``id``, the inputs, ``error`` and the run's summary figures.
        points: the study's points; ``skipped`` of them were stored before, ``executed`` run now.
        failed: stored runs whose ``success`` is False (a divergence, an unreachable path, ...).
        lost: ids of the points whose worker died: not stored, run again by the next call.
        wall_time_s: wall-clock time of the call (s).
        folder: the results folder.

    How it ended, as the other results say it (:attr:`success`, :attr:`status`, :attr:`message`),
    and the table as a DataFrame (:meth:`to_dataframe`) and a plot (:meth:`plot`).
    """

    rows: list[dict[str, Any]]
    points: int
    skipped: int
    executed: int
    failed: int
    lost: tuple[str, ...]
    wall_time_s: float
    folder: Path

    @property
    def success(self) -> bool:
        """Every point of the study is stored and its run succeeded."""
        return self.failed == 0 and not self.lost

    @property
    def status(self) -> str:
        """``"completed"`` (every run stored and successful), ``"incomplete"`` (runs lost with their
        workers: call again to finish them) or ``"runs_failed"`` (every run stored, some failed)."""
        if self.lost:
            return "incomplete"
        return "runs_failed" if self.failed else "completed"

    @property
    def message(self) -> str:
        """One line: the counts, and the first failed run's id and message if any."""
        line = (
            f"{self.points} runs: {self.skipped} already stored, {self.executed} run now, {self.failed} failed, "
            f"{len(self.lost)} lost"
        )
        failed = next((row for row in self.rows if not row.get("success")), None)
        if failed is not None:
            line += f" (first failed: {failed.get('id')}: {failed.get('message') or failed.get('error')})"
        if self.lost:
            line += "; run the study again to finish the lost runs"
        return line

    def to_dataframe(self) -> Any:
        """The results table as a :class:`pandas.DataFrame`, one row per stored run and the columns of
        ``results.csv`` (``id``, the inputs, ``error``, the summary figures; None where a run has no
        such figure). Needs pandas (``pip install "vgtarm[dataframe]"``)."""
        try:
            import pandas
        except ImportError:
            raise ImportError('to_dataframe() needs pandas: pip install "vgtarm[dataframe]"') from None
        return pandas.DataFrame(self.rows, columns=table_columns(self.rows))

    def plot(self, ax: Any = None, column: str = "max_tip_error_m") -> Any:
        """``column`` of every stored run against its place in the study, into ``ax`` (a new figure's
        axes when None); returns the axes. A figure in metres is shown in mm; failed runs are marked
        with crosses (with their figure up to the failure, where they have one).

        Raises :class:`InputError` for a column that is not a figure of the table, naming those that are.
        """
        numbers = [
            c for c in table_columns(self.rows) if any(_number(row.get(c)) for row in self.rows) and c != "success"
        ]
        if column not in numbers:
            raise InputError(f"column = {shown(column)}: expected a figure of the study's table: {', '.join(numbers)}")
        if ax is None:
            from matplotlib.figure import Figure

            ax = Figure(figsize=(6.0, 3.0), layout="constrained").add_subplot()
        scale, unit = (1e3, " (mm)") if column.endswith("_m") else (1.0, "")
        values = [float(row[column]) * scale if _number(row.get(column)) else float("nan") for row in self.rows]
        ok = [bool(row.get("success")) for row in self.rows]
        for wanted, marker, label in ((True, "o", "run"), (False, "x", "failed")):
            picked = [(i, v) for i, (v, good) in enumerate(zip(values, ok, strict=True)) if good == wanted]
            if picked:
                x, y = zip(*picked, strict=True)
                ax.plot(x, y, marker, markersize=4, linestyle="none", label=label)
        ax.set_xlabel("run (in the study's order)")
        ax.set_ylabel(mpl_text(column) + unit)
        if not all(ok):
            ax.legend(fontsize="small")
        return ax

    def _repr_html_(self) -> str:
        """The study in a notebook: its counts, and its table (the first :data:`SHOWN_ROWS` rows;
        the columns that vary between runs, then the figures), every cell escaped."""
        figures = ["max_tip_error_m", "rms_tip_error_m", "peak_force_n", "ga_activations", "success", "error"]
        inputs = sorted({key for row in self.rows for key in row} - set(figures))
        varied = [k for k in inputs if len({repr(row.get(k)) for row in self.rows}) > 1]
        columns = ["id", *[k for k in varied if k != "id"], *[f for f in figures if any(f in r for r in self.rows)]]
        rows: list[list[object]] = [
            [f"{row.get(c):.6g}" if isinstance(row.get(c), float) else row.get(c, "") for c in columns]
            for row in self.rows[:SHOWN_ROWS]
        ]
        more = f", the first {SHOWN_ROWS} shown" if len(self.rows) > SHOWN_ROWS else ""
        caption = (
            f"study in {self.folder}: {self.points} points, {self.executed} run, {self.skipped} done before, "
            f"{self.failed} failed, {len(self.lost)} lost, {self.wall_time_s:.1f} s{more}"
        )
        return html_table(columns, rows, caption=caption)


def _number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


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
        out: the results folder; runs already stored there are not run again. It must be new,
            empty or a study folder vgtarm wrote (:meth:`~vgtarm.study.store.Store.check`).
        execute: runs one point on a worker (see the module's docstring).
        check: validates a point's inputs before any run starts (raises InputError/ConfigError).
        scheduler: address of a running Dask scheduler (``tcp://host:port``); None starts a
            local cluster of ``workers`` processes (default: one per core), one thread each.
        progress: show a progress bar (runs done, failed, time left).
    """
    if workers is not None:
        checks.whole("workers", workers, 1)
    start = time.perf_counter()
    address = None if scheduler is None else scheduler_address(scheduler)
    store = Store(out)
    store.check()  # a folder vgtarm may not write in (a user's files of the study's names): before any run
    points = check_study(study, check) if check is not None else study.points()
    done = store.done()
    todo = [p for p in points if p.id not in done]
    failed = sum(1 for row in store.rows([p for p in points if p.id in done]) if not row.get("success"))
    lost: list[str] = []
    executed = 0
    if todo:
        from tqdm import tqdm

        with (
            _client(address, workers, announce=progress) as client,  # connected or started before the folder is made
            tqdm(
                total=len(points), initial=len(points) - len(todo), unit="run", disable=not progress, desc=study.name
            ) as bar,
        ):
            from distributed import as_completed

            store.prepare()
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
    store.prepare()  # every run stored already: the tables are written all the same
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


def scheduler_address(value: object) -> str:
    """``value`` checked as the address of a Dask scheduler, ``SCHEME://HOST:PORT`` (the scheme one
    of :data:`SCHEDULER_SCHEMES`, ``tcp://`` when left out); :class:`InputError` otherwise."""
    expected = (
        f"expected the address of a running Dask scheduler, SCHEME://HOST:PORT with SCHEME one of"
        f" {', '.join(SCHEDULER_SCHEMES)} (e.g. tcp://10.0.0.5:8786)"
    )
    match = _ADDRESS.fullmatch(value) if isinstance(value, str) else None
    if match is None:
        raise InputError(f"--scheduler {shown(value)}: {expected}")
    scheme, host, port = (match["scheme"] or "tcp").lower(), match["host"], int(match["port"])
    if scheme not in SCHEDULER_SCHEMES:
        raise InputError(f"--scheduler {shown(value)}: protocol {shown(scheme)}: {expected}")
    if host.startswith("["):
        try:
            ipaddress.IPv6Address(host[1:-1])
        except ValueError:
            raise InputError(
                f"--scheduler {shown(value)}: host {shown(host)} is not an IPv6 address: {expected}"
            ) from None
    elif not _HOST_NAME.fullmatch(host):
        raise InputError(f"--scheduler {shown(value)}: host {shown(host)} is not a host name or address: {expected}")
    if not 1 <= port <= 65535:
        raise InputError(f"--scheduler {shown(value)}: port {port} is not from 1 to 65535: {expected}")
    return f"{scheme}://{host}:{port}"


def connect(address: str, timeout: float | None = None) -> Any:
    """A Dask client of the scheduler at ``address`` (checked by :func:`scheduler_address`), or one
    :class:`InputError` line when no Dask scheduler answers there within ``timeout`` s (default
    :data:`CONNECT_TIMEOUT`).

    The scheduler is first asked who it is, the whole exchange bounded by ``timeout``: Dask's own
    client bounds the connection but then waits without end for a peer that never answers (an
    HTTP server waiting for a request line), and reads another server's reply as sizes of
    exabytes (a MemoryError)."""
    timeout = CONNECT_TIMEOUT if timeout is None else timeout
    fail = f"--scheduler {shown(address)}: no Dask scheduler answered within {timeout:g} s"
    try:
        identity = _run_apart(lambda: asyncio.run(asyncio.wait_for(_identify(address, timeout), timeout)))
    except TimeoutError:
        raise InputError(f"{fail}; expected the address of a running Dask scheduler") from None
    except MemoryError:  # another protocol's bytes read as Dask's frame sizes
        raise InputError(f"{fail}: the server there speaks another protocol than Dask's") from None
    except Exception as exc:  # noqa: BLE001 - refused, reset, not Dask
        raise InputError(
            f"{fail} ({type(exc).__name__}: {cut(str(exc), 120)}); expected the address of a running Dask scheduler"
        ) from None
    if not (isinstance(identity, Mapping) and identity.get("type") == "Scheduler"):
        raise InputError(f"{fail}: the server there is not a Dask scheduler")
    from distributed import Client

    try:
        return Client(address, timeout=timeout)
    except Exception as exc:  # noqa: BLE001 - it answered a moment ago: gone or refusing this client
        raise InputError(f"{fail} ({type(exc).__name__}: {cut(str(exc), 120)})") from None


def _run_apart(call: Callable[[], Any]) -> Any:
    """``call()`` here, or in a thread of its own when this thread runs an event loop already
    (``asyncio.run`` cannot be nested: a study run from a notebook)."""
    try:
        asyncio.get_running_loop()
    except RuntimeError:
        return call()
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(1) as apart:
        return apart.submit(call).result()


async def _identify(address: str, timeout: float) -> Any:
    """What the server at ``address`` says it is (Dask's ``identity`` call)."""
    from distributed.comm import connect as open_comm

    comm = await open_comm(address, timeout=timeout)
    try:
        await comm.write({"op": "identity", "reply": True})
        return await comm.read()
    finally:
        comm.abort()


class _client:
    """A Dask client on ``scheduler`` (an address checked by :func:`scheduler_address`), or on a
    local cluster it starts and stops."""

    def __init__(self, scheduler: str | None, workers: int | None, announce: bool = False) -> None:
        self.scheduler, self.workers, self.announce = scheduler, workers, announce
        self.cluster: Any = None
        self.client: Any = None
        self.level: int | None = None

    def __enter__(self) -> Any:
        from distributed import Client

        if self.scheduler is not None:
            self.client = connect(self.scheduler)
            return self.client
        # The local cluster's scheduler lives here: its notes on workers that went away (after a
        # Ctrl-C, as tracebacks at level INFO) are not the user's business, until the loop stops.
        logger = logging.getLogger("distributed")
        self.level = logger.level
        logger.setLevel(max(logging.ERROR, logger.getEffectiveLevel()))
        try:
            self.cluster = _start_local_cluster(self.workers or usable_cpus())
            if self.announce:
                print(dashboard_line(self.cluster), file=sys.stderr)
            try:
                self.client = Client(self.cluster)
            except BaseException:
                _kill_workers(self.cluster)
                self.cluster.close()
                raise
        except BaseException:
            logger.setLevel(self.level)
            raise
        return self.client

    def __exit__(self, kind: type[BaseException] | None, *exc: object) -> None:
        try:
            if kind is not None and issubclass(kind, KeyboardInterrupt) and self.cluster is not None:
                _kill_workers(self.cluster)  # Ctrl-C: the runs under way are lost anyway; do not wait for them
            if self.client is not None:
                self.client.close()
            if self.cluster is not None:
                self.cluster.close()
        finally:
            if self.level is not None:
                logging.getLogger("distributed").setLevel(self.level)


#: Where a local cluster serves its dashboard: this machine only, on a port the system chooses free.
DASHBOARD_ADDRESS = "127.0.0.1:0"


def dashboard_address() -> str | None:
    """:data:`DASHBOARD_ADDRESS` when Dask can serve a dashboard (it needs Bokeh), else None (none is
    started: Dask would otherwise only log that Bokeh is missing)."""
    return DASHBOARD_ADDRESS if importlib.util.find_spec("bokeh") is not None else None


def dashboard_line(cluster: Any) -> str:
    """The line printed when a local cluster starts: its dashboard's address, or why there is none."""
    link = getattr(cluster, "dashboard_link", None) if dashboard_address() is not None else None
    if link:
        return f"Dask dashboard of the local cluster: {link}"
    return "Dask dashboard: none (it needs Bokeh: pip install 'bokeh>=3.1'); the progress bar shows the runs"


def _start_local_cluster(workers: int) -> Any:
    """A local cluster of ``workers`` processes, one thread each, started from a thread that blocks
    SIGINT (see the module's docstring); a Ctrl-C while it starts is raised here at once, and the
    cluster is stopped as soon as it is up."""
    from distributed import LocalCluster

    if os.name == "posix":  # started now, outside the blocked thread: its start unblocks SIGINT there
        resource_tracker.ensure_running()
    lock = threading.Lock()
    outcome: dict[str, Any] = {}

    def start() -> None:
        try:
            cluster = LocalCluster(
                n_workers=workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address=dashboard_address(),
                silence_logs=logging.ERROR,
                env={"VGTARM_THREADS": "1"},  # the workers fill the CPUs; no GA threads on top
            )
        except BaseException as exc:  # noqa: BLE001 - handed to the waiting thread
            outcome["error"] = exc
            return
        with lock:
            if not outcome.get("abandoned"):
                outcome["cluster"] = cluster
                return
        _kill_workers(cluster)  # the caller was interrupted meanwhile
        cluster.close()

    posix = hasattr(signal, "pthread_sigmask")
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT}) if posix else set()
    try:
        thread = threading.Thread(target=start, name="vgtarm local cluster start", daemon=True)
        thread.start()  # inherits the blocked SIGINT
    finally:
        if posix:
            signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
    try:
        while thread.is_alive():
            thread.join(0.05)  # short waits: a Ctrl-C is raised between two
    except BaseException:
        with lock:
            outcome["abandoned"] = True
            cluster = outcome.pop("cluster", None)
        if cluster is not None:
            _kill_workers(cluster)
            cluster.close()
        else:  # still starting: its workers go now, not after this process (one just started would print)
            for child in multiprocessing.active_children():
                if child.name.startswith("Dask Worker process"):
                    with contextlib.suppress(OSError, ValueError):
                        child.kill()
        raise
    if "error" in outcome:
        raise outcome["error"]
    return outcome["cluster"]


def _kill_workers(cluster: Any) -> None:
    """Kill a local cluster's worker processes at once, each with every process below it (a
    graceful close waits a second or more for workers busy in compiled code); the close that
    follows then finds them gone."""
    import psutil

    for nanny in list(cluster.workers.values()):
        pid = getattr(nanny, "pid", None)  # the worker process a nanny watches
        if not (isinstance(pid, int) and pid > 0):
            continue
        with contextlib.suppress(psutil.Error):  # already gone, or not ours
            worker = psutil.Process(pid)
            tree = [worker, *worker.children(recursive=True)]  # found before the worker dies (then orphaned)
            for process in tree:
                with contextlib.suppress(psutil.Error):
                    process.kill()
