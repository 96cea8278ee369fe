"""The package as users install it: built as a wheel, installed into a new environment (issue 33, item 6).

An editable install reads every file from the source tree, so a file the wheel lacks goes unseen
there: ``model/recursive/csrc`` was not in the package data, and every stack on the recursive model
(the tapered 30-module example) failed after ``pip install .``. This test

1. builds the wheel from a copy of the repository (``pip wheel --no-deps --no-build-isolation``:
   offline, with the ``setuptools`` and ``wheel`` of the test extra; an environment without them
   builds in pip's isolated environment instead, which fetches them from the package index);
2. checks that it holds every file under ``src/vgtarm`` (``__pycache__`` aside), so that any new
   data file left out of ``[tool.setuptools.package-data]`` fails here;
3. installs it into a new virtual environment. That environment sees this one's dependencies
   (CasADi, NumPy...) through one ``.pth`` line naming this environment's ``site-packages``: a path
   added so is not a site folder, its own ``.pth`` files (the editable install's) are not run, so
   ``import vgtarm`` there is the wheel's, which the test asserts;
4. runs, from a folder outside the repository, every example robot (``examples/*.toml``) through
   forward kinematics (the public API and ``vgtarm fk``) and a short simulation (``vgtarm
   simulate --path``: 20 ms along a 21-row path from the tip at home, so its inverse kinematics
   is short too).

The compiled models share the user's cache (``$VGTARM_CACHE_DIR`` or the default folder): their keys
hash the model's files, the same in the wheel as in the tree, so the rest of the suite's libraries
are found and nothing is built twice. ``VGTARM_BACKEND=compiled``: a model that cannot be compiled
from the installed files fails here instead of falling back to the interpreter. About 30 s on two
cores once the models are in the cache.
"""

from __future__ import annotations

import importlib.metadata
import json
import os
import shutil
import subprocess
import sys
import sysconfig
import venv
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "src" / "vgtarm"
EXAMPLES = sorted((ROOT / "examples").glob("*.toml"))
#: Seconds a step (a build, an install, one command) may take before the test fails.
LIMIT = 600
#: The short path: rows every millisecond for 20 ms, the tip going down 0.5 mm from home.
PATH_ROWS, PATH_DT, PATH_DROP = 21, 1e-3, 5e-4

#: Run in the new environment through the public API: each robot's joint values and tip at home.
HOME_SCRIPT = """
import json, sys
import vgtarm
homes = {}
for config in sys.argv[1:]:
    robot = vgtarm.load_robot(config)
    home = [float(v) for v in robot.parameters.home]
    fk = robot.forward_kinematics(home)
    homes[config] = {"home": home, "tip": [float(v) for v in robot.tip_position(home)], "kind": robot.backend.kind}
print(json.dumps({"vgtarm": vgtarm.__file__, "path": sys.path, "robots": homes, "fk": type(fk).__name__}))
"""


def _ignored(folder: str, names: list[str]) -> list[str]:
    return [n for n in names if n == "__pycache__" or n.endswith((".pyc", ".egg-info"))]


def _package_files(package: Path) -> set[str]:
    """Every file of the package folder, as the wheel names it (``vgtarm/...``), ``__pycache__`` aside."""
    return {
        "vgtarm/" + path.relative_to(package).as_posix()
        for path in package.rglob("*")
        if path.is_file() and "__pycache__" not in path.parts and path.suffix != ".pyc"
    }


def _offline_build_possible() -> bool:
    """Whether this environment has the build system's needs (``setuptools>=68``, ``wheel``)."""
    try:
        major = int(importlib.metadata.version("setuptools").split(".")[0])
        importlib.metadata.version("wheel")
    except (importlib.metadata.PackageNotFoundError, ValueError):
        return False
    return major >= 68


def _run(argv: list[str], *, cwd: Path, env: dict[str, str] | None = None) -> str:
    """Run ``argv``; its standard output (it must succeed)."""
    done = subprocess.run(
        argv, cwd=cwd, env=env, capture_output=True, text=True, timeout=LIMIT, stdin=subprocess.DEVNULL
    )
    said = f"{done.stdout[-2000:]}\n{done.stderr[-3000:]}"
    assert done.returncode == 0, f"{' '.join(argv)[:300]}: exit {done.returncode}\n{said}"
    return done.stdout


def _build_wheel(tmp: Path) -> Path:
    """The wheel built from a copy of the repository's package files (the tree itself is left as it is)."""
    source = tmp / "source"
    source.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, source / name)
    shutil.copytree(PACKAGE, source / "src" / "vgtarm", ignore=_ignored)
    dist = tmp / "dist"
    command = [sys.executable, "-m", "pip", "wheel", "--no-deps", "--disable-pip-version-check", "-q", "-w", str(dist)]
    if _offline_build_possible():
        command += ["--no-build-isolation", "--no-index"]
    _run([*command, str(source)], cwd=tmp)
    wheels = sorted(dist.glob("vgtarm-*.whl"))
    assert len(wheels) == 1, wheels
    return wheels[0]


def _new_environment(tmp: Path, wheel: Path) -> tuple[Path, Path]:
    """A new virtual environment with the wheel installed and this one's dependencies in view: its
    Python and its ``site-packages``."""
    folder = tmp / "env"
    venv.create(folder, with_pip=False, symlinks=True)
    python = folder / "bin" / "python"
    purelib = Path(_run([str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"], cwd=tmp).strip())
    ours = {sysconfig.get_path("purelib"), sysconfig.get_path("platlib")}
    (purelib / "zz_test_dependencies.pth").write_text("".join(f"{p}\n" for p in sorted(ours)))
    pip = [sys.executable, "-m", "pip", "--python", str(python), "--disable-pip-version-check"]
    _run([*pip, "install", "-q", "--no-deps", "--no-index", str(wheel)], cwd=tmp)
    return python, purelib


def test_the_wheel_holds_every_package_file_and_runs_every_example(tmp_path: Path) -> None:
    assert EXAMPLES, "no examples/*.toml"
    wheel = _build_wheel(tmp_path)
    with zipfile.ZipFile(wheel) as archive:
        held = set(archive.namelist())
    missing = sorted(_package_files(tmp_path / "source" / "src" / "vgtarm") - held)
    assert not missing, f"files under src/vgtarm missing from the wheel (pyproject's package-data): {missing}"
    assert any(name.startswith("vgtarm/model/recursive/csrc/") for name in held)

    python, site = _new_environment(tmp_path, wheel)
    script = python.parent / "vgtarm"
    assert script.is_file(), "the wheel installed no vgtarm command"
    work = tmp_path / "work"  # outside the repository: nothing is found through the working folder
    work.mkdir()
    configs = []
    for example in EXAMPLES:
        shutil.copy(example, work / example.name)
        configs.append(example.name)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV", "PYTHONSTARTUP")}
    env.update(PYTHONNOUSERSITE="1", VGTARM_BACKEND="compiled")

    found = json.loads(_run([str(python), "-c", HOME_SCRIPT, *configs], cwd=work, env=env).splitlines()[-1])
    installed = Path(found["vgtarm"]).resolve()
    assert installed.is_relative_to(site.resolve()), f"vgtarm was imported from {installed}, not the new environment"
    # the editable install's folder (named by its .pth in this environment's site-packages) is not on the new path
    assert PACKAGE.parent not in [Path(entry).resolve() for entry in found["path"] if entry], found["path"]
    assert found["fk"] == "ForwardKinematics"
    for config in configs:
        robot = found["robots"][config]
        out = _run([str(script), "fk", "-q", "--config", config, *map(repr, robot["home"])], cwd=work, env=env)
        tip_line = next(line for line in out.splitlines() if line.startswith("tip"))
        tip = [float(v) for v in tip_line.split("[", 1)[1].split("]", 1)[0].split(",")]
        assert tip == pytest.approx(robot["tip"], abs=1e-9), (config, tip_line)

        x, y, z = robot["tip"]
        rows = [f"{k * PATH_DT!r},{x!r},{y!r},{z - PATH_DROP * k / (PATH_ROWS - 1)!r}" for k in range(PATH_ROWS)]
        path = work / f"{Path(config).stem}_path.csv"
        path.write_text("t,x,y,z\n" + "\n".join(rows) + "\n")
        run = work / f"{Path(config).stem}_run"
        simulate = [str(script), "simulate", "-q", "--config", config, "--path", path.name, "--out", run.name]
        _run(simulate, cwd=work, env=env)
        summary = json.loads((run / "summary.json").read_text())
        assert summary["success"] and summary["max_tip_error_m"] < 1e-3, (config, summary["max_tip_error_m"])
        assert summary["backend"] == robot["kind"], (config, summary["backend"])
    if "tapered_thirty.toml" in found["robots"]:  # the stack that found the missing folder: its C, from the wheel
        assert found["robots"]["tapered_thirty.toml"]["kind"] == "recursive"
