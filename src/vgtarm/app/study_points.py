"""One study point as a closed-loop run: what Dask workers execute for ``vgtarm study run``.

Each worker process keeps the robot (its compiled model) and the joint references it has built in
a per-process cache, so a study loads the model once per worker, not once per run. A point runs
exactly as ``vgtarm simulate`` would run it with the same inputs (:func:`simulate_command` gives
that command line), so any row of a study can be re-run by hand. Importing this module registers
the MuJoCo plant (``plant_engine = "mujoco"``; MuJoCo itself is needed only to run it), here and
in every worker, which imports it by name.
"""

from __future__ import annotations

import functools
import hashlib
import os
import tempfile
import tomllib
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from .. import (
    mujoco_bridge,  # noqa: F401  (registers the MuJoCo plant, in workers too)
    paths,
)
from ..control import ComputedForceControl, SwitchingControl
from ..errors import InputError
from ..ga import GAOptions
from ..model.parameters import RobotParameters
from ..model.robot import Robot, load_robot, robot_from_dict
from ..simulation import JointReference, simulate
from ..simulation.external import ExternalForce
from ..study.spec import Value, simulate_options
from .cases import case_path, case_study, path_placement, task_metadata, truncate_reference

Inputs = Mapping[str, Value]


@functools.cache
def _robot(robot_text: str | None) -> Robot:
    """The study's robot (the reference robot when ``robot_text`` is None), built once per process."""
    if robot_text is None:
        return load_robot()
    return robot_from_dict(tomllib.loads(robot_text), source="<study robot file>")


@functools.lru_cache(maxsize=16)
def _reference(
    robot_text: str | None,
    case: int | None,
    path_text: str | None,
    dt: float,
    rates: str,
    duration: float | None,
    criterion: tuple[tuple[str, Any], ...] = (),
) -> JointReference:
    """The joint reference of a case or of a path file's text, cut to ``duration``; ``criterion``: the
    inverse kinematics' criterion options (:func:`_criterion`; none: eq. 12); cached."""
    robot = _robot(robot_text)
    if case is not None:
        desired = case_path(robot, case, dt)  # placed on a stack at its home tip, scaled to its reach
        name = f"case {case}"
    else:
        assert path_text is not None
        desired = _path_of(path_text, dt)
        name = desired.name
    ik = robot.inverse_kinematics(desired, solver="fast", rates=rates, **dict(criterion))
    reference = JointReference.of(ik, name=name)
    return reference if duration is None else truncate_reference(reference, duration)


def _criterion(inputs: Inputs) -> tuple[tuple[str, Any], ...]:
    """The inverse kinematics' options of the point's ``criterion`` as ``vgtarm simulate --criterion``
    gives them: none for eq. 12; for the effort criterion its joint-limit weight and the expected
    cutting force (the point's ``cutting_force`` with the tool force, else 0)."""
    if inputs.get("criterion", "joint_limits") == "joint_limits":
        return ()
    force = float(inputs["cutting_force"]) if inputs["external_force"] else 0.0  # type: ignore[arg-type]
    weight = float(inputs["joint_limit_weight"])  # type: ignore[arg-type]
    return (("criterion", str(inputs["criterion"])), ("joint_limit_weight", weight), ("tool_force", force))


def _path_of(text: str, dt: float) -> paths.TipPath:
    """A desired path from a CSV file's text (written to a private temporary file to be read)."""
    digest = hashlib.sha256(text.encode()).hexdigest()[:12]
    fd, name = tempfile.mkstemp(suffix=".csv", prefix=f"vgtarm-path-{digest}-")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as stream:
            stream.write(text)
        return paths.from_csv(name, dt, name=f"path {digest}", quote=False)  # named by the study: never shown
    finally:
        os.unlink(name)


def _controller(inputs: Inputs, n_joints: int) -> ComputedForceControl | SwitchingControl:
    case = case_study(int(inputs["case"] or 1))  # path files use case 1's gains unless given
    kp = _number(inputs["kp"], case.kp)
    kv = _number(inputs["kv"], case.kv)
    if inputs["controller"] == "cfc":
        return ComputedForceControl.with_gains(kp, kv, n_joints)
    if inputs["controller"] == "scm":
        return SwitchingControl.with_gains(
            kp,
            kv,
            n_joints,
            threshold=_number(inputs["threshold"], case.threshold),
            kp_bounds=(case.kp_bounds[0], _number(inputs["kp_max"], case.kp_bounds[1])),
            kv_bounds=(case.kv_bounds[0], _number(inputs["kv_max"], case.kv_bounds[1])),
            horizon=int(inputs["horizon"]),  # type: ignore[arg-type]
            prediction=inputs["prediction"],
            variant=inputs["scm_variant"],
            **_safe_options(inputs),
            ga=GAOptions(population_size=int(inputs["ga_population"]), max_generations=int(inputs["ga_generations"])),  # type: ignore[arg-type]
        )
    raise InputError(f"controller = {inputs['controller']!r}: expected one of ['cfc', 'scm']")


def _safe_options(inputs: Inputs) -> dict[str, Any]:
    """``scm_hold`` and ``scm_switch_on`` as options of the safe variant (a study that sweeps the
    variant runs the paper's points without them: it holds a set for its sample only)."""
    if inputs["scm_variant"] != "safe":
        return {}
    return {"hold": inputs.get("scm_hold"), "switch_on": inputs.get("scm_switch_on")}


def _number(value: Value, default: float | tuple[float, ...]) -> float | tuple[float, ...]:
    return default if value is None else float(value)


def _external(inputs: Inputs) -> ExternalForce | None:
    if not inputs["external_force"]:
        return None
    case = case_study(int(inputs["case"] or 1))
    eta = float(inputs["disturbance"])  # type: ignore[arg-type]
    return replace(case.external_force, cutting_force=float(inputs["cutting_force"]), eta=(eta, eta, eta))  # type: ignore[arg-type]


def _model(robot: Robot, inputs: Inputs) -> RobotParameters | None:
    factors = (inputs["model_mass"], inputs["model_inertia"], inputs["model_friction"])
    if factors == (1.0, 1.0, 1.0):
        return None  # the plant's own parameters, as `vgtarm simulate` without --model-*
    mass, inertia, friction = (float(f) for f in factors)  # type: ignore[arg-type]
    return robot.parameters.scaled(mass=mass, inertia=inertia, friction=friction)


def _options(inputs: Inputs) -> dict[str, Any]:
    """The inputs that are options of the installed simulation's Scenario."""
    return {k: inputs[k] for k in simulate_options() if k in inputs}


def _metadata(robot: Robot, inputs: Inputs) -> dict[str, Any]:
    gains = _gains_metadata(inputs, robot.n_joints)
    if inputs.get("criterion", "joint_limits") != "joint_limits":  # as `vgtarm simulate --criterion` records it
        gains["ik_criterion"] = inputs["criterion"]
    if inputs["case"] is None:
        return {"path": inputs["path"], **gains, **task_metadata(robot)}  # as run_path records it
    placement = path_placement(robot)  # a case path on another robot than the paper's: where and how large
    return {
        "case": inputs["case"],
        "case_title": case_study(int(inputs["case"])).title,
        **(placement.metadata() if placement is not None else {}),
        **gains,
    }


def _gains_metadata(inputs: Inputs, n_joints: int) -> dict[str, Any]:
    """``kp`` and ``kv`` per joint when the point gives either, as ``vgtarm simulate --kp/--kv`` records them."""
    if inputs.get("kp") is None and inputs.get("kv") is None:
        return {}
    case = case_study(int(inputs["case"] or 1))
    kp, kv = _number(inputs["kp"], case.kp), _number(inputs["kv"], case.kv)
    return {"kp": [float(kp)] * n_joints, "kv": [float(kv)] * n_joints}  # type: ignore[arg-type]


def execute_point(inputs: Inputs, files: Mapping[str, str]) -> tuple[dict[str, Any], str]:
    """Run one point; returns ``(summary, error)``: the run's ``summary()`` and "" when it completes,
    else the summary up to the failure (or ``success``/``message`` only) and the error's type name.

    Never raises for a failing run: a divergence, an unreachable path, a bad value or an unexpected
    exception of one run becomes a failed row, so it does not stop the study.
    """
    from ..errors import SimulationError

    try:
        robot = _robot(files.get("robot"))
        reference = _reference(
            files.get("robot"),
            inputs["case"],
            files.get("path"),
            float(inputs["dt"]),  # type: ignore[arg-type]
            str(inputs["rates"]),
            None if inputs["duration"] is None else float(inputs["duration"]),
            _criterion(inputs),
        )
        result = simulate(
            robot,
            reference,
            _controller(inputs, robot.n_joints),
            controller_model=_model(robot, inputs),
            external_force=_external(inputs),
            integrator=str(inputs["integrator"]),
            substeps=int(inputs["substeps"]),  # type: ignore[arg-type]
            seed=int(inputs["seed"]),  # type: ignore[arg-type]
            metadata=_metadata(robot, inputs),
            **_options(inputs),
        )
        return result.summary(), ""
    except SimulationError as exc:
        partial = exc.result.summary() if exc.result is not None else {}  # type: ignore[attr-defined]
        return {**partial, "success": False, "message": str(exc)}, type(exc).__name__
    except Exception as exc:  # noqa: BLE001 - one run's failure must not stop the study
        return {"success": False, "message": f"{type(exc).__name__}: {exc}"}, type(exc).__name__


def check_point(inputs: Inputs, files: Mapping[str, str]) -> None:
    """Refuse a point whose inputs the simulator would refuse, without running it.

    Builds the robot, the controller, the tool force and the controller's model, reads the path
    file, and runs the simulator for two control periods at rest at the home pose with the
    point's options (so an option's bad value is refused here, whatever the option).
    """
    from ..errors import ConfigError

    try:
        robot = _robot(files.get("robot"))
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"study.robot = {inputs['robot']!r}: TOML syntax error: {exc}") from None
    dt = float(inputs["dt"])  # type: ignore[arg-type]
    if inputs["path"] is not None:
        _path_of(files["path"], dt)
    else:
        try:  # sampling the case's path (no inverse kinematics): a dt longer than the path is refused
            case_path(robot, int(inputs["case"]), dt)  # type: ignore[arg-type]
        except paths.PathError as exc:
            raise ConfigError(f"study.dt = {dt!r}: case {inputs['case']}'s path cannot be sampled: {exc}") from None
    n_joints = len(robot.parameters.home)
    q = np.tile(np.asarray(robot.parameters.home, dtype=float), (3, 1))
    still = JointReference(np.arange(3.0) * dt, q, np.zeros_like(q), np.zeros_like(q), name="check")
    assert still.q.shape[1] == n_joints
    simulate(
        robot,
        still,
        _controller(inputs, robot.n_joints),
        controller_model=_model(robot, inputs),
        external_force=_external(inputs),
        integrator=str(inputs["integrator"]),
        substeps=int(inputs["substeps"]),  # type: ignore[arg-type]
        seed=int(inputs["seed"]),  # type: ignore[arg-type]
        **_options(inputs),
    )


#: ``vgtarm simulate`` flags of the inputs it can express (the rest must be at their defaults).
_FLAGS = {
    "controller": "--controller",
    "integrator": "--integrator",
    "substeps": "--substeps",
    "seed": "--seed",
    "rates": "--rates",
    "horizon": "--horizon",
    "scm_variant": "--scm-variant",
    "scm_hold": "--scm-hold",
    "scm_switch_on": "--scm-switch-on",
    "duration": "--duration",
    "model_mass": "--model-mass",
    "model_inertia": "--model-inertia",
    "model_friction": "--model-friction",
    "observer": "--observer",
    "observer_gain": "--observer-gain",
    "encoder_resolution": "--encoder-resolution",
    "velocity_noise": "--velocity-noise",
    "velocity_filter_hz": "--velocity-filter",
    "plant_engine": "--plant",
}
#: Flags given only when the input is away from its default (the command lines of before stay as they were).
_OPTIONAL_FLAGS = {
    "criterion": "--criterion",
    "joint_limit_weight": "--joint-limit-weight",
    "estimator": "--estimator",
    "estimator_bandwidth_hz": "--estimator-bandwidth",
    "tool_force_speed": "--tool-force-speed",
}
_SWITCHES = {
    "external_force": "--external-force",
    "force_sensor": "--force-sensor",
    "tool_force_feedforward": "--tool-feedforward",
}
_STUDY_ONLY = {"kp": None, "kv": None, "threshold": None, "kp_max": None, "kv_max": None, "path": None, "dt": 1e-3}


def _gain_flag_repeats(inputs: Inputs, key: str) -> bool:
    """Whether ``vgtarm simulate --kp``/``--kv`` gives the point's run: always under CFC; under the
    switching method when the gain lies within the case's GA bounds and the study sets no ``kp_max``
    or ``kv_max`` (``simulate`` widens the bounds to a larger gain, a study keeps them)."""
    if inputs["controller"] == "cfc":
        return True
    case = case_study(int(inputs["case"] or 1))
    bound = case.kp_bounds[1] if key == "kp" else case.kv_bounds[1]
    return inputs.get(f"{key}_max") is None and float(inputs[key]) <= bound  # type: ignore[arg-type]


def simulate_command(inputs: Inputs, *, study_folder: str | Path | None = None) -> list[str]:
    """The ``vgtarm simulate`` arguments that re-run a point (its summary is the row's, timings aside).

    Raises InputError naming an input that ``vgtarm simulate`` has no flag for, when it is not at
    its default (gains beyond the GA's bounds, GA sizes, tool-force magnitudes, a path file, another
    ``dt``).
    """
    from ..study.spec import all_parameters

    defaults: dict[str, Value] = {k: p.default for k, p in all_parameters().items()}
    defaults.update(_STUDY_ONLY)
    args = ["simulate", "--case", str(inputs["case"])]
    for key, value in inputs.items():
        if key in ("case", "robot"):
            continue
        if key in ("kp", "kv") and value is not None and _gain_flag_repeats(inputs, key):
            args += [f"--{key}", repr(float(value))]
        elif key in _FLAGS:
            safe = (inputs["controller"], inputs["scm_variant"]) == ("scm", "safe")
            if key in ("scm_hold", "scm_switch_on") and not safe:
                continue  # options of the safe variant only, which the run did not use
            if key in ("horizon", "scm_variant") and inputs["controller"] != "scm":
                continue  # options of the switching method (simulate refuses them with another controller)
            if key == "velocity_filter_hz" and not (inputs.get("encoder_resolution") or inputs.get("velocity_noise")):
                continue  # it filters differenced velocities: a run without sensing has none (refused there)
            if value is not None:
                args += [_FLAGS[key], str(value) if not isinstance(value, float) else repr(value)]
        elif key in _OPTIONAL_FLAGS:
            if value != defaults.get(key):
                args += [_OPTIONAL_FLAGS[key], str(value) if not isinstance(value, float) else repr(value)]
        elif key in _SWITCHES:
            args += [_SWITCHES[key]] if value else []
        elif value != defaults.get(key, value):
            raise InputError(f"{key} = {value!r}: `vgtarm simulate` has no flag for it (only its default)")
    if inputs.get("robot") is not None:
        args += ["--config", str(Path(study_folder or ".") / str(inputs["robot"]))]
    return args
