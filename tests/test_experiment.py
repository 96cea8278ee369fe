"""The experiment record and its options declared once: the command line's flags, the study's
parameters and the presets follow the declarations; an experiment runs as the case runner runs
the same settings, bit for bit; its record is stored in summary.json and restores the run."""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

import vgtarm
from vgtarm.app.cli.command import build_parser, main
from vgtarm.errors import InputError
from vgtarm.experiment import Experiment
from vgtarm.experiment.cases import run_case
from vgtarm.experiment.options import all_options, study_options
from vgtarm.experiment.presets import PRESETS, applied_settings
from vgtarm.option import Option
from vgtarm.simulation import Scenario
from vgtarm.study.spec import all_parameters

DURATION = 0.03


def _simulate_parser() -> argparse.ArgumentParser:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices["simulate"]


def _valid(option: Option) -> str:
    """A value of ``option`` away from its default, as command-line text."""
    if option.choices:
        return next(c for c in option.choices if c != option.default)
    if option.kind is int:
        return str(int(option.low or 0) + 2)
    low = 0.0 if option.low is None else option.low
    return repr(low + 0.5 * (1.0 if option.high is None else min(1.0, option.high - low)))


def test_every_declared_option_with_a_flag_is_a_flag_of_simulate_with_its_name_and_default():
    parser = _simulate_parser()
    by_dest = {a.dest: a for a in parser._actions}
    flagged = {name: o for name, o in all_options().items() if o.cli_flag}
    assert {"observer_gain", "encoder_resolution", "tool_force_speed", "controller", "criterion"} <= set(flagged)
    for name, option in flagged.items():
        action = by_dest[name]
        assert option.cli_flag in action.option_strings, name
        assert action.default == (False if option.kind is bool else option.default), name
        if option.kind is not bool:
            value = _valid(option)
            parsed = parser.parse_args(["--case", "1", option.cli_flag, value])
            assert getattr(parsed, name) == option.kind(value), name


def test_the_scenario_declares_its_options_with_its_defaults_and_the_study_takes_them():
    fields = {f.name: f.default for f in dataclasses.fields(Scenario) if f.default is not dataclasses.MISSING}
    declared = Scenario.options()
    assert set(declared) <= set(fields) and "observer_gain" in declared
    for name, option in declared.items():
        assert option.default == fields[name], name
    assert set(study_options()) == set(all_parameters())  # the study's parameters are the declared ones
    assert "seed" not in all_parameters() and "duration" not in all_parameters()  # a study gives these apart


@pytest.mark.parametrize(
    ("name", "value", "expected"),
    [
        ("observer_gain", -1.0, "observer_gain = -1.0: expected a finite number > 0 (1/s)"),
        ("observer_gain", True, "observer_gain = True: expected a finite number > 0"),
        ("encoder_resolution", math.nan, "encoder_resolution = nan: expected an encoder step >= 0 (m)"),
        ("tool_force_speed", 0.0, "tool_force_speed = 0.0: expected a speed > 0 (m/s)"),
        ("substeps", 2.0, "substeps = 2.0: expected a whole number from 1 to 1,000,000"),
        ("controller", "pid", "controller = 'pid': expected one of ['cfc', 'scm']"),
        ("horizon", 0, "horizon = 0: expected a whole number from 1 to 10,000 (control periods; SCM)"),
    ],
)
def test_a_value_outside_its_declaration_is_refused_in_one_line(name, value, expected):
    with pytest.raises(InputError) as error:
        all_options()[name].convert(value)
    assert str(error.value).startswith(expected) and "\n" not in str(error.value)
    with pytest.raises(InputError, match="^" + expected.replace("(", r"\(").replace(")", r"\)").replace("[", r"\[")):
        Experiment(case=1, **{name: value})


def test_numpy_scalars_are_numbers_and_ints_become_floats_where_a_float_is_declared():
    option = all_options()["observer_gain"]
    assert option.convert(np.float32(250.0)) == 250.0 and isinstance(option.convert(np.int64(3)), float)
    assert all_options()["horizon"].convert(np.int16(7)) == 7
    with pytest.raises(InputError):
        all_options()["horizon"].convert(7.0)  # a whole number is not a float


def test_an_unknown_option_and_an_experiment_without_one_path_are_refused():
    with pytest.raises(InputError, match=r"unknown option 'obsrver': expected one of \['controller'"):
        Experiment(case=1, obsrver="momentum")
    with pytest.raises(InputError, match="give exactly one of case"):
        Experiment()
    with pytest.raises(InputError, match="case = 3: expected one of"):
        Experiment(case=3)
    with pytest.raises(InputError, match="preset = 'fast': expected None or one of"):
        Experiment(case=1, preset="fast")
    with pytest.raises(InputError, match="tool_force_speed = 0.01 without tool_force_feedforward"):
        Experiment(case=1, tool_force_speed=0.01)  # two options together: the scenario's own check


def test_a_preset_fills_what_is_not_given_and_its_dependent_settings_give_way():
    low = PRESETS["low-force"]
    plain = Experiment(case=2, preset="low-force")
    assert plain.observer == "momentum" and plain.observer_gain == low["observer_gain"]
    assert plain.kp is None and not plain.tool_force_feedforward  # no tool force: the case's gains
    forced = Experiment(case=2, preset="low-force", external_force=True, kp=1e4)
    assert forced.kp == 1e4 and forced.kv == low["kv"] and forced.tool_force_feedforward
    assert Experiment(case=2, preset="low-force", external_force=True, controller="scm").kp is None  # cfc's gains
    off = Experiment(case=2, preset="low-force", observer="none", estimator="difference")
    assert off.observer_gain is None and off.estimator_bandwidth_hz is None  # they need what was replaced
    sensor = applied_settings("low-force", {"force_sensor": True, "external_force": True})
    assert not {"observer", "observer_gain", "tool_force_feedforward"} & set(sensor)


def test_an_experiment_runs_as_the_case_runner_runs_the_same_settings_bit_for_bit(robot):
    from vgtarm.experiment.cases import joint_reference

    experiment = Experiment(
        case=2, controller="cfc", external_force=True, observer="momentum", observer_gain=300.0, duration=DURATION
    )
    ours = experiment.run()
    reference = joint_reference(robot, 2, duration=DURATION)
    theirs = run_case(robot, 2, external_force=True, observer="momentum", observer_gain=300.0, reference=reference)
    for name in ("q", "qd", "effort", "tip_error", "f_ext"):
        assert np.array_equal(getattr(ours, name), getattr(theirs, name), equal_nan=True), name
    assert ours.metadata["experiment"] == experiment.record()


def test_the_record_is_stored_in_summary_json_and_restores_the_run(tmp_path: Path, capsys):
    out = tmp_path / "run"
    argv = ["simulate", "--case", "1", "--duration", repr(DURATION), "--observer", "momentum", "--out", str(out), "-q"]
    assert main(argv) == 0
    capsys.readouterr()
    record = json.loads((out / "summary.json").read_text())["experiment"]
    assert record["case"] == 1 and record["options"]["observer"] == "momentum"
    assert record["robot"]["source"].startswith("<reference robot")  # the shipped robot: restored as the paper's
    again = Experiment.from_record(record)
    assert again.record()["options"] == record["options"] and again.robot is None and again.observer == "momentum"
    rerun = again.run()
    stored = np.genfromtxt(out / "timeseries.csv", delimiter=",", names=True)
    assert np.array_equal(stored["tip_error"], rerun.tip_error)  # the CSV keeps 17 digits: an exact round trip
    with pytest.raises(InputError, match="experiment record field 'colour'"):
        Experiment.from_record({**record, "colour": "red"})


def test_the_experiment_is_reachable_from_the_front_door():
    assert vgtarm.Experiment is Experiment and "low-force" in vgtarm.PRESETS
    experiment = vgtarm.Experiment(case=1, controller="scm", horizon=10)
    assert experiment.replace(horizon=12).horizon == 12 and experiment.horizon == 10
    with pytest.raises(TypeError, match="frozen"):
        experiment.options["horizon"] = 3  # type: ignore[index]
