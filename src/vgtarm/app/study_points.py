"""One study point as a closed-loop run: what Dask workers execute for ``vgtarm study run``.

Each worker process keeps the robot (its compiled model) and the joint references it has built in
a per-process cache, so a study loads the model once per worker, not once per run. A point runs
exactly as ``vgtarm simulate`` would run it with the same inputs (:func:`simulate_command` gives
that command line), so any row of a study can be re-run by hand. Importing this module registers
the MuJoCo plant (``plant_engine = "mujoco"``; MuJoCo itself is needed only to run it), here and
in every worker, which imports it by name.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .. import (
    mujoco_bridge,  # noqa: F401  (registers the MuJoCo plant, in workers too)
    paths,
)
from ..errors import InputError
from ..experiment import Experiment
from ..experiment.cases import case_path, case_study
from ..experiment.options import all_options
from ..experiment.record import robot_of_text
from ..model.robot import Robot, load_robot
from ..simulation import JointReference
from ..simulation.scenario import senses
from ..study.spec import Value

Inputs = Mapping[str, Value]


def _robot(robot_text: str | None, name: object = None) -> Robot:
    """The study's robot (the reference robot when ``robot_text`` is None), built once per process;
    ``name``: the study's robot file, as it gives it (the run's record says where the robot was read)."""
    return load_robot() if robot_text is None else robot_of_text(robot_text, f"study robot file {name}")


def experiment_of(inputs: Inputs, files: Mapping[str, str]) -> Experiment:
    """The experiment of a study point: its robot (the study's file, shipped as text), its case or
    path file, its ``dt`` and every option of its inputs (:mod:`vgtarm.experiment.options`)."""
    options = {key: value for key, value in inputs.items() if key in all_options()}
    options.update(rates=str(inputs["rates"]), duration=inputs["duration"])
    robot = _robot(files.get("robot"), inputs.get("robot"))
    dt = float(inputs["dt"])  # type: ignore[arg-type]
    if inputs["case"] is not None:
        return Experiment(case=int(inputs["case"]), robot=robot, dt=dt, options=options)
    return Experiment(path=_path_of(files["path"], dt), robot=robot, dt=dt, options=options)


#: The joint references a worker has built: the inverse kinematics of a path is the same for every
#: seed and controller of a study, so it is solved once per process.
_REFERENCES: dict[tuple[Any, ...], JointReference] = {}


def _reference(experiment: Experiment, files: Mapping[str, str]) -> JointReference:
    """The experiment's joint reference, cached by what it depends on (robot, path, sampling, rates,
    duration, criterion, tool task)."""
    o = experiment.options
    key = (
        files.get("robot"),
        experiment.case,
        files.get("path"),
        experiment.dt,
        o["rates"],
        o["duration"],
        tuple((k, v.tobytes() if isinstance(v, np.ndarray) else v) for k, v in sorted(experiment.ik_options().items())),
    )
    if key not in _REFERENCES:
        if len(_REFERENCES) >= 16:
            _REFERENCES.pop(next(iter(_REFERENCES)))
        _REFERENCES[key] = experiment.reference()
    return _REFERENCES[key]


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


def execute_point(inputs: Inputs, files: Mapping[str, str]) -> tuple[dict[str, Any], str]:
    """Run one point; returns ``(summary, error)``: the run's ``summary()`` and "" when it completes,
    else the summary up to the failure (or ``success``/``message`` only) and the error's type name.

    Never raises for a failing run: a divergence, an unreachable path, a bad value or an unexpected
    exception of one run becomes a failed row, so it does not stop the study.
    """
    from ..errors import SimulationError

    try:
        experiment = experiment_of(inputs, files)
        path = {} if inputs["case"] is not None else {"path": inputs["path"]}  # the file's name, as given
        result = experiment.run(reference=_reference(experiment, files), metadata=path)
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
        robot = _robot(files.get("robot"), inputs.get("robot"))
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
    experiment = experiment_of(inputs, files)
    q = np.tile(np.asarray(robot.parameters.home, dtype=float), (3, 1))
    still = JointReference(np.arange(3.0) * dt, q, np.zeros_like(q), np.zeros_like(q), name="check")
    experiment.run(reference=still)


#: The study's inputs that are no option of an experiment, and their defaults (``vgtarm simulate``
#: has no flag for them: ``--path`` takes a file, ``dt`` is the case's).
_STUDY_ONLY: dict[str, Value] = {"path": None, "dt": 1e-3}


def _gain_flag_repeats(inputs: Inputs, key: str) -> bool:
    """Whether ``vgtarm simulate --kp``/``--kv`` gives the point's run: always under CFC; under the
    switching method when the gain lies within the case's GA bounds and the study sets no ``kp_max``
    or ``kv_max`` (``simulate`` widens the bounds to a larger gain, a study keeps them)."""
    if inputs["controller"] == "cfc":
        return True
    case = case_study(int(inputs["case"] or 1))
    bound = case.kp_bounds[1] if key == "kp" else case.kv_bounds[1]
    return inputs.get(f"{key}_max") is None and float(inputs[key]) <= bound  # type: ignore[arg-type]


def _applies(key: str, inputs: Inputs) -> bool:
    """Whether the option ``key`` applies to the point: the option it needs (its declaration's
    ``needs``) applies and has the value it needs (``scm_hold``: the safe variant of the switching
    method; ``horizon``: the switching method); the velocity filter: with sensing."""
    if key == "velocity_filter_hz":  # it filters differenced velocities: a run without sensing has none
        return senses(inputs)
    needs = all_options()[key].needs
    if needs is None:
        return True
    other, value = needs
    return inputs.get(other, all_options()[other].default) == value and _applies(other, inputs)


def _flag(key: str, value: Value, inputs: Inputs) -> list[str]:
    """The ``vgtarm simulate`` arguments of the input ``key``: its declared flag when the value is away
    from its default and applies; none else; InputError when simulate has no flag for it."""
    option = all_options().get(key)
    default = _STUDY_ONLY[key] if option is None else option.default
    if value == default or value is None or not _applies(key, inputs):
        return []
    if option is None or not option.cli_flag:
        raise InputError(f"{key} = {value!r}: `vgtarm simulate` has no flag for it (only its default)")
    if option.kind is bool:
        return [option.cli_flag]
    return [option.cli_flag, repr(value) if isinstance(value, float) else str(value)]


def simulate_command(inputs: Inputs, *, study_folder: str | Path | None = None) -> list[str]:
    """The ``vgtarm simulate`` arguments that re-run a point (its summary is the row's, timings aside):
    each input away from its default by its declared flag (:mod:`vgtarm.experiment.options`).

    Raises InputError naming an input that ``vgtarm simulate`` has no flag for, when it is not at
    its default (gains beyond the GA's bounds, GA sizes, tool-force magnitudes, a path file, another
    ``dt``).
    """
    args = ["simulate", "--case", str(inputs["case"])]
    for key, value in inputs.items():
        if key in ("case", "robot"):
            continue
        if key in ("kp", "kv"):
            if value is not None and _gain_flag_repeats(inputs, key):
                args += [f"--{key}", repr(float(value))]
            elif value is not None:
                raise InputError(f"{key} = {value!r}: `vgtarm simulate` has no flag for it (only its default)")
            continue
        args += _flag(key, value, inputs)
    if inputs.get("robot") is not None:
        args += ["--config", str(Path(study_folder or ".") / str(inputs["robot"]))]
    return args
