"""Shared fixtures and helpers of the test suite."""

from __future__ import annotations

import os
import pty
import subprocess
from pathlib import Path
from typing import Any

from vgtarm._entry import single_threaded_blas

single_threaded_blas()  # as the vgtarm command does, before NumPy is imported


def _one_thread_per_worker() -> None:
    """Under ``pytest -n N`` with N workers filling the CPUs, each worker (and every command a test
    starts, which inherits the variable) runs the compiled GA and the model's batches on
    ``CPUs // N`` threads, as ``vgtarm``'s own worker processes do (``app/pool.py``, study
    workers: ``VGTARM_THREADS=1``). Two GA threads a worker on the two cores of CI made the GA's
    runs 2 to 20 times slower (its OpenMP threads wait for a core the other worker holds). The
    threads' results are tested bit for bit against one thread where the count is set explicitly
    (``test_threads.py``, ``test_ga_compiled.py``); a ``VGTARM_THREADS`` already set is kept."""
    workers = os.environ.get("PYTEST_XDIST_WORKER_COUNT", "")
    if not workers.isdigit() or int(workers) < 2 or os.environ.get("VGTARM_THREADS", "").strip():
        return
    try:
        cpus = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cpus = os.cpu_count() or 1
    os.environ["VGTARM_THREADS"] = str(max(1, cpus // int(workers)))


_one_thread_per_worker()

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import vgtarm  # noqa: E402
from vgtarm import compiler  # noqa: E402
from vgtarm.model.assembly import triangle_margins  # noqa: E402

#: Step of central finite differences: about eps**(1/3), the best balance of truncation and
#: round-off for first derivatives.
FD_STEP = 6e-6


@pytest.fixture(scope="session")
def robot() -> vgtarm.Robot:
    return vgtarm.load_robot()


EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def small_bone_of(near: float, cancellous: float, far: float) -> Any:
    """The femur's bone file with a 1 mm drill (a 0.5 mm point) and three layers of the given
    thicknesses (m): cortex, cancellous bone, cortex; short runs for the drilling tests."""
    from vgtarm.drilling import bone_from_dict, load_bone

    data = load_bone(EXAMPLES / "bones" / "femur_diaphysis.toml").to_dict()
    data["drill"]["diameter"] = 1.0e-3
    data["layers"] = [
        {"material": "cortical", "thickness": near},
        {"material": "cancellous", "thickness": cancellous},
        {"material": "cortical", "thickness": far},
    ]
    return bone_from_dict(data, source="small bone")


@pytest.fixture(scope="session")
def tight_robot(tmp_path_factory: pytest.TempPathFactory) -> vgtarm.Robot:
    """The paper robot with actuators whose legs' peak force (44 N) the drilling reaches."""
    text = (EXAMPLES / "paper_robot_with_actuators.toml").read_text()
    path = tmp_path_factory.mktemp("tight") / "tight.toml"
    path.write_text(text.replace("force = 200.0", "force = 44.0"))
    return vgtarm.load_robot(path)


def random_configurations(robot: vgtarm.Robot, n: int, seed: int = 0, margin: float = 0.01) -> np.ndarray:
    """``n`` configurations drawn uniformly inside the joint limits and assemblable with ``margin``."""
    rng = np.random.default_rng(seed)
    p = robot.parameters
    chosen: list[np.ndarray] = []
    while sum(len(c) for c in chosen) < n:
        q = rng.uniform(p.lower, p.upper, size=(2 * n, 7))
        ok = (triangle_margins(q, p.b, p.d) > margin).all(axis=1)
        chosen.append(q[ok])
    return np.concatenate(chosen)[:n]


def central_difference(f, x: np.ndarray, h: float = FD_STEP) -> np.ndarray:
    """Jacobian of ``f`` (batched, (n, k) -> (n, ...)) at ``x`` (n, k) by central differences.

    Returns ``(n, ..., k)``.
    """
    columns = []
    for i in range(x.shape[-1]):
        e = np.zeros(x.shape[-1])
        e[i] = h
        columns.append((f(x + e) - f(x - e)) / (2 * h))
    return np.stack(columns, axis=-1)


def assert_close(actual, desired, *, rtol: float = 1e-7, atol: float = 1e-9, what: str = "") -> None:
    """One tolerance helper for the suite: relative to the larger magnitude, plus an absolute floor."""
    np.testing.assert_allclose(actual, desired, rtol=rtol, atol=atol, err_msg=what)


def run_on_terminal(argv: list[str], env: dict[str, str]) -> tuple[int, bytes, bytes]:
    """Run ``argv`` with its standard error on a pseudo-terminal.

    Returns its exit status, its standard output and all the terminal showed until it closed.
    """
    leader, follower = pty.openpty()
    try:
        process = subprocess.Popen(argv, env=env, stdout=subprocess.PIPE, stderr=follower)
        os.close(follower)
        shown = b""
        while True:
            try:
                chunk = os.read(leader, 4096)
            except OSError:  # the terminal's other end closed
                break
            if not chunk:
                break
            shown += chunk
        out, _ = process.communicate(timeout=600)
    finally:
        os.close(leader)
    return process.returncode, out, shown


#: Default limit (s) of one ``make`` of a whole export (several files, sanitizers): as the model's build.
MAKE_TIME_LIMIT = 600.0


def make(folder: Path, *arguments: str) -> subprocess.CompletedProcess[str]:
    """``make ARGUMENTS`` in ``folder``, run as vgtarm runs its compilers (:func:`vgtarm.compiler.run`:
    under a time limit, ``$VGTARM_COMPILER_TIME_LIMIT`` or :data:`MAKE_TIME_LIMIT`, in a process
    group of its own killed with every child); what it did, as ``subprocess.run`` says it."""
    return compiler.run(["make", *arguments], cwd=folder, limit=MAKE_TIME_LIMIT, program="make")
