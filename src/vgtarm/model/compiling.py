"""How the model's generated C becomes a shared library: the compiler, its flags and its commands.

:func:`_compile` generates the C of every model function (CasADi) and compiles it with the drivers
of ``csrc/`` into one library; its source and flags are the build recipe the cache key hashes
(:func:`_recipe`). Every compiler command runs under :mod:`vgtarm.compiler` (a process group that
dies with vgtarm, a time limit); a command that cannot run, fails, runs past its limit or writes
nothing raises :class:`~.library_errors._Unavailable` with one line. :mod:`.build_process` runs
:func:`_compile` in a process of its own; the recursive model's library
(:mod:`vgtarm.model.recursive.library`) runs its commands with :func:`_run` too.
"""

from __future__ import annotations

import inspect
import os
import shutil
import subprocess
from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait
from pathlib import Path

import casadi as ca

from .. import compiler as compilers
from ..errors import shown
from ..machine import usable_cpus
from ..memory import memory_limit
from . import budget, interface
from .backends import _GENERATED_NAME, Signature, build_functions
from .definition import PAPER, Definition
from .library_errors import _Unavailable

#: The drivers compiled into every library (``closed_loop.c``, ``ga.c``, ``batch.c``) and their headers.
_CSRC = Path(__file__).resolve().parent / "csrc"
#: Flags of every C file of the paper robot's library and of every library's drivers (linked with ``-shared``).
_CFLAGS = ("-O2", "-fPIC", "-ffp-contract=off")
#: Flags of a stack's generated functions, compiled apart before the link with the drivers (built
#: with :data:`_CFLAGS`): its straight-line code is ten times the paper robot's (17 MB of C for six
#: modules, 12.6 MB with common-subexpression elimination), and GCC's -O2 spent 4 min 19 s on it
#: where -O1 took 1 min 22 s (measured on this 2-core machine; 77 s with the elimination). Neither
#: changes a floating-point result: no contraction, no fast math. With the tool tasks' and the
#: effort criterion's functions the six-module arm's C grew to 27 MB (187 s at -O1 in one file; a
#: file per function on two cores, :func:`_generated_units`, 126 s for the whole build).
_STACK_GENERATED_CFLAGS = ("-O1", "-fPIC", "-ffp-contract=off")
#: Default limit (s) of one compiler command (:mod:`vgtarm.compiler`, before
#: ``$VGTARM_COMPILER_TIME_LIMIT``): the build process sets it from its model's estimate
#: (:func:`compile_limit`); the recursive model's library (a few seconds) keeps this one.
_COMPILE_TIMEOUT = budget.COMPILER_LIMIT_FLOOR


def find_compiler() -> str | None:
    """The C compiler to use: ``$CC``, else ``cc``, ``gcc`` or ``clang`` on the PATH."""
    candidates = [os.environ["CC"]] if os.environ.get("CC") else ["cc", "gcc", "clang"]
    for name in candidates:
        found = shutil.which(name)
        if found:
            return found
    return None


def _compiler_failure(compiler: str, done: subprocess.CompletedProcess[str]) -> str:
    ending = compilers.ending(done.returncode)
    return f"the C compiler {shown(compiler, 80)} failed ({ending}): {compilers.first_error(done)}"


def compile_limit(definition: Definition = PAPER) -> float:
    """The limit (s) of one compiler command building ``definition``: ``$VGTARM_COMPILER_TIME_LIMIT``,
    else a generous multiple of the estimated compile (:func:`~vgtarm.model.budget.compiler_limit`).

    Raises:
        ConfigError: the variable is set but not a number of seconds > 0.
    """
    return compilers.time_limit(budget.compiler_limit(budget.estimate(definition)))


def _run(compiler: str, command: list[str]) -> subprocess.CompletedProcess[str]:
    """Run one compiler command under its time limit, in a process group of its own that dies with
    this process (:func:`vgtarm.compiler.run`), and return what it did; :class:`_Unavailable` when
    it cannot run, runs past the limit, or exits 0 without writing its output (``-o``)."""
    try:
        done = compilers.run(command, limit=_COMPILE_TIMEOUT)
    except compilers.CompilerError as exc:
        raise _Unavailable(str(exc)) from None
    if done.returncode == 0 and compilers.wrote_nothing(command):
        raise _Unavailable(f"the C compiler {shown(compiler, 80)} exited 0 but wrote no {compilers.product(command)}")
    return done


def _run_compiler(compiler: str, command: list[str]) -> None:
    """Run one compiler command; :class:`_Unavailable` with the first error line when it fails."""
    done = _run(compiler, command)
    if done.returncode != 0:
        raise _Unavailable(_compiler_failure(compiler, done))


def _compile(compiler: str, workdir: Path, definition: Definition = PAPER) -> tuple[Path, dict[str, Signature]]:
    """Generate C for every model function into ``workdir`` and compile it with the drivers.

    Returns the library (inside ``workdir``) and the functions' signatures; raises
    :class:`_Unavailable` when the compiler cannot run or fails. The cache tests replace this
    function to copy a prebuilt library instead, so that the checks around it run for real
    without a 10-20 s compile each.
    """
    built = build_functions(definition)
    (workdir / "layout.c").write_text(interface.layout_source())
    generated = _CFLAGS if definition == PAPER else _STACK_GENERATED_CFLAGS
    drivers = [workdir / "layout.c", *sorted(_CSRC.glob("*.c"))]
    driver_flags = (*_CFLAGS, "-I", str(_CSRC))
    units = [(unit, generated) for unit in _generated_units(built, workdir)]
    library = workdir / "library.so"
    failure = ""
    kept: dict[tuple[Path, tuple[str, ...]], str] = {}  # what the first try compiled, for the second
    for openmp in (("-fopenmp",), ()):  # the drivers' threads where the compiler has OpenMP
        # the largest generated file first, then the drivers (ga.c takes seconds), then the rest
        own = [(driver, (*openmp, *driver_flags)) for driver in drivers]
        try:
            objects = _compile_units(compiler, [*units[:1], *own, *units[1:]], workdir, _jobs(definition), kept)
        except _Failed as exc:
            failure = str(exc)
            continue
        done = _run(compiler, [compiler, *openmp, "-shared", "-o", str(library), *objects, "-lm"])
        if done.returncode == 0 and library.is_file():
            return library, {key: Signature.of(f) for key, f in built.items()}
        failure = _compiler_failure(compiler, done)
    raise _Unavailable(failure)


def _generated_units(built: dict[str, ca.Function], workdir: Path) -> list[Path]:
    """CasADi's C of the functions ``built``, a file each (the largest first), so that the compiler
    can take them in parallel: a long stack's largest functions take most of its compile (the
    effort criterion's rates alone 45 of the six-module arm's 187 s at ``-O1``). The first file
    carries CasADi's ``<prefix>_casadi_int_size`` checks (:data:`_GENERATED_NAME`); each file keeps
    its own copy of CasADi's static helpers."""
    order = sorted(built, key=lambda key: -built[key].n_instructions())
    units = []
    for index, key in enumerate(order):
        name = _GENERATED_NAME if index == 0 else f"{_GENERATED_NAME}_{index}"
        generator = ca.CodeGenerator(f"{name}.c", {"with_header": False})
        generator.add(built[key])
        generator.generate(str(workdir) + os.sep)
        units.append(workdir / f"{name}.c")
    return units


class _Failed(_Unavailable):
    """A compiler command ran and failed (as one without OpenMP does on ``-fopenmp``): worth a second
    try without it, where a compiler that cannot run or runs past its limit is not."""


def _compile_units(
    compiler: str,
    units: list[tuple[Path, tuple[str, ...]]],
    folder: Path,
    jobs: int,
    kept: dict[tuple[Path, tuple[str, ...]], str],
) -> list[str]:
    """Compile every C file of ``units`` with its flags into an object file in ``folder``, ``jobs``
    compilers at a time (in the order given); the objects' paths. ``kept`` holds the objects of
    ``(file, flags)`` already compiled (an earlier try's), and gets this call's. At the first failure
    nothing more is started, and the failure is raised (:class:`_Failed`, or :class:`_Unavailable`
    from :func:`_run`) once the compilers running have ended."""

    def one(unit: tuple[Path, tuple[str, ...]]) -> str:
        if unit in kept:
            return kept[unit]
        source, flags = unit
        product = folder / f"{source.stem}.o"
        done = _run(compiler, [compiler, *flags, "-c", "-o", str(product), str(source)])
        if done.returncode != 0:
            raise _Failed(_compiler_failure(compiler, done))
        kept[unit] = str(product)
        return str(product)

    pool = ThreadPoolExecutor(max_workers=jobs)
    try:
        futures = [pool.submit(one, unit) for unit in units]
        wait(futures, return_when=FIRST_EXCEPTION)
        for future in futures:  # the first failure, raised once the running compilers have ended (below)
            if future.done() and future.exception() is not None:
                future.result()
        return [future.result() for future in futures]
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _jobs(definition: Definition) -> int:
    """How many compilers a build runs at once: one per processor this process may use, and no more
    than the memory left beside the build process holds at the largest file's estimated peak
    (:mod:`.budget`); at least one (the budget refuses a build that cannot fit)."""
    processors = usable_cpus()
    available, _ = memory_limit()
    if available is None:
        return processors
    cost = budget.estimate(definition)
    room = available - (cost.bytes("compiled") - cost.compiler_bytes)  # the build process's own
    return max(1, min(processors, int(room // cost.compiler_bytes)))


def _recipe() -> bytes:
    """How this module turns the generated C into a library: the source of :func:`_compile` and
    every flag it uses (the rest of this module finds and runs the compiler; it is not hashed)."""
    flags = (_CFLAGS, _STACK_GENERATED_CFLAGS, _GENERATED_NAME)
    steps = (_compile, _generated_units, _compile_units)
    return b"".join(inspect.getsource(step).encode() for step in steps) + repr(flags).encode()
