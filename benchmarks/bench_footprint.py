"""The core's footprint: its import time and the size of its installed dependency closure, against a
baseline commit (issue 27: the core must not grow by more than 10 % when libraries replace code).

Both trees are measured in the same run: the baseline's ``src/`` and ``pyproject.toml`` are taken
from git (``git archive``) into a temporary folder, the current ones from this checkout.

- **Import time**: the wall time of a fresh interpreter running ``import vgtarm``, loading the
  paper's robot and evaluating its forward kinematics (the compiled model from the cache: the cache
  folder is chosen, so :func:`vgtarm.model.compiled.cache_dir` runs), and of ``python -m vgtarm
  --help``; median of :data:`RUNS` runs, the two trees alternating so that the machine's load
  falls on both alike. The cache folder comes from ``$XDG_CACHE_HOME`` (a private temporary one),
  not ``$VGTARM_CACHE_DIR``, so the default lookup is what is timed; the first run fills it.
- **Install size**: the bytes of every installed distribution in the closure of the core's
  requirements (``[project] dependencies`` of each tree's ``pyproject.toml``, followed through each
  distribution's own requirements whose markers hold here, extras excluded), summed from the file
  sizes listed in the distributions' ``RECORD`` files (the file on disk where RECORD gives no size).

``VGTARM_BENCH_FOOTPRINT_RUNS`` changes the number of runs; ``VGTARM_BENCH_FOOTPRINT_BASELINE`` the
baseline commit (default :data:`BASELINE`, the last commit before platformdirs, filelock and psutil).
"""

from __future__ import annotations

import importlib.metadata as metadata
import os
import re
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
import tomllib
from io import BytesIO
from pathlib import Path

from packaging.markers import default_environment
from packaging.requirements import Requirement

#: The commit the footprint is compared with: main before the libraries of issue 27 item 10.
BASELINE = "bd145e2"
#: Runs of each command per tree (the median is reported).
RUNS = 9
#: Most the core may grow (issue 27): 10 %.
ALLOWED_GROWTH = 1.10
ROOT = Path(__file__).resolve().parents[1]

IMPORT_AND_LOAD = (
    "import vgtarm; robot = vgtarm.load_robot(); robot.forward_kinematics(robot.parameters.home); "
    "import vgtarm.model.compiled as c; assert c.get_backend().__class__.__name__ == 'CompiledBackend'"
)
COMMANDS = {
    "import vgtarm, load the robot, one FK": ["-c", IMPORT_AND_LOAD],
    "vgtarm --help": ["-m", "vgtarm", "--help"],
}


def _name(text: str) -> str:
    return re.sub(r"[-_.]+", "-", text).lower()


def core_requirements(pyproject: Path) -> list[Requirement]:
    """The ``[project] dependencies`` of ``pyproject``."""
    data = tomllib.loads(pyproject.read_text(encoding="utf-8"))
    return [Requirement(text) for text in data["project"]["dependencies"]]


def closure(requirements: list[Requirement]) -> dict[str, metadata.Distribution]:
    """Every installed distribution the requirements need here, by normalised name (extras off)."""
    environment = default_environment()
    found: dict[str, metadata.Distribution] = {}
    todo = list(requirements)
    while todo:
        requirement = todo.pop()
        if requirement.marker is not None and not requirement.marker.evaluate({**environment, "extra": ""}):
            continue
        key = _name(requirement.name)
        if key in found:
            continue
        try:
            distribution = metadata.distribution(requirement.name)
        except metadata.PackageNotFoundError:
            print(f"  (not installed: {requirement.name}; not counted)")
            continue
        found[key] = distribution
        todo += [Requirement(text) for text in distribution.requires or []]
    return found


def installed_bytes(distribution: metadata.Distribution) -> int:
    """Size of a distribution's installed files, from RECORD (the file itself where RECORD has no size)."""
    total = 0
    for file in distribution.files or []:
        if file.size is not None:
            total += file.size
        else:
            path = Path(str(file.locate()))
            if path.is_file():
                total += path.stat().st_size
    return total


def install_size(pyproject: Path) -> tuple[int, dict[str, int]]:
    sizes = {name: installed_bytes(d) for name, d in closure(core_requirements(pyproject)).items()}
    return sum(sizes.values()), sizes


def baseline_tree(commit: str, into: Path) -> Path:
    """``src/`` and ``pyproject.toml`` of ``commit``, unpacked into ``into``."""
    archive = subprocess.run(
        ["git", "-C", str(ROOT), "archive", "--format=tar", commit, "src", "pyproject.toml"],
        check=True,
        capture_output=True,
    ).stdout
    with tarfile.open(fileobj=BytesIO(archive)) as tar:
        tar.extractall(into, filter="data")
    return into


def _time(arguments: list[str], src: Path, env: dict[str, str]) -> float:
    start = time.perf_counter()
    subprocess.run(
        [sys.executable, *arguments],
        env={**env, "PYTHONPATH": str(src)},
        check=True,
        stdout=subprocess.DEVNULL,
        cwd=src.parent,
    )
    return time.perf_counter() - start


def import_times(trees: dict[str, Path], runs: int, cache_home: Path) -> dict[str, dict[str, float]]:
    """Median wall time of each command for each tree (``trees``: label -> its ``src`` folder)."""
    env = {k: v for k, v in os.environ.items() if k not in ("VGTARM_CACHE_DIR", "PYTHONPATH")}
    env["XDG_CACHE_HOME"] = str(cache_home)
    medians: dict[str, dict[str, float]] = {}
    for title, arguments in COMMANDS.items():
        for src in trees.values():
            _time(arguments, src, env)  # warm up: fills the cache, the file system's caches
        times: dict[str, list[float]] = {label: [] for label in trees}
        for _ in range(runs):
            for label, src in trees.items():
                times[label].append(_time(arguments, src, env))
        medians[title] = {label: statistics.median(values) for label, values in times.items()}
    return medians


def imported_modules(src: Path, env: dict[str, str]) -> dict[str, int]:
    """Each module ``IMPORT_AND_LOAD`` imports and its own import time (us), from ``-X importtime``."""
    done = subprocess.run(
        [sys.executable, "-X", "importtime", "-c", IMPORT_AND_LOAD],
        env={**env, "PYTHONPATH": str(src)},
        check=True,
        capture_output=True,
        text=True,
        cwd=src.parent,
    )
    found: dict[str, int] = {}
    for line in done.stderr.splitlines():
        if line.startswith("import time:") and "|" in line and not line.rstrip().endswith("imported package"):
            own, _, name = line[len("import time:") :].split("|")
            if own.strip().isdigit():
                found[name.strip()] = int(own)
    return found


def added_imports(trees: dict[str, Path], cache_home: Path, runs: int) -> tuple[list[str], float]:
    """Modules the current tree imports and the baseline does not, and their summed own import
    time (median over ``runs`` measurements, s): a figure the machine's load hardly blurs."""
    env = {k: v for k, v in os.environ.items() if k not in ("VGTARM_CACHE_DIR", "PYTHONPATH")}
    env["XDG_CACHE_HOME"] = str(cache_home)
    base, current = trees.values()
    for src in (base, current):  # warm up: a first run may build the model (and take the build lock)
        imported_modules(src, env)
    extra = sorted(set(imported_modules(current, env)) - set(imported_modules(base, env)))
    extra = [name for name in extra if not name.startswith("vgtarm")]  # the package's own modules differ by design
    totals = []
    for _ in range(runs):
        times = imported_modules(current, env)
        totals.append(sum(times.get(name, 0) for name in extra) * 1e-6)
    return extra, statistics.median(totals)


def run() -> dict[str, float]:
    runs = int(os.environ.get("VGTARM_BENCH_FOOTPRINT_RUNS", str(RUNS)))
    commit = os.environ.get("VGTARM_BENCH_FOOTPRINT_BASELINE", BASELINE)
    ratios: dict[str, float] = {}
    with tempfile.TemporaryDirectory(prefix="vgtarm-footprint-") as scratch:
        base = baseline_tree(commit, Path(scratch) / "baseline")
        trees = {f"baseline {commit}": base / "src", "this checkout": ROOT / "src"}
        print(f"\n### The core's footprint against {commit} (same run; limit: {ALLOWED_GROWTH:.2f}x)\n")
        print(f"Import time, median of {runs} fresh interpreters each:\n")
        print("| command | baseline | this checkout | ratio |")
        print("| --- | --- | --- | --- |")
        cache_home = Path(scratch) / "xdg-cache"
        cache_home.mkdir(mode=0o700)
        medians_of = import_times(trees, runs, cache_home)
        for title, medians in medians_of.items():
            before, after = medians.values()
            ratios[title] = after / before
            print(f"| `{title}` | {before * 1e3:.0f} ms | {after * 1e3:.0f} ms | {after / before:.3f} |")
        extra, seconds = added_imports(trees, cache_home, runs)
        first = next(iter(medians_of.values()))
        share = seconds / next(iter(first.values()))
        names = ", ".join(extra) if extra else "none"
        print(
            f"\nModules imported by `{next(iter(COMMANDS))}` here and not in the baseline: {names}; their own import "
            f"time (-X importtime, median of {runs}): {seconds * 1e3:.1f} ms, {share:.1%} of the baseline's time."
        )
        before_bytes, before_sizes = install_size(base / "pyproject.toml")
        after_bytes, after_sizes = install_size(ROOT / "pyproject.toml")
    ratios["install size"] = after_bytes / before_bytes
    added = sorted(set(after_sizes) - set(before_sizes))
    removed = sorted(set(before_sizes) - set(after_sizes))
    print("\nInstall size of the core's dependency closure (RECORD sizes of the installed distributions):\n")
    print("| | distributions | size | ratio |")
    print("| --- | --- | --- | --- |")
    print(f"| baseline | {len(before_sizes)} | {before_bytes / 2**20:.1f} MiB | |")
    print(f"| this checkout | {len(after_sizes)} | {after_bytes / 2**20:.1f} MiB | {after_bytes / before_bytes:.3f} |")
    for name in added:
        print(f"| + {name} | | {after_sizes[name] / 2**20:.2f} MiB | |")
    for name in removed:
        print(f"| - {name} | | {before_sizes[name] / 2**20:.2f} MiB | |")
    worst = max(ratios, key=lambda k: ratios[k])
    verdict = "within" if ratios[worst] <= ALLOWED_GROWTH else "BEYOND"
    print(f"\nlargest growth: {worst} {ratios[worst]:.3f}x, {verdict} the {ALLOWED_GROWTH:.2f}x limit")
    return ratios
