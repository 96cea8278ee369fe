"""`import vgtarm` is the whole library: every capability of the command line is a name of the
package, each the very object of the module that defines it, loaded on first use."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

import vgtarm

#: What a user of the command line reaches from Python, by name (issue: the library's front door).
CAPABILITIES = (
    "load_robot",
    "Robot",
    "inverse_kinematics",
    "solve_point",
    "IKOptions",
    "ComputedForceControl",
    "SwitchingControl",
    "Scenario",
    "ExternalForce",
    "simulate",
    "run_case",
    "run_study",
    "load_study",
    "reproduce",
    "export_controller",
    "to_mjcf",
    "comparison_figure",
    "plot_tip_error",
    "save_figure",
    "paths",
)


@pytest.mark.parametrize("name", vgtarm.__all__)
def test_every_public_name_is_the_defining_modules_object(name):
    value = getattr(vgtarm, name)
    if name in vgtarm._MODULES:
        assert value is importlib.import_module(f"vgtarm.{name}")
    else:
        module, attribute = vgtarm._SOURCES[name]
        assert value is getattr(importlib.import_module(f"vgtarm.{module}"), attribute)


def test_the_command_lines_capabilities_are_public_names():
    assert set(CAPABILITIES) <= set(vgtarm.__all__)
    assert sorted(vgtarm.__all__) == sorted([*vgtarm._SOURCES, *vgtarm._MODULES])


def test_dir_lists_the_public_names_only():
    names = dir(vgtarm)
    assert set(vgtarm.__all__) <= set(names)
    for helper in ("Any", "TYPE_CHECKING", "importlib", "annotations"):
        assert helper not in names


def test_the_version_is_the_packages():
    from vgtarm.version import __version__

    assert vgtarm.__version__ == __version__ and "__version__" in dir(vgtarm)


def test_an_unknown_name_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'simulat'"):
        vgtarm.simulat  # noqa: B018


def test_import_vgtarm_loads_nothing_heavy():
    """The front door costs nothing until a name is used (the CLI's Ctrl-C handling comes first)."""
    code = "import sys, vgtarm; print(sorted(m for m in ('numpy', 'casadi', 'matplotlib') if m in sys.modules))"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"


def test_run_study_refuses_what_is_not_a_study(tmp_path):
    with pytest.raises(vgtarm.InputError, match="study = 3: expected a study file"):
        vgtarm.run_study(3, tmp_path / "out")  # type: ignore[arg-type]
    (tmp_path / "file").write_text("x")
    study = vgtarm.load_study(_example_study(tmp_path))
    with pytest.raises(vgtarm.InputError, match="is a file, not a folder"):
        vgtarm.run_study(study, tmp_path / "file")


def _example_study(folder):
    from vgtarm.study.example import EXAMPLE

    path = folder / "study.toml"
    path.write_text(EXAMPLE)
    return path
