"""The low-force preset as rows of ``vgtarm reproduce``'s section beyond the paper (issue 22).

The preset (:data:`vgtarm.experiment.presets.PRESETS`, the one definition ``vgtarm simulate --preset`` reads
too) runs on case 1 and on case 2 with the tool force, with the section's realistic sensing
(1 um leg encoders, a controller model 10 % heavy; the Kalman estimator needs encoders) and the
paper runs' seed, beside CFC + observer with the same sensing: case 2's is the section's own run,
case 1's is run here. Each run is made exactly as the command line would make it
(:func:`simulate_command` gives that command), into a new folder under ``beyond/``; the paper's runs
and the other runs of the section are not touched.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from ...errors import SimulationError
from ...experiment.cases import case_study, joint_reference, run_case
from ...experiment.presets import preset_options, preset_text
from ...markup import md_cell, md_code
from ...model.robot import Robot
from ...simulation import SimulationResult
from .beyond import ENCODER_RESOLUTION, MODEL_MASS
from .runs import folder_cell, mm

#: The preset shown, and the options of the run it is compared with (the section's CFC + observer).
PRESET = "low-force"
BASELINE: dict[str, Any] = {"observer": "momentum"}


@dataclass(frozen=True)
class PresetRun:
    """One row: case 1, or case 2 with the tool force; the preset, or (``preset`` None) CFC + observer."""

    case: int
    preset: str | None = PRESET

    @property
    def external_force(self) -> bool:
        return self.case == 2

    @property
    def label(self) -> str:
        return f"{self.preset} preset" if self.preset else "CFC + observer"

    @property
    def folder(self) -> str:
        name = self.preset.replace("-", "_") if self.preset else "cfc_observer"
        return f"beyond/case{self.case}_{name}_realistic"


def low_force_runs(robot: Robot | None = None) -> list[PresetRun]:
    """The runs this module makes: case 1's comparison and the preset on both cases (case 2's
    comparison is the section's ``CFC + observer`` with realistic sensing); none on a stack of
    modules (``robot.is_stack``): the preset was chosen on the paper robot's measured front, and on
    the six-module example the effort criterion's reference of a case path takes minutes (3 to 10 on
    the shared 2-core VM), which would multiply the reproduction's time."""
    if robot is not None and robot.is_stack:
        return []
    return [PresetRun(1, None), PresetRun(1), PresetRun(2)]


def run_options(robot: Robot, spec: PresetRun) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(ik_options, run_case options)`` of ``spec``, realistic sensing included."""
    tool_force = case_study(spec.case).external_force.cutting_force if spec.external_force else 0.0
    ik, options = preset_options(spec.preset, tool_force=tool_force) if spec.preset else ({}, dict(BASELINE))
    options.update(encoder_resolution=ENCODER_RESOLUTION, controller_model=robot.parameters.scaled(mass=MODEL_MASS))
    return ik, options


def run_low_force_one(
    robot: Robot,
    spec: PresetRun,
    folder: Path,
    *,
    seed: int,
    integrator: str,
    substeps: int,
    duration: float | None = None,
) -> SimulationResult:
    """Run ``spec`` (its reference computed here; the first ``duration`` seconds only, if given) and
    save it into ``folder / spec.folder``: the run of :func:`simulate_command`."""
    ik, options = run_options(robot, spec)
    reference = (
        joint_reference(robot, spec.case, duration=duration, **ik)
        if ik or duration is not None
        else None  # run_case's own eq. 12 reference, as the paper's runs
    )
    try:
        result = run_case(
            robot,
            spec.case,
            controller="cfc",
            external_force=spec.external_force,
            integrator=integrator,
            substeps=substeps,
            seed=seed,
            reference=reference,
            **options,
        )
    except SimulationError as error:  # a finding, as in the rest of the section: keep the samples
        if not isinstance(error.result, SimulationResult):
            raise
        result = error.result
    if ik:  # recorded as `vgtarm simulate --criterion` records it
        result = replace(result, metadata={**result.metadata, "ik_criterion": ik["criterion"]})
    result.save(folder / spec.folder)
    return result


def simulate_command(spec: PresetRun, *, seed: int) -> list[str]:
    """The ``vgtarm simulate`` arguments that make ``spec``'s run (integrator and substeps at their defaults)."""
    args = ["simulate", "--case", str(spec.case)] + (["--external-force"] if spec.external_force else [])
    args += ["--preset", spec.preset] if spec.preset else ["--observer", str(BASELINE["observer"])]
    return args + [
        "--encoder-resolution",
        repr(ENCODER_RESOLUTION),
        "--model-mass",
        repr(MODEL_MASS),
        "--seed",
        str(seed),
    ]


def low_force_section(
    results: dict[PresetRun, SimulationResult],
    case2_baseline: tuple[str, SimulationResult] | None,
    *,
    seed: int,
) -> list[str]:
    """Markdown lines of the subsection: the preset beside CFC + observer on both cases, with the force
    figures; ``case2_baseline``: the folder and run of the section's CFC + observer with realistic sensing."""
    rows = [(spec.case, spec.label, spec.folder, result.summary()) for spec, result in results.items()]
    if case2_baseline is not None:
        rows.append((2, "CFC + observer", case2_baseline[0], case2_baseline[1].summary()))
    rows.sort(key=lambda row: (row[0], row[1] != "CFC + observer"))
    settings = preset_text(PRESET)
    command = " ".join(["vgtarm", *simulate_command(PresetRun(2), seed=seed)])
    lines = [
        "",
        f"### The {PRESET} preset (issue 22)",
        "",
        f"`vgtarm simulate --preset {PRESET}` ({md_cell(settings)}) beside CFC + observer, both with realistic"
        f" sensing ({ENCODER_RESOLUTION * 1e6:g} um encoders, model {round((MODEL_MASS - 1) * 100)} % heavy), seed"
        f" {seed}: case 1, and case 2 with the tool force (the same command: {md_code(command)}).",
        "Forces are the six legs'; chatter and energy as above. The choice of the preset and the front it is"
        " taken from: `docs/control.md`.",
        "",
        "| case | run | max (mm) | max after 0.2 s (mm) | RMS (mm) | peak force (N) | RMS force (N) | chatter (N) |"
        " energy (J) | folder |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for case, label, folder, s in rows:
        largest = mm(s["max_tip_error_m"]) if s["success"] else md_cell(str(s["message"]).split(":")[0])
        lines.append(
            f"| {case} | {md_cell(label)} | {largest} | {mm(s['max_tip_error_after_transient_m'])} |"
            f" {mm(s['rms_tip_error_m'])} | {_n(s['peak_force_n'], 1)} | {_n(s['rms_force_n'], 2)} |"
            f" {_n(s['chatter_n'], 2)} | {_n(s['actuator_energy_j'], 2)} | {folder_cell(folder)} |"
        )
    lines += ["", *_reading(rows)]
    return lines


def _reading(rows: list[tuple[int, str, str, dict[str, Any]]]) -> list[str]:
    """One line per case comparing the preset's force figures with CFC + observer's."""
    out = []
    for case in (1, 2):
        pair = {label: s for c, label, _, s in rows if c == case}
        base, low = pair.get("CFC + observer"), pair.get(f"{PRESET} preset")
        if not (base and low and base["success"] and low["success"] and base["rms_force_n"]):
            continue
        change = (low["rms_force_n"] / base["rms_force_n"] - 1) * 100
        out.append(
            f"- Case {case}{' with the tool force' if case == 2 else ''}: RMS leg force {base['rms_force_n']:.2f}"
            f" -> {low['rms_force_n']:.2f} N ({change:+.1f} %), chatter {base['chatter_n']:.2f} ->"
            f" {low['chatter_n']:.2f} N, peak {base['peak_force_n']:.1f} -> {low['peak_force_n']:.1f} N; max tip error"
            f" after the start {mm(base['max_tip_error_after_transient_m'])} -> "
            f"{mm(low['max_tip_error_after_transient_m'])} mm."
        )
    return out


def _n(value: float | None, digits: int) -> str:
    return "—" if value is None else f"{value:.{digits}f}"
