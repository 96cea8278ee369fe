"""Robot configuration: the reference file and every kind of bad file."""

from __future__ import annotations

import copy
import dataclasses
import tomllib
from importlib import resources

import numpy as np
import pytest

import vgtarm
from vgtarm.model.parameters import load_parameters, parameters_from_dict

REFERENCE = tomllib.loads(resources.files("vgtarm.model.data").joinpath("reference_robot.toml").read_text())


def write_toml(path, data) -> None:
    """A minimal TOML writer for the nested dicts and lists of a robot file."""

    def value(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{k} = {value(x)}" for k, x in v.items()) + " }"
        if isinstance(v, str):
            return '"' + v + '"'
        return repr(v)

    lines = [f"{k} = {value(v)}" for k, v in data.items() if not isinstance(v, dict)]
    for k, v in data.items():
        if isinstance(v, dict):
            lines.append(f"[{k}]")
            lines += [f"{kk} = {value(vv)}" for kk, vv in v.items()]
    path.write_text("\n".join(lines) + "\n")


def test_reference_robot_matches_the_spec():
    p = load_parameters()
    assert p.b == (0.15, 0.15) and p.d == (0.10, 0.10) and p.h1 == 0.10
    assert [b.mass for b in p.bodies] == [2.75, 2.75, 0.75]
    assert p.bodies[1].inertia[0][1] == pytest.approx(-0.09e-3)
    assert p.viscous == (200.0,) * 6 + (0.0,)
    assert p.home[0] == pytest.approx(np.hypot(0.05, 0.28), abs=1e-12)
    assert p.home[2] == pytest.approx(np.hypot(0.25, 0.28), abs=1e-12)
    assert p.vector().shape == (45,)


def test_a_written_file_round_trips(tmp_path):
    file = tmp_path / "robot.toml"
    write_toml(file, REFERENCE)
    assert load_parameters(file) == load_parameters()


def mutated(change):
    data = copy.deepcopy(REFERENCE)
    change(data)
    return data


def set_in(path, value):
    def change(data):
        node = data
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value

    return change


def delete(path):
    def change(data):
        node = data
        for key in path[:-1]:
            node = node[key]
        del node[path[-1]]

    return change


BAD_CONFIGURATIONS = {
    "negative mass": (set_in(["bodies", "platform1", "mass"], -2.75), r"bodies\.platform1\.mass.*-2\.75.*positive"),
    "zero mass": (set_in(["bodies", "end_effector", "mass"], 0.0), r"bodies\.end_effector\.mass.*positive"),
    "asymmetric inertia": (
        set_in(["bodies", "platform2", "inertia"], [[0.0176, -0.0001, 0], [0.0001, 0.0175, 0], [0, 0, 0.0346]]),
        r"bodies\.platform2\.inertia.*symmetric",
    ),
    "inertia not positive definite": (
        set_in(["bodies", "platform1", "inertia"], [[0.01, 0, 0], [0, -0.01, 0], [0, 0, 0.02]]),
        r"bodies\.platform1\.inertia.*positive definite",
    ),
    "inertia breaks the triangle inequality": (
        set_in(["bodies", "platform1", "inertia"], [[0.01, 0, 0], [0, 0.01, 0], [0, 0, 0.03]]),
        r"bodies\.platform1\.inertia.*triangle inequality",
    ),
    "d >= b": (set_in(["geometry", "module2"], {"b": 0.1, "d": 0.12}), r"geometry\.module2\.d.*0\.12.*d < b"),
    "inverted limits": (set_in(["limits", "p1"], [0.46, 0.30]), r"limits\.p1.*inverted or empty"),
    "empty limits": (set_in(["limits", "s2"], [0.3, 0.3]), r"limits\.s2.*inverted or empty"),
    "unknown top-level key": (set_in(["colour"], "red"), r"unknown key 'colour'"),
    "unknown nested key": (set_in(["bodies", "platform1", "volume"], 1.0), r"unknown key 'bodies\.platform1\.volume'"),
    "missing key": (delete(["geometry", "h1"]), r"missing key 'geometry\.h1'"),
    "home outside the limits": (
        set_in(["home", "q"], [0.4, 0.28, 0.37, 0.28, 0.28, 0.37, 0.0]),
        r"home\.q\[0\] \(s1\).*inside the limits",
    ),
    "home that cannot be assembled": (
        set_in(["home", "q"], [0.22, 0.30, 0.45, 0.28, 0.28, 0.37, 0.0]),
        r"home\.q.*assembled.*module 1.*s \+ 2d > p",
    ),
    "negative friction": (set_in(["friction", "viscous"], [200.0] * 6 + [-1.0]), r"friction\.viscous\[6\] \(psi3\)"),
    "wrong type": (set_in(["geometry", "h1"], "tall"), r"geometry\.h1.*'tall'.*a number"),
    "wrong length": (set_in(["environment", "gravity"], [0, -9.81]), r"environment\.gravity.*3 numbers"),
}


@pytest.mark.parametrize("case", sorted(BAD_CONFIGURATIONS))
def test_bad_configuration_is_rejected_with_field_and_value(tmp_path, case):
    change, message = BAD_CONFIGURATIONS[case]
    file = tmp_path / "robot.toml"
    write_toml(file, mutated(change))
    with pytest.raises(vgtarm.ConfigError, match=message) as info:
        load_parameters(file)
    assert str(file) in str(info.value)


def test_missing_file_and_bad_toml_are_config_errors(tmp_path):
    with pytest.raises(vgtarm.ConfigError, match="not found"):
        load_parameters(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[geometry\nh1 = 1")
    with pytest.raises(vgtarm.ConfigError, match="not valid TOML"):
        load_parameters(bad)


def test_replace_revalidates_and_scaled_copies_change_only_inertial_values():
    p = load_parameters()
    with pytest.raises(vgtarm.ConfigError, match="h1"):
        dataclasses.replace(p, h1=-1.0)
    wrong = p.scaled(mass=1.2, inertia=0.8, friction=0.5)
    assert wrong.bodies[0].mass == pytest.approx(3.3)
    assert wrong.bodies[2].inertia[2][2] == pytest.approx(0.8 * 0.884e-3)
    assert wrong.viscous[0] == 100.0
    assert wrong.modules == p.modules and wrong.home.tolist() == p.home.tolist()


def test_parameters_from_dict_names_its_source():
    with pytest.raises(vgtarm.ConfigError, match="<mine>"):
        parameters_from_dict({"geometry": {}}, source="<mine>")
