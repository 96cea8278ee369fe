"""Scaling benchmark over stacks of 1 to 10 modules (issue 13): compile, FK, dynamics, IK, CFC.

**The family.** ``family(k)`` is ``k`` identical modules of the paper's robot
(``examples/paper_robot.toml``: ``b = 0.15 m``, ``d = 0.10 m``, the same strokes, home and
friction), base first, with their operating planes alternating 0 and 90 degrees; odd modules carry
the paper's platform 1 (link 7), even ones its platform 2 (link 8). A twist joint follows every
second module and, when ``k`` is odd, the last one, so the tip can always turn: the inner twists are
a rotary stage 0.06 m high of 0.5 kg (as in ``examples/six_modules.toml``), the last twist is the
paper's (0.10 m to the tip, lumped with the paper's end-effector body, tool at the mount point).
``k`` modules have ``3 k + ceil(k / 2)`` joints (4, 7, 11, 14, ..., 35) and stand ``0.28 k`` m plus
the twists' heights high at home. ``family(2)`` is the paper's robot as a stack (every value of
``examples/paper_robot.toml``), the baseline of every ratio.

**Per module count** (each figure measured in this process):

- the **cold compile** of the stack's library (wall time, and the compiler's CPU time, which
  another load on the machine disturbs less) into a fresh temporary cache folder, so that
  ``~/.cache/vgtarm`` is neither used nor touched; the size of the generated C (written again
  apart, not timed) and of the library;
- batched **forward kinematics** and **forward dynamics** through the compiled library, per sample;
- the **inverse kinematics** of the case-1 path placed on the robot
  (:func:`vgtarm.experiment.cases.joint_reference`: fast solver, exact rates; 6,284 samples), per
  sample. One module alone has a tip moving in a plane: its IK is refused, so it has no IK or CFC;
- one **computed-force-control run of case 1** (:func:`vgtarm.experiment.cases.run_case`, 6.283 s
  simulated at 1 ms), with its real-time factor and maximum tip error.

Every figure is printed with its ratio against ``k = 2`` measured in the same run; the paper's
fixed 7-joint model is measured alongside; CasADi's interpreter is compared with the compiled
library on one stack; and the growth exponent ``a`` of ``y ~ n_joints^a`` is fitted by least
squares in log-log (over all module counts, and over the larger half).

Batches of 4,096 samples or more run on OpenMP threads in the library; on a machine shared with
other work a thread that waits for a busy core makes such timings jump, so the figures recorded in
``docs/benchmarks.md`` were taken with ``OMP_NUM_THREADS=1`` (one thread: the cost per sample).

``VGTARM_BENCH_MAX_MODULES`` (default 10) sets the largest stack, for quick runs. Stacks of more
than ``VGTARM_BENCH_INTERPRETED_FROM`` modules (default: none) are run on CasADi's interpreter
instead of being compiled, and the table says so. The machine's other load makes the compile
times noisy (two cores, shared): compare the compiler's CPU time first.
"""

from __future__ import annotations

import dataclasses
import math
import os
import resource
import shutil
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import casadi as ca
import numpy as np

import vgtarm
from vgtarm.errors import VgtarmError
from vgtarm.experiment.cases import joint_reference, run_case
from vgtarm.model.compiled import InterpretedBackend, build_functions, get_backend
from vgtarm.model.definition import StackDefinition
from vgtarm.model.parameters import Body
from vgtarm.model.stack import Stack, Twist, load_stack

from .common import Row, _fmt, best_time, print_table

T = TypeVar("T")
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
MAX_MODULES_VARIABLE = "VGTARM_BENCH_MAX_MODULES"
INTERPRETED_FROM_VARIABLE = "VGTARM_BENCH_INTERPRETED_FROM"
#: The stack compared with CasADi's interpreter (the six-module size of ``examples/``... or less).
INTERPRETER_MODULES = 4
#: Control period of the case runs (s): one step of the loop simulates this much.
DT = 1e-3
#: Seconds one batch timing aims at (the batch size follows a first probe).
BATCH_SECONDS = 0.2
#: The inner twists' rotary stage (``examples/six_modules.toml``, psi3).
STAGE = Twist(
    height=0.06,
    limits=(-math.pi, math.pi),
    home=0.0,
    viscous=0.5,
    body=Body("twist", 0.5, (0.0, 0.0, 0.03), ((0.4625e-3, 0.0, 0.0), (0.0, 0.4625e-3, 0.0), (0.0, 0.0, 0.625e-3))),
)


def family(k: int) -> Stack:
    """The benchmark's stack of ``k`` paper modules (module docstring); ``family(2)`` is the paper's robot."""
    if not 1 <= k <= 50:
        raise ValueError(f"k = {k}: expected 1 to 50 modules")
    paper = load_stack(EXAMPLES / "paper_robot.toml")
    first, second = paper.modules
    tool_twist = second.twist
    modules = []
    for i in range(1, k + 1):
        twist = tool_twist if i == k else (STAGE if i % 2 == 0 else None)
        modules.append(dataclasses.replace(first if i % 2 else second, twist=twist))
    return dataclasses.replace(paper, name=f"{k} paper modules", modules=tuple(modules))


@dataclass
class Figures:
    """What one robot measured: sizes in bytes, times in seconds (``nan``: not measured)."""

    label: str
    modules: int
    joints: int
    backend: str
    compile_wall: float = math.nan
    compile_cpu: float = math.nan
    c_bytes: float = math.nan
    library_bytes: float = math.nan
    fk: float = math.nan  # per sample
    fd: float = math.nan  # per sample
    ik: float = math.nan  # per sample of the path
    cfc_step: float = math.nan  # per control period
    cfc_error: float = math.nan  # maximum tip error (m)
    note: str = ""


@contextmanager
def _cache_folder(folder: str) -> Iterator[None]:
    previous = os.environ.get("VGTARM_CACHE_DIR")
    os.environ["VGTARM_CACHE_DIR"] = folder
    try:
        yield
    finally:
        if previous is None:
            os.environ.pop("VGTARM_CACHE_DIR")
        else:
            os.environ["VGTARM_CACHE_DIR"] = previous


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _generated_c_bytes(definition: StackDefinition) -> int:
    """Bytes of the C that the library's build generates (generated again here, not timed)."""
    with tempfile.TemporaryDirectory() as folder:
        generator = ca.CodeGenerator("vgtarm_model.c", {"with_header": False})
        for f in build_functions(definition).values():
            generator.add(f)
        generator.generate(folder + os.sep)
        return sum(path.stat().st_size for path in Path(folder).glob("*.c"))


def _cold_compile(stack: Stack, figures: Figures) -> vgtarm.Robot:
    """The stack's robot, its library compiled cold into a temporary cache folder (removed after)."""
    definition = StackDefinition.of(stack)
    folder = tempfile.mkdtemp(prefix="vgtarm-bench-stacks-")
    try:
        with _cache_folder(folder):
            cpu, start = _children_cpu(), time.perf_counter()
            backend = get_backend("compiled", definition)
            figures.compile_wall = time.perf_counter() - start
            figures.compile_cpu = _children_cpu() - cpu
        figures.library_bytes = sum(p.stat().st_size for p in Path(folder).glob("vgtarm_*.so"))
    finally:
        shutil.rmtree(folder, ignore_errors=True)  # the library stays mapped while the process lives
    figures.c_bytes = _generated_c_bytes(definition)
    return vgtarm.Robot(stack, backend)


def _per_sample(call: Callable[[int], object]) -> float:
    """Seconds per sample of ``call(n)`` (a batch of ``n``): the best of five rounds
    (:func:`~benchmarks.common.best_time`), ``n`` sized by a first call to take about
    :data:`BATCH_SECONDS`."""
    probe = 256
    start = time.perf_counter()
    call(probe)
    each = max((time.perf_counter() - start) / probe, 1e-9)
    n = int(min(max(BATCH_SECONDS / each, probe), 100_000))
    return best_time(lambda: call(n), repeat=5, min_time=BATCH_SECONDS) / n


def _batch_inputs(robot: vgtarm.Robot, n_max: int = 100_000, seed: int = 0) -> tuple[np.ndarray, ...]:
    """Configurations within a tenth of each joint's span around home (assemblable), rates, efforts."""
    rng = np.random.default_rng(seed)
    p = robot.parameters
    span = p.upper - p.lower
    q = p.home + 0.1 * span * rng.uniform(-1.0, 1.0, size=(n_max, robot.n_joints))
    qd = rng.normal(scale=0.1, size=q.shape)
    F = rng.normal(scale=50.0, size=q.shape)
    return q, qd, F


def _timed(f: Callable[[], T], repeat: int) -> tuple[float, T]:
    """Best wall time of ``repeat`` (>= 1) calls of ``f`` and the last result."""
    best = math.inf
    for _ in range(repeat):
        start = time.perf_counter()
        result = f()
        best = min(best, time.perf_counter() - start)
    return best, result


def _measure(robot: vgtarm.Robot, figures: Figures) -> None:
    q, qd, F = _batch_inputs(robot)
    figures.fk = _per_sample(lambda n: robot.forward_kinematics(q[:n]))
    figures.fd = _per_sample(lambda n: robot.forward_dynamics(q[:n], qd[:n], F[:n]))
    try:  # refused at once when the tip moves in a plane (one module)
        ik_time, reference = _timed(lambda: joint_reference(robot, 1), 1)
    except VgtarmError as exc:
        figures.note = f"no IK and no CFC run: {str(exc).splitlines()[0]}"
        return
    fast = robot.n_joints <= 14  # the larger stacks are timed once
    if fast:
        ik_time = min(ik_time, _timed(lambda: joint_reference(robot, 1), 2)[0])
    samples = len(reference.t)
    figures.ik = ik_time / samples
    cfc_time, result = _timed(lambda: run_case(robot, 1, reference=reference), 3 if fast else 1)
    steps = samples - 1
    figures.cfc_step = cfc_time / steps
    figures.cfc_error = float(np.max(result.tip_error))
    if not result.success:
        figures.note = f"CFC: {result.message}"


def _growth(x: list[float], y: list[float]) -> float:
    """Least-squares slope of ``log y`` against ``log x`` (``nan`` with fewer than two points)."""
    pairs = [(a, b) for a, b in zip(x, y, strict=True) if math.isfinite(b) and b > 0]
    if len(pairs) < 2:
        return math.nan
    lx, ly = np.log([a for a, _ in pairs]), np.log([b for _, b in pairs])
    return float(np.polyfit(lx, ly, 1)[0])


def _cell(value: float, base: float, show: Callable[[float], str]) -> str:
    if not math.isfinite(value):
        return "-"
    ratio = f" ({value / base:.2f}x)" if math.isfinite(base) and base > 0 else ""
    return f"{show(value)}{ratio}"


def _mb(value: float) -> str:
    return f"{value / 1e6:.2f} MB"


def _seconds(value: float) -> str:
    return f"{value:.1f} s"


COLUMNS: tuple[tuple[str, str, Callable[[float], str]], ...] = (
    ("generated C", "c_bytes", _mb),
    ("library", "library_bytes", _mb),
    ("compile, wall", "compile_wall", _seconds),
    ("compile, compiler CPU", "compile_cpu", _seconds),
    ("FK per sample", "fk", _fmt),
    ("forward dynamics per sample", "fd", _fmt),
    ("IK case 1 per sample", "ik", _fmt),
    ("CFC case 1 per step", "cfc_step", _fmt),
)


def _print_scaling(rows: list[Figures], base: Figures) -> None:
    print(f"\n### Stacks of 1 to {max(r.modules for r in rows if r.modules)} modules (ratio against {base.label})\n")
    header = ["robot", "joints", "backend", *[c[0] for c in COLUMNS], "CFC real-time factor", "CFC max tip error"]
    print("| " + " | ".join(header) + " |")
    print("|" + " --- |" * len(header))
    for r in rows:
        cells = [_cell(getattr(r, attr), getattr(base, attr), show) for _, attr, show in COLUMNS]
        rtf, base_rtf = DT / r.cfc_step, DT / base.cfc_step  # nan without a run
        rtf_cell = f"{rtf:,.0f}x ({rtf / base_rtf:.2f}x)" if math.isfinite(rtf) else "-"
        error = f"{r.cfc_error * 1e3:.2f} mm" if math.isfinite(r.cfc_error) else "-"
        print(f"| {r.label} | {r.joints} | {r.backend} | " + " | ".join([*cells, rtf_cell, error]) + " |")
    for r in rows:
        if r.note:
            print(f"{r.label}: {r.note}")


def _print_growth(rows: list[Figures]) -> None:
    stacks = [r for r in rows if r.modules and r.backend == "compiled"]
    print("\n### Growth with the number of joints n (least-squares fit of y ~ n^a, compiled stacks)\n")
    half = sorted({r.modules for r in stacks})
    tail = [r for r in stacks if r.modules >= half[len(half) // 2]] if half else []
    span = f"k >= {tail[0].modules}" if tail else "-"
    print(f"| figure | a, all module counts | a, {span} |")
    print("| --- | --- | --- |")
    for name, attr, _ in COLUMNS:
        a_all = _growth([r.joints for r in stacks], [getattr(r, attr) for r in stacks])
        a_tail = _growth([r.joints for r in tail], [getattr(r, attr) for r in tail])
        print(f"| {name} | {a_all:.2f} | {a_tail:.2f} |")


def _interpreter_rows(robot: vgtarm.Robot, figures: Figures) -> list[Row]:
    slow = vgtarm.Robot(robot.parameters, InterpretedBackend(build_functions(robot.definition)))
    q, qd, F = _batch_inputs(robot, 2_000)
    n = 2_000
    label = f"{figures.modules} modules ({figures.joints} joints)"
    fk_slow = _timed(lambda: slow.forward_kinematics(q), 2)[0] / n
    fd_slow = _timed(lambda: slow.forward_dynamics(q, qd, F), 2)[0] / n
    return [
        Row(f"FK, {label}, compiled batch", figures.fk, "sample", 1, "CasADi interpreter batch", fk_slow),
        Row(f"forward dynamics, {label}, compiled batch", figures.fd, "sample", 1, "CasADi interpreter batch", fd_slow),
    ]


def _module_counts() -> tuple[int, int | None]:
    text = os.environ.get(MAX_MODULES_VARIABLE, "") or "10"
    interpreted = os.environ.get(INTERPRETED_FROM_VARIABLE, "")
    try:
        largest = int(text)
        above = int(interpreted) if interpreted else None
    except ValueError:
        raise SystemExit(
            f"{MAX_MODULES_VARIABLE} = {text!r}, {INTERPRETED_FROM_VARIABLE} = {interpreted!r}: expected whole numbers"
        ) from None
    if not 2 <= largest <= 50:
        raise SystemExit(f"{MAX_MODULES_VARIABLE} = {largest}: expected 2 to 50 (k = 2 is the baseline)")
    return largest, above


def run() -> list[Figures]:
    largest, interpreted_above = _module_counts()
    rows: list[Figures] = []
    stacks: dict[int, vgtarm.Robot] = {}
    for k in range(1, largest + 1):
        stack = family(k)
        figures = Figures(f"{k} module{'s' if k > 1 else ''}", k, stack.n_joints, "compiled")
        if interpreted_above is not None and k > interpreted_above:
            figures.backend = "interpreted"
            robot = vgtarm.Robot(stack, InterpretedBackend(build_functions(StackDefinition.of(stack))))
        else:
            robot = _cold_compile(stack, figures)
        _measure(robot, figures)
        rows.append(figures)
        stacks[k] = robot
        print(
            f"  {figures.label}: compile {figures.compile_wall:.1f} s, FK {_fmt(figures.fk)}, "
            f"FD {_fmt(figures.fd)}, IK {_fmt(figures.ik)}, CFC step {_fmt(figures.cfc_step)}",
            flush=True,
        )
    print(f"  OMP_NUM_THREADS = {os.environ.get('OMP_NUM_THREADS', '(unset)')}")
    paper = vgtarm.load_robot()
    paper_figures = Figures("paper's fixed model", 0, paper.n_joints, paper.backend.kind)
    _measure(paper, paper_figures)
    rows.append(paper_figures)
    base = rows[1]
    _print_scaling(rows, base)
    _print_growth(rows)
    k = min(INTERPRETER_MODULES, largest)
    print_table(
        f"Compiled library against CasADi's interpreter ({k} modules, same run)",
        _interpreter_rows(stacks[k], rows[k - 1]),
    )
    from . import bench_recursive  # the recursive model, 1 to 50 modules, beside the symbolic one

    bench_recursive.run()
    return rows


if __name__ == "__main__":
    run()
