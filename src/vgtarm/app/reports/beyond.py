"""The report's section *beyond the paper*: tracking under the tool force with a disturbance
observer, a force sensor and realistic sensing (case 2 with the tool force, the paper's hardest).

Each run is case 2 with the 20 N cutting force and the 5 N disturbance, under computed force
control (CFC) or switching control (SCM), with nothing, the generalised-momentum observer, or the
tip force sensor added; once with perfect sensing and an exact model, once with 1 um leg encoders
(a 20-bit twist encoder) and a controller model 10 % heavier than the robot. Four more runs,
not in the table, take the observer's remaining error apart: the cutting force only, the
disturbance only, and velocities differenced from 1 nm encoders with and without the default
velocity filter (what sensing costs beyond the resolution). With the force sensor, whose only
error is its one-period delay, they give the numbers of "What bounds the remaining error".
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from ...errors import SimulationError
from ...experiment.cases import case_study, run_case
from ...markup import md_cell, md_text
from ...model.robot import Robot
from ...simulation import ExternalForce, JointReference, SimulationResult, simulate
from ..pictures.plotting import save_figure
from . import safe_study
from .runs import folder_cell, mm

#: The heading of the section's last subsection (other subsections of runs beyond the paper go before it).
BOUNDS_HEADING = "### What bounds the remaining error"
#: Realistic sensing: leg encoder step (m) and the controller model's mass factor.
ENCODER_RESOLUTION = 1e-6
MODEL_MASS = 1.1
#: Desired tip speed (m/s) below which the tool counts as starting, turning or stopping.
SLOW_SPEED = 0.02


@dataclass(frozen=True, eq=False)
class BeyondRun:
    """One run of the section."""

    label: str
    controller: str
    options: dict[str, Any] = field(default_factory=dict)
    realistic: bool = False
    force: ExternalForce | None = None
    in_table: bool = True

    @property
    def folder(self) -> str:
        text = self.label.lower().replace(" + ", "_").replace(" ", "_").replace(",", "")
        return "beyond/" + text + ("_realistic" if self.realistic else "")


def beyond_runs() -> list[BeyondRun]:
    """The runs of the section, perfect sensing first, then realistic, then the decomposition."""
    base: list[tuple[str, str, dict[str, Any]]] = [
        ("CFC", "cfc", {}),
        ("SCM", "scm", {}),
        ("CFC + observer", "cfc", {"observer": "momentum"}),
        ("SCM + observer", "scm", {"observer": "momentum"}),
        ("CFC + force sensor", "cfc", {"force_sensor": True}),
    ]
    runs = [BeyondRun(label, ctrl, dict(opts)) for label, ctrl, opts in base]
    runs += [BeyondRun(label, ctrl, dict(opts), realistic=True) for label, ctrl, opts in base]
    runs += [
        BeyondRun(
            "CFC + observer, cutting force only",
            "cfc",
            {"observer": "momentum"},
            force=ExternalForce(disturbance=False),
            in_table=False,
        ),
        BeyondRun(
            "CFC + observer, disturbance only",
            "cfc",
            {"observer": "momentum"},
            force=ExternalForce(cutting=False),
            in_table=False,
        ),
        BeyondRun(
            "CFC + observer, 1 nm encoders, 1000 Hz filter",
            "cfc",
            {"observer": "momentum", "encoder_resolution": 1e-9, "velocity_filter_hz": 1000.0},
            in_table=False,
        ),
        BeyondRun(
            "CFC + observer, 1 nm encoders", "cfc", {"observer": "momentum", "encoder_resolution": 1e-9}, in_table=False
        ),
    ]
    return runs


def run_beyond(
    robot: Robot, reference: JointReference, folder: Path, *, seed: int, integrator: str, substeps: int
) -> dict[BeyondRun, SimulationResult]:
    """Run every :func:`beyond_runs` run on case 2's ``reference`` and save it under ``folder``."""
    return {
        spec: run_beyond_one(robot, spec, reference, folder, seed=seed, integrator=integrator, substeps=substeps)
        for spec in beyond_runs()
    }


def run_beyond_one(
    robot: Robot,
    spec: BeyondRun,
    reference: JointReference,
    folder: Path,
    *,
    seed: int,
    integrator: str,
    substeps: int,
) -> SimulationResult:
    """Run ``spec`` on case 2's ``reference`` and save it under ``folder``; a run that fails with
    :class:`~vgtarm.errors.SimulationError` is kept (its samples up to the failure) and saved too."""
    options = dict(spec.options)
    if spec.realistic:
        options.update(encoder_resolution=ENCODER_RESOLUTION, controller_model=robot.parameters.scaled(mass=MODEL_MASS))
    try:
        if spec.force is not None:
            result = simulate(
                robot,
                reference,
                # the paper's variant: the section shows where it fails (and stays bit for bit)
                case_study(2).controller(spec.controller, n_joints=robot.n_joints, variant="paper"),
                external_force=spec.force,
                seed=seed,
                integrator=integrator,
                substeps=substeps,
                metadata={"case": 2},
                **options,
            )
        else:
            result = run_case(
                robot,
                2,
                controller=spec.controller,
                external_force=True,
                integrator=integrator,
                substeps=substeps,
                seed=seed,
                reference=reference,
                scm_variant="paper",
                **options,
            )
    except SimulationError as error:  # a finding, not a failure of the report: keep the samples
        if not isinstance(error.result, SimulationResult):
            raise
        result = error.result
    result.save(folder / spec.folder)
    return result


def _n(value: float | None, digits: int) -> str:
    return "—" if value is None else f"{value:.{digits}f}"


def _force_steps(result: SimulationResult) -> list[float]:
    """Times at which the cutting force steps: it switches on or off, or turns by more than 60
    degrees within one period (the tool starts, stops, or reverses at a corner)."""
    f = np.nan_to_num(result.f_ext)
    magnitude = np.linalg.norm(f, axis=1)
    cutting = magnitude > 10.0  # the 20 N cutting force dominates the 5 N disturbance
    unit = f / np.maximum(magnitude, 1e-12)[:, None]
    turned = (np.sum(unit[1:] * unit[:-1], axis=1) < 0.5) & cutting[1:] & cutting[:-1]
    changes = np.flatnonzero((np.diff(cutting.astype(int)) != 0) | turned) + 1
    times = [float(result.t[k]) for k in changes]
    return [t for i, t in enumerate(times) if i == 0 or t - times[i - 1] > 0.01]


def _slow(result: SimulationResult, speed: float = SLOW_SPEED) -> np.ndarray:
    """Samples where the desired tip speed is below ``speed`` (m/s): starting, turning, stopping."""
    desired = np.linalg.norm(np.gradient(result.tip_desired, result.t, axis=0), axis=1)
    return np.asarray(desired < speed)


def _split(result: SimulationResult, slow: np.ndarray) -> tuple[float, float, float]:
    """Largest tip error in the slow phases, and the largest and RMS error elsewhere (m)."""
    error = result.tip_error
    fast = error[~slow]
    largest = float(np.max(error[slow])) if slow.any() else float("nan")
    if not fast.size:  # a run all in slow phases (reproduce --duration shorter than the start)
        return largest, float("nan"), float("nan")
    return largest, float(np.max(fast)), float(np.sqrt(np.mean(fast**2)))


def beyond_figure(results: dict[BeyondRun, SimulationResult], folder: Path, name: str = "beyond_tip_error.png") -> str:
    """Tip error against time of the section's main runs (log scale)."""
    fig = Figure(figsize=(9, 4.5), layout="constrained")
    ax = fig.add_subplot()
    for spec, result in results.items():
        if not spec.in_table:
            continue
        style = "--" if spec.realistic else "-"
        label = spec.label + (" (1 um encoders, model +10 % mass)" if spec.realistic else "")
        ax.semilogy(result.t, np.maximum(result.tip_error, 1e-7) * 1e3, style, lw=0.8, label=label)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("tip error (mm)")
    ax.set_title("Case 2 with the tool force: beyond the paper")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    save_figure(fig, folder / name)
    save_figure(safe_study.study_figure(safe_study.load_summary()), folder / "safe_study.png")  # issue 23
    return name


def beyond_section(results: dict[BeyondRun, SimulationResult], figure: str) -> list[str]:
    """Markdown lines of the section: table, figure, and what bounds the remaining error."""
    summaries = {spec: r.summary() for spec, r in results.items()}
    lines = _beyond_table(summaries)
    lines += safe_study.section_lines(safe_study.load_summary(), "safe_study.png")  # issue 23: the 60 runs
    lines += ["", f"![tip error beyond the paper]({figure})", "", BOUNDS_HEADING, ""]
    by_label = {(spec.label, spec.realistic): s for spec, s in summaries.items()}
    lines += _bounds_perfect(results, by_label)
    lines += _bounds_switching(by_label)
    lines += _bounds_realistic(results, by_label)
    return lines


def _beyond_table(summaries: dict[BeyondRun, dict[str, Any]]) -> list[str]:
    """The section's opening and its table of the runs :attr:`BeyondRun.in_table`."""
    lines = [
        "## Beyond the paper: tracking under the tool force",
        "",
        "Case 2 with the tool force. *Perfect*: exact joint measurements and an exact controller model;"
        f" *realistic*: {ENCODER_RESOLUTION * 1e6:g} um leg encoders (20-bit twist), velocities from encoder"
        f" differences, and a controller model {round((MODEL_MASS - 1) * 100)} % heavier than the robot."
        " The paper's best figure for this case is below 0.4 mm (switching control).",
        "",
        "Forces are the six legs' (the twist torque apart); chatter is the RMS of the change of the leg forces"
        " from one control period to the next, energy the integral of the actuators' absolute power |F qd|.",
        "",
        "| run | sensing | max (mm) | RMS (mm) | peak force (N) | RMS force (N) | chatter (N) | RMS twist torque"
        " (N m) | energy (J) | GA activations | folder |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for spec, s in summaries.items():
        if not spec.in_table:
            continue
        largest = mm(s["max_tip_error_m"]) if s["success"] else md_cell(str(s["message"]).split(":")[0])
        lines.append(
            f"| {md_cell(spec.label)} | {'realistic' if spec.realistic else 'perfect'} | {largest} |"
            f" {mm(s['rms_tip_error_m'])} | {_n(s['peak_force_n'], 1)} | {_n(s['rms_force_n'], 1)} |"
            f" {_n(s['chatter_n'], 2)} | {_n(s['rms_twist_torque_nm'], 3)} | {_n(s['actuator_energy_j'], 2)} |"
            f" {s['ga_activations']} | {folder_cell(spec.folder)} |"
        )
    return lines


def _bounds_perfect(
    results: dict[BeyondRun, SimulationResult], by_label: dict[tuple[str, bool], dict[str, Any]]
) -> list[str]:
    """What bounds the observer's error with perfect sensing: the cutting force's steps where the
    tool is slow, the disturbance, and the force sensor's one-period delay (nothing without the
    five runs that tell them apart)."""
    cfc = by_label.get(("CFC", False))
    observed = by_label.get(("CFC + observer", False))
    sensor = by_label.get(("CFC + force sensor", False))
    cutting = by_label.get(("CFC + observer, cutting force only", False))
    noise = by_label.get(("CFC + observer, disturbance only", False))
    if not (cfc and observed and sensor and cutting and noise):
        return []
    run = {spec.label: r for spec, r in results.items() if not spec.realistic}
    slow = _slow(run["CFC + observer"])
    steps = ", ".join(f"{t:.3f}" for t in _force_steps(run["CFC + observer, cutting force only"])) or "none"
    gain = float(observed.get("observer_gain_per_s") or 0.0)
    both, alone, late = (
        _split(run[label], slow)
        for label in ("CFC + observer", "CFC + observer, cutting force only", "CFC + force sensor")
    )
    return [
        f"- Computed force control has no integral action: the 20 N cutting force leaves an offset"
        f" (max {mm(cfc['max_tip_error_m'])} mm). The observer ({gain:g} 1/s) estimates the external joint"
        f" efforts and cancels them: max {mm(observed['max_tip_error_m'])} mm, RMS"
        f" {mm(observed['rms_tip_error_m'])} mm.",
        f"- The cutting force points against the tool's actual velocity. Where the tool is slow (desired"
        f" speed below {SLOW_SPEED * 1e3:g} mm/s: it starts, turns at the corner, stops; {slow.mean():.1%} of"
        " the run) that velocity is mostly the tracking error's, and the 20 N force turns within a few"
        f" periods, or flips from one period to the next (steps at t = {steps} s), faster than the"
        f" observer's time constant 1/K_O = {1e3 / gain:.1f} ms. With the cutting force alone the error is"
        f" max {mm(alone[0])} mm there and {mm(alone[1])} mm elsewhere (RMS {mm(alone[2])} mm).",
        f"- The random disturbance alone (5 N per axis, a new value each period, faster than any observer"
        f" can follow) leaves max {mm(noise['max_tip_error_m'])} mm, RMS {mm(noise['rms_tip_error_m'])} mm,"
        " everywhere on the path: it sets the floor.",
        f"- Together: max {mm(both[0])} mm in the slow phases, {mm(both[1])} mm elsewhere (RMS {mm(both[2])} mm).",
        f"- The force sensor knows the tool force one period late, with no filter lag: max"
        f" {mm(sensor['max_tip_error_m'])} mm, RMS {mm(sensor['rms_tip_error_m'])} mm ({mm(late[0])} mm in"
        f" the slow phases, {mm(late[1])} mm elsewhere). What is left is the one-period delay, of the"
        " disturbance that changes every period and of the force flipping at low speed.",
    ]


def _bounds_switching(by_label: dict[tuple[str, bool], dict[str, Any]]) -> list[str]:
    """Switching control under realistic sensing (when it fails) and with the observer (when its
    GA never runs)."""
    lines: list[str] = []
    scm_realistic = by_label.get(("SCM", True))
    if scm_realistic and not scm_realistic["success"]:
        lines.append(
            "- Switching control without the observer does not survive realistic sensing: its GA tunes full gain"
            " matrices on a 20 ms prediction from the measured state, and with velocities differenced from"
            f" {ENCODER_RESOLUTION * 1e6:g} um encoder counts the run {md_text(scm_realistic['message'])}."
        )
    quiet = [
        realistic
        for (label, realistic), s in by_label.items()
        if label == "SCM + observer" and s["ga_activations"] == 0
    ]
    if quiet:
        lines.append(
            "- With the observer the tip error never reaches the switching threshold"
            f" ({'both sensings' if len(quiet) == 2 else 'realistic' if quiet[0] else 'perfect'}): SCM + observer"
            " runs as CFC + observer."
        )
    return lines


def _bounds_realistic(
    results: dict[BeyondRun, SimulationResult], by_label: dict[tuple[str, bool], dict[str, Any]]
) -> list[str]:
    """The observer and the force sensor under realistic sensing, and what each part of that
    sensing costs (the decomposition runs)."""
    lines: list[str] = []
    realistic = by_label.get(("CFC + observer", True))
    if realistic:
        lines.append(
            f"- With {ENCODER_RESOLUTION * 1e6:g} um encoders and a model {round((MODEL_MASS - 1) * 100)} % off in"
            f" mass the observer still tracks to max {mm(realistic['max_tip_error_m'])} mm, RMS"
            f" {mm(realistic['rms_tip_error_m'])} mm: it estimates the model's error together with the tool force."
        )
        lines += _sensing_cost(results)
    sensor_realistic = by_label.get(("CFC + force sensor", True))
    if sensor_realistic and sensor_realistic["success"]:
        lines.append(
            f"- The force sensor with the same sensing and model: max {mm(sensor_realistic['max_tip_error_m'])} mm,"
            f" RMS {mm(sensor_realistic['rms_tip_error_m'])} mm. It measures the tool force only, so the offset"
            " from the model's wrong mass (gravity and inertia) stays; the observer removes both."
        )
    return lines


def _sensing_cost(results: dict[BeyondRun, SimulationResult]) -> list[str]:
    """RMS error away from the slow phases along the chain from perfect to realistic sensing
    (nothing unless all four runs succeeded)."""
    named = {(spec.label, spec.realistic): r for spec, r in results.items()}
    chain = [
        named.get(key)
        for key in (
            ("CFC + observer", False),
            ("CFC + observer, 1 nm encoders, 1000 Hz filter", False),
            ("CFC + observer, 1 nm encoders", False),
            ("CFC + observer", True),
        )
    ]
    if not all(r is not None and r.success for r in chain):
        return []
    slow = _slow(chain[0])  # type: ignore[arg-type]
    exact, unfiltered, filtered, real = (mm(_split(r, slow)[2]) for r in chain)  # type: ignore[arg-type]
    return [
        f"- What realistic sensing costs, RMS away from the slow phases: {exact} mm with perfect sensing;"
        f" {unfiltered} mm with velocities differenced from 1 nm encoders and a nearly transparent filter"
        " (1000 Hz), because a difference of positions is the velocity of the period before; "
        f"{filtered} mm with the default 100 Hz filter, whose lag adds to that (it halves the effort's"
        f" chatter and keeps the observer stable up to K_O = 1/dt); {real} mm with"
        f" {ENCODER_RESOLUTION * 1e6:g} um counts and the wrong mass. The encoder resolution itself costs"
        " little: the velocity's delay and filter bound this part."
    ]
