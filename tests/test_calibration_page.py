"""The pages of ``vgtarm calibrate`` (``calibration.html``) and ``vgtarm identify``
(``identification.html``): written by the commands on the example measurements
(examples/calibration/) and on simulated leg forces, their numbers against the files the commands
write by other code (``parameters.csv``, ``report.md``, ``base_parameters.csv``) and against
identities (the pose conditioning against the identifiability analysis, each parameter's standard
error bounded by the worst direction's, a hold-out prediction at the noise level and exact on
noise-free data), a hostile robot name and file name shown as written, and both pages opened in a
real headless Chromium."""

from __future__ import annotations

import argparse
import csv
import html
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

import vgtarm
from vgtarm.app.cli import calibrate as calibrate_cli
from vgtarm.app.cli import identify as identify_cli
from vgtarm.app.reports.calibration_page import UNDETERMINED, calibration_markdown
from vgtarm.calibration import dynamic, excitation
from vgtarm.calibration import kinematic as K

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
MEASUREMENTS = EXAMPLES / "calibration" / "measurements.csv"
REFERENCE = ROOT / "src" / "vgtarm" / "model" / "data" / "reference_robot.toml"
#: A robot name (and file name) that would be markup in HTML, Markdown and TOML if not escaped.
HOSTILE = '<script>alert("name")</script> & *bold* | `tick` [x](javascript:alert(1))'
HOSTILE_FILE = "m<img src=x onerror=alert(2)>.csv"
#: Noise of the simulated leg forces and twist torque (N, N m), as tests/test_identification.py.
FORCE_NOISE = 0.5


def _run(module, command: str, *argv: str) -> int:
    parser = argparse.ArgumentParser()
    module.add_parser(parser.add_subparsers())
    args = parser.parse_args([command, *argv])
    return int(args.run(args))


def _hostile_robot(folder: Path) -> Path:
    """The reference robot file under :data:`HOSTILE`'s name."""
    text = re.sub(r'(?m)^name = ".*"$', lambda _: f"name = {json.dumps(HOSTILE)}", REFERENCE.read_text())
    path = folder / "hostile.toml"
    path.write_text(text)
    assert vgtarm.load_robot(path).parameters.name == HOSTILE
    return path


def _text(page: Path) -> str:
    """The page's text as a reader sees it (tags dropped, references resolved, images left out), its
    white space collapsed to single spaces."""
    body = re.sub(r"data:image/png;base64,[A-Za-z0-9+/=]+", "", page.read_text())
    return " ".join(html.unescape(re.sub(r"<[^>]+>", " ", body)).split())


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``vgtarm calibrate`` on the example measurements (the reference robot), its folder."""
    out = tmp_path_factory.mktemp("calibrate") / "fit"
    assert _run(calibrate_cli, "calibrate", "--measurements", str(MEASUREMENTS), "--out", str(out)) == 0
    return out


@pytest.fixture(scope="module")
def identified(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """``vgtarm identify --excite`` (a short search), forces of a perturbed robot along it with
    :data:`FORCE_NOISE`, then ``vgtarm identify --data`` with a robot file named :data:`HOSTILE`:
    the data file and the folder."""
    folder = tmp_path_factory.mktemp("identify")
    assert _run(identify_cli, "identify", "--excite", "--evaluations", "5", "--out", str(folder / "excite")) == 0
    robot = vgtarm.load_robot()
    n = robot.n_joints
    table = np.loadtxt(folder / "excite" / "excitation.csv", delimiter=",", skiprows=1)
    t, q, qd, qdd = table[:, 0], table[:, 1 : 1 + n], table[:, 1 + n : 1 + 2 * n], table[:, 1 + 2 * n :]
    truth = robot.with_parameters(dynamic.perturbed_parameters(robot.parameters, seed=1))
    forces = dynamic.simulated_forces(truth, q, qd, qdd, noise=FORCE_NOISE, seed=1)
    data = folder / "data.csv"
    data.write_text(identify_cli.measurements_csv(robot.joint_names, t, q, qd, qdd, forces))
    config = _hostile_robot(folder)
    out = folder / "out"
    assert _run(identify_cli, "identify", "--data", str(data), "--config", str(config), "--out", str(out)) == 0
    return data, out


# -- the calibration page ----------------------------------------------------------------------------


def test_calibration_page_gives_the_fit_and_every_parameter(calibrated: Path) -> None:
    text = _text(calibrated / "calibration.html")
    with open(calibrated / "parameters.csv", newline="") as stream:
        rows = list(csv.DictReader(stream))
    assert len(rows) == 11
    for row in rows:  # parameters.csv is written by other code, in full precision
        assert f"{row['parameter']} {1e3 * float(row['nominal']):.4f} {1e3 * float(row['fitted']):.4f}" in text
        assert f"{1e3 * float(row['standard_error']):.4f} {row['status']}" in text
    report = (calibrated / "report.md").read_text()
    rms = re.search(r"RMS position residual: ([0-9.]+) mm per coordinate \(nominal model: ([0-9.]+) mm\)", report)
    assert rms is not None
    assert f"calibrated (mm per coordinate) {rms[1]}" in text and f"nominal model (mm per coordinate) {rms[2]}" in text
    assert "Every parameter is determined" in text and "held at nominal" not in text
    assert f"{UNDETERMINED} no" not in text and "nan" not in text.lower().split()
    assert "Corrected robot file: robot.toml" in text


def test_pose_conditioning_agrees_with_the_identifiability_analysis(robot: vgtarm.Robot) -> None:
    """The page's condition number of the measured poses (a Jacobian of its own, positions only) is
    the identifiability analysis's (the calibration's weighted Jacobian); the example's planned poses
    beat every random set of as many; each parameter's standard error is at most the worst
    direction's (``sigma / s_min``: ``var x_i = sigma^2 sum_j V_ij^2 / s_j^2``)."""
    measured = K.read_measurements(MEASUREMENTS, robot)
    result = K.calibrate(robot, measured)
    found = K.pose_conditioning(robot, result, measured, candidates=3000, seed=0, sensor_offsets=True)
    assert found["condition_number"] == pytest.approx(result.identifiability.condition_number, rel=1e-9)
    assert found["random"]["trials"] == K.RANDOM_TRIALS
    assert found["condition_number"] < found["random"]["best"] <= found["random"]["median"] <= found["random"]["worst"]
    worst = result.sigma / result.identifiability.singular_values[-1]
    assert np.nanmax(result.standard_errors) <= worst * (1 + 1e-9)
    summary = calibrate_cli.calibration_summary(robot, result, measured, "m.csv", K.DEFAULT_POSITION_NOISE, found)
    assert f"{1e3 * worst:.4f} | yes |" in calibration_markdown(summary, [])
    json.dumps(summary)  # plain data


def test_an_undetermined_parameter_is_reported_as_such(tmp_path: Path) -> None:
    """The stack format's tool z and twist height move the tool alike: the held one shows no value
    and no standard error, its direction no standard error, and the combination is named."""
    out = tmp_path / "fit"
    config = str(EXAMPLES / "paper_robot.toml")
    assert (
        _run(calibrate_cli, "calibrate", "--measurements", str(MEASUREMENTS), "--config", config, "--out", str(out))
        == 0
    )
    text = _text(out / "calibration.html")
    assert f"end_effector.tool[2] 0.0000 {UNDETERMINED} {UNDETERMINED} held at nominal" in text
    assert f"{UNDETERMINED} no" in text  # the last singular value: no standard error along it
    assert "0.707 module2.twist.height - 0.707 end_effector.tool[2]" in text
    assert "nan" not in text.lower().split()


# -- the identification page -------------------------------------------------------------------------


def test_identification_page_gives_the_base_parameters_and_the_checks(identified: tuple[Path, Path]) -> None:
    _, out = identified
    text = _text(out / "identification.html")
    with open(out / "base_parameters.csv", newline="") as stream:
        rows = list(csv.DictReader(stream))
    for row in rows:  # base_parameters.csv is written by other code, as repr of the floats
        if row["least_squares"] == "undetermined":
            assert row["base_parameter"] in text.split("Not determined")[1]
            continue
        value, error = float(row["least_squares"]), float(row["standard_error"])
        assert f"{row['base_parameter']} " in text
        assert f" {value:.6g} {error:.3g} " in text
    assert "platform1.mx" in text.split("Not determined")[1]
    consistency = text.split("Physical consistency")[1].split("Viscous")[0]
    assert consistency.count(" yes") == 3 and "no" not in consistency.split()
    numbers = {
        label: float(value)
        for label, value in re.findall(
            r"(prior \(the input robot\)|least squares \(base parameters\)|physically consistent|the written robot "
            r"file, read back) ([0-9][0-9.e+-]*)",
            text.split(" Validation ")[1],
        )
    }
    assert len(numbers) == 4
    # the file read back gives the consistent model's residual; it and the fit sit at the noise
    assert numbers["the written robot file, read back"] == numbers["physically consistent"]
    assert numbers["physically consistent"] == pytest.approx(FORCE_NOISE, rel=0.05)
    assert numbers["prior (the input robot)"] > 3 * FORCE_NOISE
    held = re.search(r"predicted with RMS residual ([0-9.]+) \(fit: ([0-9.]+)\)", text)
    assert held is not None and float(held[1]) == pytest.approx(FORCE_NOISE, rel=0.1)


def test_hold_out_check_is_exact_on_noise_free_data_and_refuses_an_unexcited_fit(robot: vgtarm.Robot) -> None:
    """Forces of the prior itself (no noise): the fit to 70 % of the samples predicts the rest to
    round-off. A first 70 % at rest excites nothing: no check (``None``), never a made-up number."""
    trajectory = excitation.exciting_trajectory(robot, evaluations=3, seed=2)
    q, qd, qdd = trajectory.q, trajectory.qd, trajectory.qdd
    forces = robot.inverse_dynamics(q, qd, qdd)
    result = dynamic.identify(robot, q, qd, qdd, forces)
    found = dynamic.holdout_check(robot, result, (q, qd, qdd, forces))
    assert found is not None and found["fit_samples"] + found["test_samples"] == len(q)
    assert found["rms_prediction"] <= 1e-9 * float(np.sqrt(np.mean(forces**2)))
    split, n = found["fit_samples"], robot.n_joints
    still = (
        np.concatenate([np.repeat(q[:1], split, axis=0), q[split:]]),
        np.concatenate([np.zeros((split, n)), qd[split:]]),
        np.concatenate([np.zeros((split, n)), qdd[split:]]),
    )
    assert dynamic.holdout_check(robot, result, (*still, robot.inverse_dynamics(*still))) is None


# -- hostile names and the browser -------------------------------------------------------------------


def test_hostile_names_are_escaped_and_both_pages_open_in_a_real_browser(
    tmp_path: Path, identified: tuple[Path, Path]
) -> None:
    from tests.test_html_report import browser_tab

    measurements = tmp_path / HOSTILE_FILE
    shutil.copyfile(MEASUREMENTS, measurements)
    config = _hostile_robot(tmp_path)
    out = tmp_path / "fit"
    assert (
        _run(
            calibrate_cli, "calibrate", "--measurements", str(measurements), "--config", str(config), "--out", str(out)
        )
        == 0
    )
    pages = (out / "calibration.html", identified[1] / "identification.html")
    for page in pages:
        raw = page.read_text()
        assert "<script>alert" not in raw and "<img src=x" not in raw
        assert HOSTILE in _text(page)
    assert HOSTILE_FILE in _text(pages[0])
    for page in pages:
        with browser_tab(page, 0) as (tab, problems):
            shown = tab.inner_text("body")
            images = tab.evaluate("Array.from(document.images).map(i => i.naturalWidth)")
            scripts = tab.evaluate("document.scripts.length")
            links = tab.evaluate("document.links.length")
        assert HOSTILE in shown, page.name
        assert len(images) == 2 and min(images) > 0, page.name
        assert scripts == 0 and links == 0, page.name
        assert problems == [], page.name
