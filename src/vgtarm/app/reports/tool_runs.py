"""Drilling and cutting as rows of ``vgtarm reproduce``'s section beyond the paper (issue 36).

The paper robot drills 10 mm deep along an axis tilted 15 degrees from its twist axis (approach
from home and align, plunge at 2 mm/s, dwell, retract: :func:`vgtarm.toolpaths.drilling`, the axis
task) and cuts a 40 mm arc of 30 mm radius on a plane, the blade's edge on the cut and its axis
tilted 10 degrees about the edge (:func:`vgtarm.toolpaths.cutting`, the tool frame in full). Both
in the closed loop of the section's realistic sensing (1 um leg encoders, a controller model 10 %
heavy) with the low-force preset's observer, estimator and force feedforward, the case gains
(``Kp = 15000 I``, ``Kv = 600 I``), the paper's tool force (20 N against the motion: the thrust along
the axis in the plunge) and its 5 N disturbance, and the paper runs' seed. Each run is saved into a
new folder under ``beyond/``; nothing else of the reproduction is touched.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ... import toolpaths
from ...control import ComputedForceControl
from ...experiment.cases import truncate_reference
from ...experiment.presets import PRESETS
from ...markup import md_cell
from ...model.robot import Robot
from ...simulation import ExternalForce, JointReference, SimulationResult, simulate
from .beyond import ENCODER_RESOLUTION, MODEL_MASS
from .runs import folder_cell, mm

#: The drill: its entry point (m), its tilt from the vertical about the base x axis (rad), its depth (m).
DRILL_ENTRY, DRILL_TILT, DRILL_DEPTH = (0.0, 0.02, 0.67), np.radians(15.0), 0.01
#: The cut: its start (m), direction, the plane's normal (towards the tool), length and radius (m), tilt (rad).
CUT_START, CUT_DIRECTION, CUT_NORMAL = (0.0, -0.02, 0.68), (1.0, 0.0, 0.0), (0.0, 0.0, -1.0)
CUT_LENGTH, CUT_RADIUS, CUT_TILT = 0.04, 0.03, np.radians(10.0)
#: The case gains, and the low-force preset's sensing and estimation settings the runs take.
GAINS = (15000.0, 600.0)
PRESET_KEYS = ("observer", "observer_gain", "estimator", "estimator_bandwidth_hz", "tool_force_feedforward")
#: The issue's targets: the tip error (m) and the axis error (rad) at most.
TIP_TARGET, AXIS_TARGET = 30e-6, 0.5e-3


@dataclass(frozen=True)
class ToolRun:
    """One row: ``"drilling"`` or ``"cutting"``."""

    kind: str

    @property
    def folder(self) -> str:
        return f"beyond/{self.kind}_realistic"


def tool_runs(robot: Robot | None = None) -> list[ToolRun]:
    """The runs this module makes; none on a stack of modules (the paths are placed for the paper robot)."""
    if robot is not None and robot.is_stack:
        return []
    return [ToolRun("drilling"), ToolRun("cutting")]


def tool_path(robot: Robot, spec: ToolRun) -> toolpaths.ToolPath:
    """The desired tool path of ``spec``."""
    if spec.kind == "drilling":
        axis = np.array([0.0, np.sin(DRILL_TILT), np.cos(DRILL_TILT)])
        home = robot.tip_position(robot.parameters.home)
        start_axis = robot.tool_axis(robot.parameters.home)
        return toolpaths.drilling(DRILL_ENTRY, axis, DRILL_DEPTH, start=home, start_axis=start_axis)
    return toolpaths.cutting(CUT_START, CUT_DIRECTION, CUT_NORMAL, CUT_LENGTH, radius=CUT_RADIUS, tilt=CUT_TILT)


def run_tool_one(
    robot: Robot,
    spec: ToolRun,
    folder: Path,
    *,
    seed: int,
    integrator: str,
    substeps: int,
    duration: float | None = None,
) -> SimulationResult:
    """Run ``spec`` (its reference solved here; the first ``duration`` seconds only, if given) and save
    it into ``folder / spec.folder``."""
    path = tool_path(robot, spec)
    ik = robot.inverse_kinematics(path.tip, **path.task(robot))
    reference = JointReference.of(ik, name=spec.kind)
    if duration is not None:
        reference = truncate_reference(reference, duration)
    options: dict[str, Any] = {key: PRESETS["low-force"][key] for key in PRESET_KEYS}
    result = simulate(
        robot,
        reference,
        ComputedForceControl.with_gains(*GAINS),
        external_force=ExternalForce(),
        controller_model=robot.parameters.scaled(mass=MODEL_MASS),
        encoder_resolution=ENCODER_RESOLUTION,
        integrator=integrator,
        substeps=substeps,
        seed=seed,
        metadata={"case": spec.kind, "controller": "cfc", "task": ik.task},
        check=False,  # a failed run is a finding, as in the rest of the section: its samples are kept
        **options,
    )
    # the tool figures need the robot, which a run sent back from a worker process no longer holds
    result = replace(result, metadata={**result.metadata, **result.tool_figures()})
    result.save(folder / spec.folder)
    return result


def tool_section(results: dict[ToolRun, SimulationResult]) -> list[str]:
    """The section's rows of the tool tasks, with the targets they are held to."""
    lines = [
        "### Tool tasks: drilling and cutting",
        "",
        f"The paper robot drills {DRILL_DEPTH * 1e3:g} mm deep along an axis tilted "
        f"{np.degrees(DRILL_TILT):g} degrees (approach and align from home, plunge at 2 mm/s, dwell, "
        "retract; the tool-axis task, its spin free) and cuts a "
        f"{CUT_LENGTH * 1e3:g} mm arc of {CUT_RADIUS * 1e3:g} mm radius, the blade's edge on the cut and "
        f"its axis tilted {np.degrees(CUT_TILT):g} degrees about it (the tool frame in full). Computed force "
        f"control (Kp = {GAINS[0]:g} I, Kv = {GAINS[1]:g} I) with the low-force preset's observer, estimator "
        "and force feedforward, 1 um encoders, a controller model 10 % heavy, the paper's 20 N tool force "
        "(the thrust along the axis in the plunge) and its 5 N disturbance. Targets: tip error <= "
        f"{TIP_TARGET * 1e3:g} mm, axis error <= {AXIS_TARGET * 1e3:g} mrad.",
        "",
        "| run | max tip error (mm) | max axis error (mrad) | peak leg force (N) | targets met | run folder |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for spec, result in results.items():
        s = result.summary()
        tip, axis = s["max_tip_error_m"], s.get("max_axis_error_rad")
        met = s["success"] and tip <= TIP_TARGET and axis is not None and axis <= AXIS_TARGET
        axis_text = "-" if axis is None else f"{axis * 1e3:.3f}"
        lines.append(
            f"| {md_cell(spec.kind)} | {mm(tip)} | {axis_text} | {s['peak_force_n']:.1f} | "
            f"{'yes' if met else 'no'} | {folder_cell(spec.folder)} |"
        )
    return lines
