"""What building a model costs, estimated from its structure before anything is built, and the
limits the estimate must fit.

A model is built once per structure: CasADi constructs its symbolic functions (the *symbolic
construction*), writes them as C and the C compiler compiles it; the interpreter needs the
symbolic construction alone. Both grow fast with the number of joints ``n``: fifty modules
(175 joints, the most a stack may have) would take hours and tens of GB. So a build is first
estimated from ``n`` with the fits of ``docs/benchmarks.md`` ("Building a model"), and refused
in one line when the estimate exceeds:

- the **memory** one request may use (:func:`vgtarm.memory.memory_limit`: ``MemAvailable`` of
  ``/proc/meminfo``, or ``$VGTARM_MEMORY_LIMIT``);
- the **build time limit**: ``$VGTARM_BUILD_TIME_LIMIT`` seconds (a number; default
  :data:`DEFAULT_TIME_LIMIT`, 30 min).

One compiler command of a build runs under a limit of its own (:mod:`vgtarm.compiler`):
``$VGTARM_COMPILER_TIME_LIMIT`` seconds, else :func:`compiler_limit` of the estimate: ten times the
estimated compile and at least :data:`COMPILER_LIMIT_FLOOR` (10 min for the paper's robot, whose
compile took 60 s on this 2-core machine under load; about 42 min for six modules: one compiler command
compiles one file of the build, each well within it).

The fits (least squares of ``y = c n^a`` in log-log, 2-core x86_64 vm, CasADi 3.8.2, gcc 12.2;
stacks of the benchmark family, ``k`` modules, ``3k + ceil(k/2)`` joints). The symbolic
construction and the compiler were measured again on 2026-11-28 (4 to 21 joints, fit on 7 to 21),
after the tool tasks' and the effort criterion's functions had made them several times the
2026-11-25 figures (the six-module arm's generated C 27 MB):

- symbolic construction of every function: ``0.0134 n^2.39`` s; holding ``0.19 n^2.07`` MiB
  (2026-11-25, measured 4 to 42 joints, fit on 14 to 42);
- the build process with the generated C: ``0.293 n^2.00`` MiB above its ``95`` MiB of Python,
  CasADi and NumPy (2026-11-25, measured 4 to 28 joints, fit on 14 to 28); it waits while the
  compilers run;
- the compiler: ``0.648 n^1.96`` s of CPU, all files one after the other (the measurements scatter
  from 0.57 to 1.57 times the curve); a file per function, compiled in parallel
  (:mod:`.compiling`), whose largest file peaks at ``30.05 n^1.42`` MiB: the curve put through the
  highest of the measurements (1.81 GB at 21 joints), so that it errs on the high side, and never
  below the 180 MiB it takes for the smallest stack;
- the mass matrix alone (what ``vgtarm describe`` evaluates): ``1.06e-5 n^3.13`` s (21 to 70 joints).

The paper's fixed robot is measured apart (its C is compiled at ``-O2``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from ..compiler import seconds_setting
from ..errors import VgtarmError, shown
from ..memory import memory_limit, size_text
from .definition import Definition, StackDefinition

#: The variable that sets the longest estimated build allowed (seconds).
TIME_LIMIT_VARIABLE = "VGTARM_BUILD_TIME_LIMIT"
#: Longest estimated build allowed by default (s).
DEFAULT_TIME_LIMIT = 1800.0
#: One compiler command of a build may run this many times its estimated compile by default...
COMPILER_LIMIT_FACTOR = 10.0
#: ... and at least this long (s): ten times the paper robot's compile on a busy 2-core machine.
COMPILER_LIMIT_FLOOR = 600.0
#: A build estimated longer than this (s) shows its progress on a terminal.
LONG_BUILD = 5.0

_MIB = float(1 << 20)
#: ``(c, a)`` of ``c n^a``: symbolic construction (s) and its memory (MiB), the build process with
#: the generated C (MiB), compiler CPU (s) and peak memory (MiB), the mass matrix alone (s). See
#: the module docstring.
SYMBOLIC_SECONDS = (0.0134, 2.39)
SYMBOLIC_MIB = (0.190, 2.07)
GENERATION_MIB = (0.293, 2.00)
COMPILER_SECONDS = (0.648, 1.96)
COMPILER_MIB = (30.05, 1.42)
MASS_SECONDS = (1.06e-5, 3.13)
#: The compiler's peak for the smallest stack (MiB): the least it takes.
COMPILER_FLOOR_MIB = 180.0
#: Memory of the build process before the symbolic construction (MiB).
PROCESS_MIB = 95.0
#: The paper's robot, measured on an idle machine: symbolic construction (s, MiB), the build
#: process with the generated C (MiB), compile (s: 8.2 s idle, about 15 s on a busy machine, the
#: figure used) and the compiler's peak (MiB).
PAPER_FIGURES = (0.15, 10.0, 20.0, 15.0, 275.0)


class BuildRefused(VgtarmError, RuntimeError):
    """Building a model would take more time or memory than allowed; the message says how much."""


@dataclass(frozen=True)
class BuildEstimate:
    """The estimated cost of building one model.

    Attributes:
        model: the model for messages (``"the paper's robot"``, ``"stack 'x' (50 modules, 175 joints)"``).
        joints: its number of joints.
        symbolic_seconds, symbolic_bytes: CasADi's construction of every function (time, memory held).
        generation_bytes: the build process's memory with the functions and their generated C.
        compiler_seconds, compiler_bytes: the C compiler (time, peak memory).
        mass_seconds: the construction of the mass matrix function alone.
    """

    model: str
    joints: int
    symbolic_seconds: float
    symbolic_bytes: float
    generation_bytes: float
    compiler_seconds: float
    compiler_bytes: float
    mass_seconds: float

    def seconds(self, kind: str) -> float:
        """Time of a build for the ``compiled`` or ``interpreted`` backend (s)."""
        return self.symbolic_seconds + (self.compiler_seconds if kind == "compiled" else 0.0)

    def bytes(self, kind: str) -> float:
        """Peak memory of a build for the ``compiled`` backend (the build process with the generated
        C and the compiler beside it) or the ``interpreted`` one (the functions built in a process
        and read back by this one)."""
        if kind == "compiled":
            return PROCESS_MIB * _MIB + self.generation_bytes + self.compiler_bytes
        return PROCESS_MIB * _MIB + 2 * self.symbolic_bytes


def _power(fit: tuple[float, float], n: int) -> float:
    c, a = fit
    return c * float(n) ** a


def describe_model(definition: Definition) -> str:
    """The model for a message: the paper's robot, or a stack with its name and size."""
    if isinstance(definition, StackDefinition):
        stack = definition.stack
        k = len(definition.structure)
        return f"stack {shown(stack.name)} ({k} module{'' if k == 1 else 's'}, {definition.n_joints} joints)"
    return "the paper's robot"


def estimate(definition: Definition) -> BuildEstimate:
    """The estimated cost of building ``definition`` (module docstring)."""
    n = definition.n_joints
    if not isinstance(definition, StackDefinition):
        sym, sym_mib, generation_mib, compile_s, compiler_mib = PAPER_FIGURES
        return BuildEstimate(
            describe_model(definition),
            n,
            sym,
            sym_mib * _MIB,
            generation_mib * _MIB,
            compile_s,
            compiler_mib * _MIB,
            0.02,
        )
    return BuildEstimate(
        model=describe_model(definition),
        joints=n,
        symbolic_seconds=_power(SYMBOLIC_SECONDS, n),
        symbolic_bytes=_power(SYMBOLIC_MIB, n) * _MIB,
        generation_bytes=_power(GENERATION_MIB, n) * _MIB,
        compiler_seconds=_power(COMPILER_SECONDS, n),
        compiler_bytes=max(_power(COMPILER_MIB, n), COMPILER_FLOOR_MIB) * _MIB,
        mass_seconds=_power(MASS_SECONDS, n),
    )


def time_text(seconds: float) -> str:
    """A duration for a message: ``"0.4 s"``, ``"78 s"``, ``"3.4 min"``, ``"12 min"``, ``"2.5 h"``."""
    if seconds < 10:
        return f"{seconds:.1f} s"
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 600:
        return f"{seconds / 60:.1f} min"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def time_limit() -> float:
    """The longest estimated build allowed (s): ``$VGTARM_BUILD_TIME_LIMIT``, else 30 min.

    Raises:
        ConfigError: the variable is set but not a positive number of seconds.
    """
    return seconds_setting(TIME_LIMIT_VARIABLE, DEFAULT_TIME_LIMIT)


def compiler_limit(cost: BuildEstimate, floor: float = COMPILER_LIMIT_FLOOR) -> float:
    """The default limit (s) of one compiler command building the model of ``cost``, before
    ``$VGTARM_COMPILER_TIME_LIMIT`` (:func:`vgtarm.compiler.time_limit`): a generous multiple of the
    estimated compile (:data:`COMPILER_LIMIT_FACTOR`; a busy machine compiles several times more
    slowly), at least ``floor``, so that only a compiler that hangs meets it: 10 min for the
    paper's robot, about 42 min for six modules, 1.9 h for ten (the whole estimated compile of one
    file per function: each command compiles one)."""
    return max(floor, COMPILER_LIMIT_FACTOR * cost.compiler_seconds)


def check(cost: BuildEstimate, kind: str) -> None:
    """Refuse, in one line naming the estimate and what to do, a build for the ``compiled`` or
    ``interpreted`` backend whose estimated time or memory exceeds the limits."""
    seconds, needed = cost.seconds(kind), cost.bytes(kind)
    limit = time_limit()
    memory, where = memory_limit()
    over: list[str] = []
    advice = ["use a stack of fewer modules"]
    if seconds > limit:
        source = "set by " if os.environ.get(TIME_LIMIT_VARIABLE, "").strip() else ""
        over.append(f"the build time limit of {time_text(limit)} ({source}{TIME_LIMIT_VARIABLE})")
        advice.append(f"raise {TIME_LIMIT_VARIABLE} (seconds)")
    if memory is not None and needed > memory:
        over.append(f"the {size_text(memory)} {where}")
        advice.append("free memory")
    if not over:
        return
    what = "compiled model" if kind == "compiled" else "symbolic model (for CasADi's interpreter)"
    # what to do before the limits' details: a long stack name may make the line long enough for the
    # command line's last guard to cut its end
    raise BuildRefused(
        f"building the {what} of {cost.model} needs about {time_text(seconds)} and {size_text(needed)} of memory "
        f"(estimated from its {cost.joints} joints); {', '.join(advice[:-1]) + ' or ' if len(advice) > 1 else ''}"
        f"{advice[-1]}: that is more than {' and '.join(over)}"
    )
