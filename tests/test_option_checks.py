"""Option and argument checks of issue 33, item 7: each refusal is one line naming the option or
the argument, its value and what was expected, before any work (nothing written, no model built).

- ``export controller`` checks what it is given with the checks ``simulate`` uses (the gains as
  ``simulate --kp/--kv`` reads them, :func:`vgtarm.control.gains.check_definite`; the controller
  model against the robot, :func:`vgtarm.simulation.checks.model_of_plant`; the twist encoder,
  :func:`vgtarm.simulation.sensing.check_twist_resolution`);
- a preset never overrides an option the user typed (known from what argparse parsed, not from the
  default), never sets what the user's options rule out, and a refusal of one of its values says it
  came from the preset; an option the run would not use is refused;
- the Python API refuses masked arrays with masked entries, a GA cost that returns NaN, and seeds
  outside 0 to 2**63 - 1, wherever a seed enters.
"""

from __future__ import annotations

import argparse
import re
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import vgtarm
from vgtarm import ga, paths
from vgtarm.app.cli import presets
from vgtarm.app.cli.command import build_parser, main
from vgtarm.control.gains import KP_MAX, KV_MAX, Gains, check_definite, gain_matrix
from vgtarm.errors import ConfigError, InputError, PathError
from vgtarm.export import export_controller
from vgtarm.model.parameters import load_parameters
from vgtarm.simulation import JointReference, Scenario, checks
from vgtarm.simulation.sensing import sensing_settings
from vgtarm.study.spec import parse_study

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
PRESET = presets.PRESETS["low-force"]
TOO_LARGE_SEED = 2**63


def refused(capsys: pytest.CaptureFixture[str], argv: list[str], status: int = 1) -> str:
    """The one error line of the command ``argv`` (in this process), which must end with ``status``
    and print nothing else (no NumPy warning either)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert main(argv) == status
    out, err = capsys.readouterr()
    assert not caught, [str(w.message) for w in caught]
    assert out == "" and err.count("\n") == 1 and err.startswith("vgtarm: error: "), err
    return err


@pytest.fixture(scope="module")
def heavy_model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The reference robot with every body 360,000 times as heavy: no model of it."""
    text = (Path(vgtarm.__file__).parent / "model" / "data" / "reference_robot.toml").read_text()
    for mass in ("2.75", "0.75"):
        text = text.replace(f"mass = {mass}\n", f"mass = {float(mass) * 360_000}\n")
    file = tmp_path_factory.mktemp("models") / "heavy.toml"
    file.write_text(text)
    return file


# -- export controller: the checks of simulate ----------------------------------------------------

GAIN_CASES = [
    (["--kp", "-1"], "--kp '-1': expected one number for every joint or 7 numbers"),
    (["--kp", "0"], "--kp '0': expected"),
    (["--kv", "inf"], "--kv 'inf': expected"),
    (["--kv", "nan"], "--kv 'nan': expected"),
    (["--kp", "1,2,3"], "--kp '1,2,3': expected"),
    (["--kp", "1,2,3,4,5,6,-7"], "each finite and > 0"),
    (["--kp", "\u0661\u0660\u0660"], "--kp '\u0661\u0660\u0660': expected"),  # Arabic-Indic 100: float() reads it
    (["--kv", "\uff11\uff10\uff10"], "written in ASCII digits (0-9)"),  # full-width 100
    (["--kp", "100,100,100,100,100,100,\u0661"], "written in ASCII digits"),
    (["--kp", "1e300"], "--kp '1e300': expected one number for every joint or 7 numbers"),
    (["--kp", "2e12"], "and at most 1e+12"),
    (["--kv", "1.5e6"], "--kv '1.5e6': expected"),
]


@pytest.mark.parametrize(("options", "message"), GAIN_CASES, ids=[" ".join(c[0]) for c in GAIN_CASES])
@pytest.mark.parametrize("command", ["simulate", "export"])
def test_the_export_refuses_the_gains_simulate_refuses_in_the_same_line(
    command: str, options: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    argv = ["simulate", "--case", "1", "--out", str(out)] if command == "simulate" else ["export", "controller"]
    err = refused(capsys, [*argv, *(["--out", str(out)] if command == "export" else []), *options])
    assert message in err
    assert not out.exists()


EXPORT_CASES = [
    (
        ["--config", str(EXAMPLES / "planar_module.toml"), "--twist-resolution", "1e-3"],
        "--twist-resolution 0.001: the robot has no twist joint (its 3 joints are legs, in m)",
    ),
    (["--velocity-filter", "50"], "--velocity-filter 50.0: filters the velocities differenced from encoders"),
]


@pytest.mark.parametrize(("options", "message"), EXPORT_CASES, ids=["twist without a twist", "filter without encoders"])
def test_an_export_option_that_would_be_ignored_is_refused_before_any_build(
    options: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    err = refused(capsys, ["export", "controller", "--out", str(tmp_path / "out"), *options])
    assert message in err
    assert not (tmp_path / "out").exists()


def test_a_controller_model_far_from_the_robot_is_refused_as_simulate_refuses_it(
    heavy_model: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    err = refused(capsys, ["export", "controller", "--out", str(tmp_path / "out"), "--model-config", str(heavy_model)])
    assert "--model-config" in err and "its mass is 3.6e+05 times the plant's" in err and "[0.001, 1000]" in err
    assert not (tmp_path / "out").exists()
    # the check simulate runs on its controller model against the plant (checks.arguments)
    with pytest.raises(InputError, match="controller_model: its mass is 3.6e"):
        checks.model_of_plant(load_parameters(None), load_parameters(heavy_model))


def _symmetric(coupling: float) -> np.ndarray:
    """100 on the diagonal, ``coupling`` between the first two joints."""
    matrix = np.diag(np.full(7, 100.0))
    matrix[0, 1] = matrix[1, 0] = coupling
    return matrix


MATRIX_CASES = {
    "asymmetric": (np.triu(np.full((7, 7), 5.0)) + np.eye(7) * 100.0, "must be a symmetric matrix, got Kp[0, 1] = 5.0"),
    "negative diagonal": (-100.0 * np.eye(7), "each gain > 0), got Kp[0, 0] = -100.0"),
    "indefinite": (_symmetric(500.0), "positive definite, got a matrix whose smallest eigenvalue is -400"),
    "zero": (0.0, "each gain > 0), got Kp[0, 0] = 0.0"),
    "beyond the largest": (1e300, "Kp must be at most 1e+12 on every element"),
    "one beyond the largest": (np.diag([100.0] * 6 + [2e12]), "got Kp[6, 6] = 2000000000000.0"),
}


@pytest.mark.parametrize("case", MATRIX_CASES)
def test_gain_matrices_a_controller_cannot_run_with_are_refused_by_the_export(
    case: str, robot: vgtarm.Robot, tmp_path: Path
) -> None:
    kp, message = MATRIX_CASES[case]
    with pytest.raises(InputError, match=re.escape(message)) as caught:
        export_controller(robot, tmp_path / "out", kp=kp, check_build=False)
    assert "\n" not in str(caught.value)
    assert not (tmp_path / "out").exists()


def test_a_diagonal_and_a_symmetric_positive_definite_matrix_pass_the_one_check() -> None:
    check_definite(gain_matrix([1.0, 2, 3, 4, 5, 6, 7], "Kp"), "Kp")
    check_definite(gain_matrix(_symmetric(50.0), "Kp"), "Kp")


@pytest.mark.parametrize(("name", "largest"), [("Kp", KP_MAX), ("--kp", KP_MAX), ("Kv", KV_MAX), ("--kv", KV_MAX)])
def test_the_one_check_bounds_the_gains_at_the_documented_maximum(name: str, largest: float) -> None:
    """At most 1e12 (Kp) and 1e6 (Kv) on every element: beyond, no control period vgtarm runs
    (down to 1 us) is stable; a huge gain is refused before its eigenvalues overflow."""
    check_definite(gain_matrix(largest, name), name)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for value in (largest * 1.01, 1e300, _symmetric(50.0) * largest / 10):
            with pytest.raises(
                InputError, match="^" + re.escape(f"{name} must be at most {largest:g} on every element")
            ):
                check_definite(gain_matrix(value, name), name)


#: Options read by argparse's ``type=float``/``type=int`` or vgtarm's number types, per command.
NUMBER_OPTIONS = [
    (["simulate", "--case", "1"], "--duration"),
    (["simulate", "--case", "1"], "--seed"),
    (["simulate", "--case", "1"], "--model-mass"),
    (["simulate", "--case", "1"], "--tool-force-speed"),
    (["export", "controller", "--out", "x"], "--dt"),
    (["export", "controller", "--out", "x"], "--observer-gain"),
    (["export", "mjcf", "--out", "x.xml"], "--digits"),
    (["animate", "run", "--out", "x.gif"], "--fps"),
    (["reproduce"], "--seeds"),
]


@pytest.mark.parametrize(
    "text", ["\u0661", "\uff11", "\u0661\u066b\u0665"], ids=["arabic-indic", "full-width", "decimal sign"]
)
@pytest.mark.parametrize(("command", "option"), NUMBER_OPTIONS, ids=[f"{c[0]} {o}" for c, o in NUMBER_OPTIONS])
def test_a_number_not_written_in_ascii_digits_is_refused_naming_the_option(
    command: list[str], option: str, text: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as caught:
        main([*command, option, text])
    assert caught.value.code == 2
    err = capsys.readouterr().err.splitlines()
    assert err[-1].endswith(f"error: argument {option}: expected a number written in ASCII digits (0-9), got {text!r}")


def test_an_infinite_gain_is_one_line_without_a_numpy_warning() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # inf times the identity's zeros was a RuntimeWarning
        for value in (np.inf, -np.inf, np.nan):
            with pytest.raises(InputError, match=r"Kv must be finite, got Kv\[0, 0\] = "):
                Gains.of(15000.0, value)


def test_a_twist_resolution_on_a_robot_without_a_twist_is_refused_by_the_shared_sensing_check() -> None:
    with pytest.raises(InputError, match="twist_resolution = 0.001: the robot has no twist joint"):
        sensing_settings(("m", "m", "m"), 1e-3, "none", None, False, 1e-6, 1e-3, 0.0, 100.0)
    legs = sensing_settings(("m", "m", "m"), 1e-3, "none", None, False, 1e-6, None, 0.0, 100.0)
    assert legs.resolution.tolist() == [1e-6] * 3  # encoders on the legs, no twist: as before


# -- presets and options the run would not use -------------------------------------------------------


def _parsed(*options: str) -> argparse.Namespace:
    args = build_parser().parse_args(["simulate", "--case", "1", *options])
    presets.apply_preset(args)
    return args


def test_an_option_typed_with_its_default_value_keeps_it_beside_the_preset() -> None:
    args = _parsed("--preset", "low-force", "--observer", "none", "--encoder-resolution", "1e-6")
    assert args.observer == "none" and args.observer_gain is None  # no observer, so none of its gain
    assert args.estimator == "kalman" and args.criterion == "effort"  # the preset's other settings
    typed = _parsed("--preset", "low-force", "--criterion", "joint_limits", "--encoder-resolution", "1e-6")
    assert typed.criterion == "joint_limits"
    assert _parsed("--preset", "low-force").observer == "momentum"  # not typed: the preset's


def test_the_preset_sets_its_gains_with_computed_force_control_only() -> None:
    cfc = _parsed("--preset", "low-force", "--external-force")
    assert (cfc.kp, cfc.kv) == (repr(PRESET["kp"]), repr(PRESET["kv"])) and cfc.tool_force_feedforward
    scm = _parsed("--preset", "low-force", "--external-force", "--controller", "scm")
    assert scm.kp is None and scm.kv is None and scm.tool_force_feedforward  # the case's gains: the GA's genes hit them
    sensor = _parsed("--preset", "low-force", "--external-force", "--force-sensor")
    assert sensor.observer == "none" and sensor.observer_gain is None and not sensor.tool_force_feedforward


def test_the_preset_with_the_switching_method_and_the_tool_force_runs(tmp_path: Path, capsys: Any) -> None:
    argv = ["simulate", "--case", "2", "--duration", "0.01", "--quiet", "--controller", "scm", "--external-force"]
    assert main([*argv, "--preset", "low-force", "--encoder-resolution", "1e-6"]) == 0
    out, err = capsys.readouterr()
    assert err == "" and "20000" not in out


PRESET_REFUSALS = [
    (["--preset", "low-force"], "--preset low-force sets --estimator kalman, which estimates the state from encoder"),
    (
        ["--preset", "low-force", "--encoder-resolution", "1e-6", "--velocity-noise", "0.01", "--duration", "0.005"],
        "with --preset low-force, which set --criterion effort, --observer momentum, --observer-gain 400, --estimator"
        " kalman, --estimator-bandwidth 120: velocity_noise = 0.01 with estimator = 'kalman'",
    ),
]


@pytest.mark.parametrize(("options", "message"), PRESET_REFUSALS, ids=["no encoders", "noise"])
def test_a_refusal_of_a_value_the_preset_set_says_the_preset_set_it(
    options: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    err = refused(capsys, ["simulate", "--case", "1", "--quiet", *options])
    assert message in err


UNUSED = [
    (["--scm-variant", "safe"], "--scm-variant 'safe': an option of the switching method; expected --controller scm"),
    (["--scm-variant", "paper", "--horizon", "20"], "--scm-variant 'paper' --horizon 20: options of the switching"),
    (["--velocity-filter", "100"], "--velocity-filter 100.0: filters the velocities differenced from encoders"),
]


@pytest.mark.parametrize(("options", "message"), UNUSED, ids=["variant", "variant and horizon", "filter"])
def test_an_option_the_run_would_not_use_is_refused_even_at_its_default_value(
    options: list[str], message: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    err = refused(capsys, ["simulate", "--case", "1", "--controller", "cfc", "--out", str(tmp_path / "o"), *options])
    assert message in err
    assert not (tmp_path / "o").exists()


# -- the Python API: masked arrays, the GA's cost, seeds ---------------------------------------------


def _masked(values: Any, index: int) -> np.ma.MaskedArray:
    mask = np.zeros(np.shape(values), dtype=bool)
    mask.flat[index] = True
    return np.ma.array(values, mask=mask)


def _reference(robot: vgtarm.Robot, q: Any) -> JointReference:
    t = np.arange(3) * 1e-3
    return JointReference(t, q, np.zeros((3, 7)), np.zeros((3, 7)))


MASKED: dict[str, Any] = {
    "forward_kinematics q": (lambda r, q: r.forward_kinematics(_masked(q, 2)), InputError, "q is a masked array"),
    "bias_forces qd": (lambda r, q: r.bias_forces(q, _masked(np.zeros(7), 6)), InputError, "qd is a masked array"),
    "simulate initial_state": (
        lambda r, q: checks.initial_state(r, _reference(r, np.tile(q, (3, 1))), (_masked(q, 0), q * 0)),
        InputError,
        "initial_state q0 is a masked array",
    ),
    "reference q": (lambda r, q: _reference(r, _masked(np.tile(q, (3, 1)), 4)), InputError, "reference q is a masked"),
    "gains": (lambda r, q: Gains.of(_masked(np.full(7, 5.0), 1), 300.0), InputError, "Kp is a masked array"),
    "path samples": (
        lambda r, q: paths.from_samples(_masked([0.0, 0.1, 0.2], 1), np.tile([0.0, 0.0, 0.66], (3, 1))),
        PathError,
        "is a masked array",
    ),
    "GA bounds": (lambda r, q: ga.minimize(np.sum, _masked([0.0, 0.0], 0), [1.0, 1.0]), InputError, "^lower is a"),
}


@pytest.mark.parametrize("case", MASKED)
def test_a_masked_array_with_masked_entries_is_refused_naming_the_argument(case: str, robot: vgtarm.Robot) -> None:
    call, error, message = MASKED[case]
    with pytest.raises(error, match=message) as caught:
        call(robot, robot.parameters.home)
    assert "\n" not in str(caught.value) and "masked entr" in str(caught.value)


def test_a_masked_array_without_a_masked_entry_is_its_data(robot: vgtarm.Robot) -> None:
    q = robot.parameters.home
    np.testing.assert_array_equal(robot.tip_position(np.ma.array(q)), robot.tip_position(q))


def test_a_nan_cost_is_refused_naming_the_individual_and_the_generation() -> None:
    with pytest.raises(InputError, match=r"`cost` returned nan for individual 3 of generation 0 \(genes \[") as caught:
        ga.minimize(lambda x: np.where(np.arange(len(x)) == 3, np.nan, x.sum(axis=1)), [0.0, 0.0], [1.0, 1.0], seed=1)
    assert "\n" not in str(caught.value)
    calls = []

    def later(x: np.ndarray) -> np.ndarray:
        calls.append(len(x))
        return np.full(len(x), np.nan) if len(calls) > 1 else x.sum(axis=1)

    with pytest.raises(InputError, match="of generation 1 "):
        ga.minimize(later, [0.0, 0.0], [1.0, 1.0], seed=1)


def test_a_ga_run_without_a_finite_cost_is_a_failure_with_its_reason() -> None:
    result = ga.minimize(
        lambda x: np.full(len(x), np.inf), [0.0], [1.0], seed=0, options=ga.GAOptions(max_generations=2)
    )
    assert not result.success and result.cost == np.inf and "no individual had a finite cost" in result.reason


SEED_RANGE = "expected a whole number from 0 to 2**63 - 1 = 9223372036854775807"


@pytest.mark.parametrize("seed", [TOO_LARGE_SEED, -1, 2**64, True])
def test_a_seed_outside_the_stored_range_is_refused_wherever_it_enters(seed: Any) -> None:
    with pytest.raises(InputError, match=r"seed = .*: " + SEED_RANGE.replace("*", r"\*")):
        Scenario(seed=seed)
    with pytest.raises(
        InputError, match=r"seed = .*: " + SEED_RANGE.replace("*", r"\*") + ", a numpy Generator or None$"
    ):
        ga.minimize(np.sum, [0.0], [1.0], seed=seed)
    assert Scenario(seed=TOO_LARGE_SEED - 1).seed == ga.MAX_SEED


STUDY_SEEDS = [
    ({"seeds": [0, TOO_LARGE_SEED]}, {}, "study.seeds = [0, 9223372036854775808]: seed 9223372036854775808: expected"),
    ({"seeds": {"start": TOO_LARGE_SEED - 1, "count": 2}}, {}, "the last seed is 9223372036854775808; expected seeds"),
    ({}, {"seed": TOO_LARGE_SEED, "draws": 1}, "random.seed = 9223372036854775808: " + SEED_RANGE),
]


@pytest.mark.parametrize(("study", "random", "message"), STUDY_SEEDS, ids=["list", "range", "random"])
def test_a_study_seed_outside_the_range_is_refused_at_load(study: dict, random: dict, message: str) -> None:
    data: dict[str, Any] = {"study": {"case": 1, "duration": 0.02, **study}, "grid": {"controller": "cfc"}}
    if random:
        data["random"] = {**random, "model_mass": {"uniform": [0.9, 1.1]}}
    with pytest.raises(ConfigError) as caught:
        parse_study(data, source="s.toml")
    assert message in str(caught.value) and "\n" not in str(caught.value)
    assert parse_study({"study": {"case": 1, "seeds": [TOO_LARGE_SEED - 1]}}).seeds == (TOO_LARGE_SEED - 1,)


def test_the_study_command_refuses_the_seed_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    study = tmp_path / "s.toml"
    study.write_text(f'[study]\nname = "s"\ncase = 1\nduration = 0.02\nseeds = [{TOO_LARGE_SEED}]\n')
    err = refused(capsys, ["study", "run", str(study), "--out", str(tmp_path / "results")])
    assert "expected seeds from 0 to 2**63 - 1" in err
    assert not (tmp_path / "results").exists()


@pytest.mark.parametrize("command", [["simulate", "--case", "1"], ["reproduce"], ["check", "mujoco"]])
def test_the_command_line_refuses_a_seed_outside_the_range(command: list[str], capsys: Any) -> None:
    with pytest.raises(SystemExit) as info:
        main([*command, "--seed", str(TOO_LARGE_SEED)])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert f"argument --seed: {SEED_RANGE}, got {TOO_LARGE_SEED}" in err
