"""Work without bound (issue 20, item 6): building a model is estimated, refused, shown and stoppable.

- ``vgtarm describe`` needs no compiled model and builds none, even for fifty modules;
- a build is estimated from the structure (``vgtarm.model.budget``, the fits of
  ``docs/benchmarks.md``) and refused up front in one line when the estimate exceeds the memory
  available or the build time limit;
- Ctrl-C stops a build at once in every phase (the build runs in a process of its own,
  ``vgtarm.model.building``), leaving nothing behind; so does the death of the command;
- on a terminal a long build prints a line per phase;
- a file size limit (``ulimit -f``) that stops a build is named as such, not blamed on the compiler.

Commands run in subprocesses with a private, empty ``VGTARM_CACHE_DIR``. The interrupt tests report
the measured latency and assert only a generous bound (tests never assert tight wall-clock times).
"""

from __future__ import annotations

import dataclasses
import os
import resource
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

import vgtarm
from vgtarm.errors import ConfigError
from vgtarm.model import budget, compiled
from vgtarm.model.definition import PAPER, StackDefinition
from vgtarm.model.stack import Stack, load_stack, stack_to_toml

from .build_support import LONG_BUILD_NAME, default_sigint, long_build_stack
from .conftest import run_on_terminal

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
SCRIPT = Path(sys.executable).parent / "vgtarm"
#: Longest wait for an interrupted command to end (s): generous for a busy machine; the measured
#: latency is printed, never asserted tightly.
ENDS_WITHIN = 5.0
NO_COMPILER = compiled.find_compiler() is None


def stack_of(k: int) -> Stack:
    """``k`` modules of the paper's robot, planes alternating 0/90 degrees, a twist after every
    second module and after the last (the family of ``benchmarks/bench_stacks.py``)."""
    paper = load_stack(EXAMPLES / "paper_robot.toml")
    first, second = paper.modules
    stage = dataclasses.replace(second.twist, height=0.06)
    modules = []
    for i in range(1, k + 1):
        twist = second.twist if i == k else (stage if i % 2 == 0 else None)
        modules.append(dataclasses.replace(first if i % 2 else second, twist=twist))
    return dataclasses.replace(paper, name=f"{k} paper modules", modules=tuple(modules))


@pytest.fixture(scope="module")
def fifty(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A stack file of fifty modules (175 joints), the most a stack may have."""
    path = tmp_path_factory.mktemp("fifty") / "fifty.toml"
    path.write_text(stack_to_toml(stack_of(50)))
    return path


def private_cache(tmp_path: Path) -> Path:
    folder = tmp_path / "cache"
    folder.mkdir(mode=0o700)
    return folder


def environment(cache: Path, **extra: str) -> dict[str, str]:
    names = ("VGTARM_BACKEND", "VGTARM_CACHE_DIR", "VGTARM_BUILD_TIME_LIMIT", "VGTARM_MEMORY_LIMIT")
    env = {k: v for k, v in os.environ.items() if k not in names}
    return {**env, "VGTARM_CACHE_DIR": str(cache), **extra}


def home_args(config: Path) -> list[str]:
    return ["fk", "--config", str(config), *(repr(float(v)) for v in load_stack(config).home)]


def vgtarm_command(args: list[str], env: dict[str, str], **options: object) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(SCRIPT), *args], env=env, capture_output=True, text=True, timeout=600, **options)  # type: ignore[call-overload]


def lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.strip()]


# ----------------------------------------------------------------------------- the estimate


#: Measured on this project's 2-core machine on 2026-11-28 (docs/benchmarks.md, "Building a model"):
#: the CPU of a cold build in seconds, the symbolic construction and every generated file's compile
#: one after the other (what the estimate is of; two cores build it in about half of that).
MEASURED_BUILDS = {1: 6.1, 2: 21.9, 3: 102.7, 4: 188.6, 6: 184.3}


@pytest.mark.parametrize("k", sorted(MEASURED_BUILDS))
def test_the_estimate_follows_the_documented_build_times(k):
    cost = budget.estimate(StackDefinition.of(stack_of(k)))
    assert cost.joints == 3 * k + (k + 1) // 2
    assert 0.5 < cost.seconds("compiled") / MEASURED_BUILDS[k] < 2.0


def test_the_estimate_grows_with_the_structure_and_fifty_modules_exceed_this_machine():
    costs = [budget.estimate(StackDefinition.of(stack_of(k))) for k in (1, 2, 5, 10, 20, 50)]
    for kind in ("compiled", "interpreted"):
        for a, b in zip(costs[:-1], costs[1:], strict=True):
            assert a.seconds(kind) < b.seconds(kind) and a.bytes(kind) < b.bytes(kind)
    largest = costs[-1]
    assert largest.seconds("compiled") > budget.DEFAULT_TIME_LIMIT and largest.bytes("compiled") > 32e9
    assert 10 < budget.estimate(PAPER).seconds("compiled") < 30


def test_limits_are_validated_and_named(monkeypatch):
    paper = budget.estimate(PAPER)
    monkeypatch.delenv(budget.TIME_LIMIT_VARIABLE, raising=False)
    monkeypatch.delenv("VGTARM_MEMORY_LIMIT", raising=False)
    budget.check(paper, "compiled")  # the paper's robot fits any machine that runs vgtarm
    for bad in ("soon", "-1", "0", "nan", "inf"):
        monkeypatch.setenv(budget.TIME_LIMIT_VARIABLE, bad)
        with pytest.raises(
            ConfigError, match=rf"^VGTARM_BUILD_TIME_LIMIT = '{bad}': expected a number of seconds > 0$"
        ):
            budget.check(paper, "compiled")
    monkeypatch.setenv(budget.TIME_LIMIT_VARIABLE, "2")
    with pytest.raises(budget.BuildRefused) as refused:
        budget.check(paper, "compiled")
    message = str(refused.value)
    assert "about 15 s" in message and "the build time limit of 2.0 s (set by VGTARM_BUILD_TIME_LIMIT)" in message
    assert "raise VGTARM_BUILD_TIME_LIMIT (seconds)" in message and "\n" not in message
    budget.check(paper, "interpreted")  # 0.15 s of symbolic construction fits
    monkeypatch.delenv(budget.TIME_LIMIT_VARIABLE)
    monkeypatch.setenv("VGTARM_MEMORY_LIMIT", "100M")
    with pytest.raises(
        budget.BuildRefused, match=r"409 MB of memory .* more than the 100 MB set by VGTARM_MEMORY_LIMIT"
    ):
        budget.check(paper, "compiled")


# ----------------------------------------------------------------------------- fifty modules


def test_describe_of_fifty_modules_returns_promptly_and_builds_nothing(tmp_path, fifty):
    cache = private_cache(tmp_path)
    start = time.monotonic()
    # the symbolic model, as forced (a stack of 50 modules runs on the recursive one by default)
    done = vgtarm_command(["describe", "--config", str(fifty)], environment(cache, VGTARM_MODEL="symbolic"))
    elapsed = time.monotonic() - start
    print(f"describe of 50 modules: {elapsed:.2f} s")
    assert done.returncode == 0 and not done.stderr, done.stderr
    out = done.stdout
    assert "a stack of 50 modules, 175 joints; compiled library not built yet: about" in out
    assert "commands that need it refuse to build it" in out
    assert "tip @ home" in out and "reach 15.54 m" in out and "psi51" in out
    assert "M @ home   not evaluated: its function alone takes about" in out
    assert not list(cache.iterdir()), "describe built or wrote nothing"
    assert elapsed < 60  # it used to build for 9 minutes and more


def test_describe_evaluates_a_small_stack_without_building_it(tmp_path):
    cache = private_cache(tmp_path)
    done = vgtarm_command(["describe", "--config", str(EXAMPLES / "six_modules.toml")], environment(cache))
    assert done.returncode == 0 and not done.stderr, done.stderr
    assert "reach 1.54" in done.stdout and "M @ home   eigenvalues [" in done.stdout
    assert "compiled library not built yet: about" in done.stdout and "to build on first use (estimated)" in done.stdout
    assert not list(cache.iterdir())


@pytest.mark.parametrize(
    ("backend", "what"),
    [
        ("auto", "compiled model"),
        ("compiled", "compiled model"),
        ("interpreted", "symbolic model (for CasADi's interpreter)"),
    ],
)
def test_building_fifty_modules_is_refused_up_front_in_one_line(tmp_path, fifty, backend, what):
    cache = private_cache(tmp_path)
    start = time.monotonic()
    done = vgtarm_command(home_args(fifty), environment(cache, VGTARM_BACKEND=backend, VGTARM_MODEL="symbolic"))
    elapsed = time.monotonic() - start
    assert done.returncode == 1 and not done.stdout
    assert len(lines(done.stderr)) == 1, done.stderr
    line = lines(done.stderr)[0]
    assert line.startswith(f"vgtarm: error: building the {what} of stack '50 paper modules' (50 modules, 175 joints)")
    assert "needs about" in line and "estimated from its 175 joints" in line and "use a stack of fewer modules" in line
    assert "VGTARM_BUILD_TIME_LIMIT" in line
    assert not [p.name for p in cache.iterdir() if p.name != ".lock"], "no build happened"
    assert elapsed < 60


def test_the_python_api_refuses_fifty_modules_before_any_work(tmp_path, fifty, monkeypatch):
    monkeypatch.setenv("VGTARM_CACHE_DIR", str(private_cache(tmp_path)))
    monkeypatch.delenv("VGTARM_BACKEND", raising=False)
    monkeypatch.delenv(budget.TIME_LIMIT_VARIABLE, raising=False)
    with pytest.raises(budget.BuildRefused, match=r"^building the compiled model of stack '50 paper modules'"):
        vgtarm.load_robot(fifty, model="symbolic")  # forced: 50 modules run on the recursive model by default


# ----------------------------------------------------------------------------- Ctrl-C and the parent's death


def _build_folders(cache: Path) -> list[Path]:
    return [p for p in cache.iterdir() if p.name.startswith(".build-")] if cache.is_dir() else []


def _process_group_of_child(pid: int) -> int | None:
    """The process group of a child of ``pid`` in a group of its own (the build), if any."""
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid and int(fields[2]) != os.getpgid(pid):
            return int(fields[2])
    return None


def _live_members(group: int) -> list[str]:
    """Processes of ``group`` that still run (zombies waiting for init to reap them are dead)."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            name, rest = (entry / "stat").read_text().rsplit(")", 1)
        except OSError:
            continue
        fields = rest.split()
        if int(fields[2]) == group and fields[0] != "Z":
            found.append(f"{entry.name} {name.split('(', 1)[1]}")
    return found


def _gone(group: int, within: float = ENDS_WITHIN) -> list[str]:
    deadline = time.monotonic() + within
    while (alive := _live_members(group)) and time.monotonic() < deadline:
        time.sleep(0.05)
    return alive


def _start(args: list[str], env: dict[str, str]) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [str(SCRIPT), *args],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=default_sigint,  # noqa: PLW1509  (SIGINT not inherited ignored)
    )


def _wait_for_phase(
    process: subprocess.Popen[str], folder_of: Callable[[], list[Path]], ready: Callable[[Path], bool]
) -> Path:
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        assert process.poll() is None, process.communicate()
        for folder in folder_of():
            if ready(folder):
                return folder
        time.sleep(0.02)
    raise AssertionError("the build never reached the phase")


def _symbolic(folder: Path) -> bool:
    return not (folder / "vgtarm_model.c").exists()


def _compiling(folder: Path) -> bool:
    return (folder / "layout.c").exists()


INTERRUPTS = {
    # six modules: about 4 s of symbolic construction in the build process
    "symbolic construction": ("six_modules.toml", "auto", _symbolic),
    # the paper's robot as a stack: about 5 s in the C compiler
    "compiler": ("paper_robot.toml", "auto", _compiling),
    # the interpreter's symbolic construction, also in a build process (a temporary folder)
    "interpreter's symbolic construction": ("six_modules.toml", "interpreted", _symbolic),
}


@pytest.mark.skipif(NO_COMPILER, reason="no C compiler")
@pytest.mark.parametrize("phase", list(INTERRUPTS))
def test_ctrl_c_stops_a_build_at_once_and_leaves_nothing(tmp_path, phase):
    config, backend, ready = INTERRUPTS[phase]
    cache, scratch = private_cache(tmp_path), tmp_path / "tmp"
    scratch.mkdir()
    env = environment(cache, VGTARM_BACKEND=backend, TMPDIR=str(scratch))
    process = _start(home_args(EXAMPLES / config), env)

    def folders() -> list[Path]:
        return _build_folders(cache) if backend != "interpreted" else [p for p in scratch.iterdir() if p.is_dir()]

    _wait_for_phase(process, folders, ready)
    time.sleep(0.5)  # well inside the phase
    group = _process_group_of_child(process.pid)
    assert group is not None, "the build runs in a process group of its own"
    assert folders() and ready(folders()[0]), "still in the phase"
    start = time.monotonic()
    os.killpg(process.pid, signal.SIGINT)  # a terminal's Ctrl-C: the command's whole group
    _, err = process.communicate(timeout=60)
    latency = time.monotonic() - start
    print(f"Ctrl-C during the {phase}: the command ended {latency:.3f} s later")
    assert process.returncode == 130 and lines(err) == ["vgtarm: interrupted"], err
    assert latency < ENDS_WITHIN
    assert not _gone(group), "the build and its compiler are gone"
    assert not folders(), "no build folder is left"
    assert not [p.name for p in cache.iterdir() if p.name != ".lock"], "no library, no metadata"


@pytest.mark.skipif(NO_COMPILER, reason="no C compiler")
def test_the_build_ends_with_the_command_whatever_kills_it(tmp_path):
    cache = private_cache(tmp_path)
    process = _start(home_args(EXAMPLES / "six_modules.toml"), environment(cache))
    _wait_for_phase(process, lambda: _build_folders(cache), _symbolic)
    group = _process_group_of_child(process.pid)
    assert group is not None
    process.kill()  # kill -9: no clean-up in the command
    process.communicate(timeout=60)
    start = time.monotonic()
    assert not _gone(group), "the build process dies with the command"
    print(f"kill -9 of the command: its build ended within {time.monotonic() - start:.3f} s")
    # the next command removes the dead build's folder and builds afresh (not waited for here)


# ----------------------------------------------------------------------------- progress and file size


@pytest.mark.skipif(NO_COMPILER, reason="no C compiler")
def test_a_long_build_shows_its_phases_on_a_terminal_only(tmp_path):
    cache = private_cache(tmp_path)
    config = long_build_stack(tmp_path)  # the cheapest long build: one module, about 10 s estimated
    status, out, shown = run_on_terminal([str(SCRIPT), *home_args(config)], environment(cache))
    assert status == 0 and b"tip" in out
    progress = [line.strip() for line in shown.decode().splitlines() if line.strip()]
    assert progress[0].startswith(f"vgtarm: building the compiled model of stack '{LONG_BUILD_NAME}'")
    assert "(1 module, 4 joints): about" in progress[0] and progress[0].endswith("(estimated); Ctrl-C stops it")
    shown_phases = [line.split(": ", 2)[-1] for line in progress[1:]]
    # a phase longer than 30 s (a loaded machine) adds 'still <phase>' lines, each right after its phase's
    phases = [phase for phase in shown_phases if not phase.startswith("still ")]
    for before, line in zip(shown_phases, shown_phases[1:], strict=False):
        if line.startswith("still "):
            assert line.removeprefix("still ") in (before, before.removeprefix("still ")), progress
    order = ["building the symbolic model", "writing the C code", "compiling the C code", "linking the library"]
    # a phase shorter than a poll (the C code is written in a fraction of a second) may go unseen
    assert phases[0] == order[0] and phases[-1] == "built" and "compiling the C code" in phases, progress
    assert phases[:-1] == [phase for phase in order if phase in phases], progress
    assert all(line.startswith("vgtarm: ") for line in progress)
    # a cached library: nothing to show; and without a terminal a build shows nothing (test_cache.py)
    again = vgtarm_command(home_args(config), environment(cache))
    assert again.returncode == 0 and not again.stderr


def _file_limit(size: int) -> Callable[[], None]:
    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (size, size))

    return limit


@pytest.mark.skipif(NO_COMPILER, reason="no C compiler")
@pytest.mark.parametrize("backend", ["auto", "compiled"])
def test_a_file_size_limit_that_cuts_the_generated_c_is_named(tmp_path, backend):
    cache = private_cache(tmp_path)
    config = EXAMPLES / "planar_module.toml"  # its generated C: 0.8 MB, a file per function, the largest 0.2 MB
    done = vgtarm_command(
        home_args(config), environment(cache, VGTARM_BACKEND=backend), preexec_fn=_file_limit(150_000)
    )
    found = lines(done.stderr)
    assert len(found) == 1, found
    reason = "the file size limit (ulimit -f) of 150,000 bytes (150 kB) stopped the build: vgtarm_model.c stopped"
    assert reason in found[0] and "raise it (ulimit -f unlimited)" in found[0] and "compiler" not in found[0]
    if backend == "auto":
        assert done.returncode == 0 and "tip" in done.stdout and "using CasADi's interpreter instead" in found[0]
    else:
        assert done.returncode == 1 and found[0].startswith("vgtarm: error: VGTARM_BACKEND = 'compiled', but the file")
    assert not [p.name for p in cache.iterdir() if p.name != ".lock"], "nothing partial is left"


@pytest.mark.skipif(NO_COMPILER, reason="no C compiler")
def test_a_file_size_limit_that_stops_the_compiler_is_named(tmp_path):
    cache = private_cache(tmp_path)
    done = vgtarm_command(
        home_args(EXAMPLES / "planar_module.toml"), environment(cache), preexec_fn=_file_limit(450_000)
    )
    found = lines(done.stderr)
    assert done.returncode == 0 and len(found) == 1, found
    assert "the file size limit (ulimit -f) of 450,000 bytes (450 kB) stopped the build" in found[0]
    assert not [p.name for p in cache.iterdir() if p.name != ".lock"]


@pytest.mark.skipif(NO_COMPILER, reason="no C compiler")
def test_a_build_of_sources_that_changed_meanwhile_is_refused(tmp_path):
    """The build process imports the model afresh: it builds only if the sources still give the key
    the command computed (another edit in the checkout would otherwise be cached under it)."""
    from vgtarm.model import building

    folder = private_cache(tmp_path)
    compiler = compiled.find_compiler()
    assert compiler is not None
    with pytest.raises(
        building.BuildFailed, match="^the model's source files changed while the library was being built"
    ):
        building.run("compile", compiler, folder, PAPER, "0" * 20, budget.estimate(PAPER))
    assert sorted(p.name for p in folder.iterdir()) == [building.RESULT]  # the caller removes its build folder


def test_a_build_runs_as_many_compilers_as_processors_and_memory_allow(monkeypatch):
    """The generated C is compiled a file per function, as many at once as there are processors this
    process may use, and no more than the memory left beside the build process holds at the
    largest file's estimated peak."""
    from vgtarm.model import budget, compiling
    from vgtarm.model.definition import PAPER

    cost = budget.estimate(PAPER)
    peak, own = cost.compiler_bytes, cost.bytes("compiled") - cost.compiler_bytes
    monkeypatch.setattr(compiling, "usable_cpus", lambda: 8)
    monkeypatch.setenv("VGTARM_MEMORY_LIMIT", str(int(own + 3.5 * peak)))
    assert compiling._jobs(PAPER) == 3
    monkeypatch.setenv("VGTARM_MEMORY_LIMIT", str(int(0.5 * peak)))
    assert compiling._jobs(PAPER) == 1  # one compiler at least: the budget refuses what cannot fit
    monkeypatch.setenv("VGTARM_MEMORY_LIMIT", str(int(own + 100 * peak)))
    assert compiling._jobs(PAPER) == 8


def test_the_generated_c_is_a_file_per_function_largest_first(tmp_path):
    """Each function's C is in a file of its own (so that they compile in parallel), the largest first,
    and the first file carries CasADi's size checks, which the library is opened with."""
    from vgtarm.model import codegen, compiling
    from vgtarm.model.backends import _GENERATED_NAME

    builders = codegen.builders_for(PAPER)
    built = {key: builders[key]() for key in ("fk", "fd", "mass")}
    units = compiling._generated_units(built, tmp_path)
    assert [unit.name for unit in units] == [f"{_GENERATED_NAME}{suffix}.c" for suffix in ("", "_1", "_2")]
    texts = [unit.read_text() for unit in units]
    assert f"{_GENERATED_NAME}_casadi_int_size" in texts[0]
    holding = [[key for key in built if f"int vgt_{key}(const casadi_real** arg" in text] for text in texts]
    assert sorted(map(len, holding)) == [1, 1, 1], holding  # every function in exactly one file
    sizes = [built[keys[0]].n_instructions() for keys in holding]
    assert sizes == sorted(sizes, reverse=True) and sizes[0] > sizes[-1], (holding, sizes)


@pytest.mark.skipif(compiled.find_compiler() is None, reason="no C compiler")
def test_a_compiler_without_openmp_builds_the_library_without_it(tmp_path):
    """A compiler that refuses ``-fopenmp`` (as one without OpenMP does) still builds a working
    library, its drivers compiled again without it and the generated files' objects kept."""
    import ctypes
    import tomllib

    from vgtarm.model import compiling
    from vgtarm.model.robot import definition_of, robot_parameters_from_dict

    real = compiled.find_compiler()
    log = tmp_path / "commands.log"
    fake = tmp_path / "cc-without-openmp"
    fake.write_text(
        "#!/bin/sh\n"
        f'echo "$*" >> "{log}"\n'
        'for a in "$@"; do [ "$a" = -fopenmp ] && { echo "error: unsupported option -fopenmp" >&2; exit 1; }; done\n'
        f'exec "{real}" "$@"\n'
    )
    fake.chmod(0o755)
    parameters = robot_parameters_from_dict(tomllib.loads((EXAMPLES / "planar_module.toml").read_text()))
    work = tmp_path / "build"
    work.mkdir()
    library, signatures = compiling._compile(str(fake), work, definition_of(parameters))
    assert "fk" in signatures
    ctypes.CDLL(str(library)).vgt_fk  # noqa: B018  (a library the loader opens, with the model's functions)
    commands = log.read_text().splitlines()
    generated = [c for c in commands if Path(c.split()[-1]).name.startswith("vgtarm_model")]
    assert len(generated) == len(signatures), "each generated file compiled once, kept for the second try"
    assert any("-fopenmp" in c.split() for c in commands)  # tried, refused
    assert any("-fopenmp" not in c.split() and c.split()[-1].endswith("/ga.c") for c in commands)
    assert "-fopenmp" not in commands[-1].split() and "-shared" in commands[-1].split()  # the link, without
