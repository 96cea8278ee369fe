"""One experiment: a closed-loop run from the robot to its results, as one frozen, checked record.

:class:`Experiment` holds what a run is: the robot (the paper's, a robot or stack file, or a
:class:`~vgtarm.Robot`), the path (one of the paper's cases or a desired tip path), its sampling
period, a preset, and every option of :mod:`.options` (the controller and its gains, the
switching method, the tool force, the controller model's errors, the reference's criterion, and
the :class:`~vgtarm.simulation.Scenario`'s options), each checked by its declaration when the
record is built. ``vgtarm simulate``, a study's points and ``vgtarm reproduce``'s preset rows run
through it, so that one record describes a run made from any of them:

>>> import vgtarm
>>> experiment = vgtarm.Experiment(case=2, controller="cfc", external_force=True, preset="low-force")
>>> result = experiment.run()                                        # doctest: +SKIP
>>> vgtarm.Experiment.from_record(result.metadata["experiment"]) == experiment  # doctest: +SKIP
True

:meth:`Experiment.record` is stored whole in the run's ``summary.json`` (key ``experiment``).
"""

from __future__ import annotations

import dataclasses
import functools
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .. import (
    checks,
    mujoco_bridge,  # noqa: F401  (registers the MuJoCo plant, in a study's workers too)
    paths,
)
from ..control import ComputedForceControl, SwitchingControl
from ..errors import InputError, shown
from ..ga import GAOptions
from ..model.parameters import RobotParameters
from ..model.robot import Robot, load_robot, robot_from_dict
from ..option import Value
from ..simulation import ExternalForce, JointReference, SimulationResult, simulate
from .cases import CASES, PATH_GAINS_CASE, case_path, case_study, path_placement, task_metadata, truncate_reference
from .options import all_options, scenario_names
from .presets import PRESETS, applied_settings

#: A gain of the experiment: one value for every joint, or one per joint.
Gain = float | tuple[float, ...]
#: The options of a tool-axis task, as refusals name them.
TOOL_TASK_NAMES = ("axis", "cone_degrees", "entry_point")


@dataclass(frozen=True)
class Experiment:
    """A closed-loop run, from the robot to its results (module docstring).

    Attributes:
        case: the paper's case study (1 or 2), or None with ``path``.
        path: a desired tip path (:class:`~vgtarm.paths.TipPath`), or None with ``case``.
        robot: None (the paper's robot), a robot or stack file's name, or a :class:`~vgtarm.Robot`.
        dt: the sampling period of a case's path (s); a path keeps its own.
        preset: named settings (:data:`~vgtarm.experiment.presets.PRESETS`): each fills an option
            not given in ``options`` (a setting that needs what an option given replaced gives way).
        options: every option of :func:`~vgtarm.experiment.options.all_options` by name, the
            defaults filled in; ``kp`` and ``kv`` may hold one gain per joint.
    """

    case: int | None = None
    path: paths.TipPath | None = None
    robot: str | Robot | None = None
    dt: float = 1e-3
    preset: str | None = None
    options: Mapping[str, Any] = field(default_factory=dict)

    def __init__(
        self,
        case: int | None = None,
        path: paths.TipPath | None = None,
        robot: str | Path | Robot | None = None,
        *,
        dt: float = 1e-3,
        preset: str | None = None,
        options: Mapping[str, Any] | None = None,
        **keywords: Any,
    ) -> None:
        given = {**(options or {}), **keywords}
        unknown = sorted(set(given) - set(all_options()))
        if unknown:
            raise InputError(f"Experiment got the unknown option {unknown[0]!r}: expected one of {list(all_options())}")
        if (case is None) == (path is None):
            raise InputError(f"case = {shown(case)}, path = {shown(path)}: give exactly one of case (1 or 2) and path")
        if case is not None and (isinstance(case, bool) or case not in CASES):
            raise InputError(f"case = {shown(case)}: expected one of {sorted(CASES)}")
        if path is not None and not isinstance(path, paths.TipPath):
            raise InputError(
                f"path = {shown(path)}: expected a vgtarm.paths.TipPath (vgtarm.paths.from_csv reads a file)"
            )
        if preset is not None and preset not in PRESETS:
            raise InputError(f"preset = {shown(preset)}: expected None or one of {sorted(PRESETS)}")
        if robot is not None and not isinstance(robot, str | Path | Robot):
            raise InputError(f"robot = {shown(robot)}: expected None, a robot file's name or a vgtarm.Robot")
        values = {name: _checked(name, value) for name, value in given.items()}
        settings = applied_settings(preset, values) if preset is not None else {}
        filled = {name: o.default for name, o in all_options().items()}
        filled.update(settings)
        filled.update(values)
        for name, value in (("case", case), ("path", path), ("dt", float(dt)), ("preset", preset)):
            object.__setattr__(self, name, value)
        object.__setattr__(self, "robot", str(robot) if isinstance(robot, Path) else robot)
        object.__setattr__(self, "options", _Frozen(filled))
        self.scenario_options()  # the scenario's own checks (two options together), before any work
        self.tool_task()  # likewise

    def __getattr__(self, name: str) -> Any:
        """An option's value by its name (``experiment.seed``)."""
        options = self.__dict__.get("options")
        if options is not None and name in options:
            return options[name]
        raise AttributeError(f"{type(self).__name__!r} has no attribute {name!r}")

    def replace(self, **changes: Any) -> Experiment:
        """A copy with ``changes`` (options or ``case``, ``path``, ``robot``, ``dt``, ``preset``), checked again."""
        own = {"case", "path", "robot", "dt", "preset"}
        fields_ = {name: getattr(self, name) for name in own}
        fields_.update({k: v for k, v in changes.items() if k in own})
        if "case" in changes and "path" not in changes:
            fields_["path"] = None
        if "path" in changes and "case" not in changes:
            fields_["case"] = None
        options = {**self.options, **{k: v for k, v in changes.items() if k not in own}}
        return Experiment(**fields_, options=options)

    def scenario_options(self) -> dict[str, Any]:
        """The options that are the :class:`~vgtarm.simulation.Scenario`'s, as ``simulate`` takes them."""
        from ..simulation import Scenario

        chosen = {name: self.options[name] for name in scenario_names()}
        Scenario(**chosen, external_force=self.external_force() or ExternalForce.none())  # two options together
        return chosen

    def robot_model(self) -> Robot:
        """The robot this experiment runs (built once per process for a file)."""
        if isinstance(self.robot, Robot):
            return self.robot
        return _robot_of_file(self.robot)

    def reference(self, robot: Robot | None = None) -> JointReference:
        """The joint reference: the inverse kinematics of the path with the criterion, cut to ``duration``."""
        robot = robot or self.robot_model()
        desired = self.desired(robot)
        name = f"case {self.case}" if self.case is not None else desired.name
        ik = robot.inverse_kinematics(desired, solver="fast", rates=self.options["rates"], **self.ik_options())
        reference = JointReference.of(ik, name=name)
        duration = self.options["duration"]
        return reference if duration is None else truncate_reference(reference, duration)

    def desired(self, robot: Robot | None = None) -> paths.TipPath:
        """The desired tip path: the case's (placed for ``robot``, default the experiment's) or the one given."""
        if self.case is not None:
            return case_path(robot or self.robot_model(), self.case, self.dt)
        assert self.path is not None
        return self.path

    def ik_options(self) -> dict[str, Any]:
        """The inverse kinematics' options: the tool task (:meth:`tool_task`) and the criterion's (none
        for eq. 12; for the effort criterion its joint-limit weight and the expected cutting force,
        the tool force's, else 0)."""
        task = self.tool_task()
        if self.options["criterion"] == "joint_limits":
            return task
        force = float(self.options["cutting_force"]) if self.options["external_force"] else 0.0
        weight = float(self.options["joint_limit_weight"])
        return {**task, "criterion": str(self.options["criterion"]), "joint_limit_weight": weight, "tool_force": force}

    def tool_task(self) -> dict[str, Any]:
        """The inverse kinematics' keywords of the tool-axis task of ``axis``, ``cone_degrees`` and
        ``entry_point`` (:func:`vgtarm.ik.axis.tool_task_keywords`); ``{}``: the tip alone."""
        from ..ik.axis import tool_task_keywords

        o = self.options
        return tool_task_keywords(o["axis"], o["cone_degrees"], o["entry_point"], names=TOOL_TASK_NAMES)

    def controller(self, n_joints: int) -> ComputedForceControl | SwitchingControl:
        """The controller with the experiment's gains (default: the case's; a path: case 1's)."""
        o = self.options
        case = case_study(self.case or PATH_GAINS_CASE)
        kp = case.kp if o["kp"] is None else o["kp"]
        kv = case.kv if o["kv"] is None else o["kv"]
        if o["controller"] == "cfc":
            return ComputedForceControl.with_gains(kp, kv, n_joints)
        safe = {"hold": o["scm_hold"], "switch_on": o["scm_switch_on"]} if o["scm_variant"] == "safe" else {}
        return SwitchingControl.with_gains(
            kp,
            kv,
            n_joints,
            threshold=case.threshold if o["threshold"] is None else float(o["threshold"]),
            kp_bounds=(case.kp_bounds[0], _upper(case.kp_bounds[1], o["kp_max"], kp)),
            kv_bounds=(case.kv_bounds[0], _upper(case.kv_bounds[1], o["kv_max"], kv)),
            horizon=int(o["horizon"]),
            prediction=o["prediction"],
            variant=o["scm_variant"],
            ga=GAOptions(population_size=int(o["ga_population"]), max_generations=int(o["ga_generations"])),
            **safe,
        )

    def external_force(self) -> ExternalForce | None:
        """The tool force (the case's cutting force and disturbance, at the experiment's magnitudes), or None."""
        if not self.options["external_force"]:
            return None
        eta = float(self.options["disturbance"])
        force = case_study(self.case or PATH_GAINS_CASE).external_force
        return dataclasses.replace(force, cutting_force=float(self.options["cutting_force"]), eta=(eta, eta, eta))

    def controller_model(self, robot: Robot) -> RobotParameters | None:
        """The controller's model: the robot's parameters scaled by the model errors (None: exact)."""
        factors = (self.options["model_mass"], self.options["model_inertia"], self.options["model_friction"])
        if factors == (1.0, 1.0, 1.0):
            return None
        mass, inertia, friction = (float(f) for f in factors)
        return robot.parameters.scaled(mass=mass, inertia=inertia, friction=friction)

    def metadata(self, robot: Robot) -> dict[str, Any]:
        """The summary's entries of the run's inputs (the case and its placement, the path, the gains
        given, the criterion), as ``vgtarm simulate`` records them."""
        o = self.options
        gains: dict[str, Any] = {}
        if o["kp"] is not None or o["kv"] is not None or self.case is None:
            case = case_study(self.case or PATH_GAINS_CASE)
            for key, value in (
                ("kp", o["kp"] if o["kp"] is not None else case.kp),
                ("kv", o["kv"] if o["kv"] is not None else case.kv),
            ):
                gains[key] = np.broadcast_to(np.asarray(value, dtype=float), (robot.n_joints,)).tolist()
        if o["criterion"] != "joint_limits":
            gains["ik_criterion"] = o["criterion"]
        if self.case is None:
            assert self.path is not None
            return {"path": self.path.name, **gains, **task_metadata(robot)}
        placement = path_placement(robot)
        return {
            "case": self.case,
            "case_title": case_study(self.case).title,
            **(placement.metadata() if placement is not None else {}),
            **gains,
        }

    def run(
        self,
        *,
        reference: JointReference | None = None,
        progress: Callable[[int, int], None] | None = None,
        check: bool = True,
        metadata: Mapping[str, Any] | None = None,
    ) -> SimulationResult:
        """Run the experiment: its reference (or ``reference``, computed before), controller, tool
        force and controller model, simulated with its scenario; the result's metadata (and so
        ``summary.json``) holds :meth:`record` under ``experiment``. ``check``: as
        :func:`vgtarm.simulation.simulate` (False: a failed run is returned, not raised)."""
        robot = self.robot_model()
        ref = reference if reference is not None else self.reference(robot)
        info = {**self.metadata(robot), **(metadata or {}), "experiment": self.record()}
        return simulate(
            robot,
            ref,
            self.controller(robot.n_joints),
            controller_model=self.controller_model(robot),
            external_force=self.external_force(),
            metadata=info,
            progress=progress,
            check=check,
            **self.scenario_options(),
        )

    def record(self) -> dict[str, Any]:
        """The experiment as JSON values: the case or the path's name, the robot's name (or file),
        ``dt``, the preset and every option."""
        return {
            "case": self.case,
            "path": None if self.path is None else self.path.name,
            "robot": _robot_record(self.robot),
            "dt": self.dt,
            "preset": self.preset,
            "options": {name: list(v) if isinstance(v, tuple) else v for name, v in self.options.items()},
        }

    @classmethod
    def from_record(
        cls, record: Mapping[str, Any], *, path: paths.TipPath | None = None, robot: str | Robot | None = None
    ) -> Experiment:
        """The experiment a :meth:`record` describes (as read from a run's ``summary.json``). A
        path's record keeps its name only: pass the path itself; ``robot`` replaces the recorded one
        (a file's name, relative to where the run was made)."""
        if not isinstance(record, Mapping) or not isinstance(record.get("options"), Mapping):
            raise InputError(f"experiment record = {shown(record)}: expected the mapping Experiment.record() gives")
        unknown = sorted(set(record) - {"case", "path", "robot", "dt", "preset", "options"})
        if unknown:
            raise InputError(f"experiment record field {unknown[0]!r}: expected case, path, robot, dt, preset, options")
        options = {k: tuple(v) if isinstance(v, list) else v for k, v in record["options"].items()}
        chosen_robot = robot if robot is not None else _robot_of_record(record.get("robot"))
        return cls(
            case=record.get("case"),
            path=path,
            robot=chosen_robot,
            dt=record.get("dt", 1e-3),
            options=options,
        )

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Experiment):
            return NotImplemented
        return self.record() == other.record()

    def __hash__(self) -> int:
        return hash(repr(sorted(self.record().items(), key=lambda kv: kv[0])))


class _Frozen(dict[str, Any]):
    """A read-only mapping of the options (an experiment is frozen)."""

    def _refuse(self, *args: Any, **kwargs: Any) -> None:
        raise TypeError("an Experiment's options are frozen: use Experiment.replace(...)")

    __setitem__ = __delitem__ = update = pop = popitem = clear = setdefault = _refuse  # type: ignore[assignment]


def _robot_record(robot: str | Robot | None) -> str | dict[str, str] | None:
    """The robot in a record: None (the paper's), a file's name, or a robot's name and where it was read."""
    if not isinstance(robot, Robot):
        return robot
    parameters = robot.parameters
    return {"name": str(parameters.name), "source": str(getattr(parameters, "source", "<robot>"))}


def _robot_of_record(value: object) -> str | None:
    """The robot of a record's ``robot`` (:func:`_robot_record`): None for the paper's, else its file;
    a robot built in Python (no file) must be passed to :meth:`Experiment.from_record`."""
    if value is None or isinstance(value, str):
        return value
    if isinstance(value, Mapping):
        source = str(value.get("source", ""))
        if source.startswith("<reference robot"):
            return None
        if source and not source.startswith("<"):
            return source
    raise InputError(
        f"experiment record robot = {shown(value)}: a robot built in Python; pass it to "
        "Experiment.from_record(record, robot=...)"
    )


def _checked(name: str, value: Any) -> Any:
    """``value`` of the option ``name`` checked by its declaration (``kp``, ``kv``: one gain, or one per joint)."""
    declaration = all_options()[name]
    if name in ("axis", "entry_point") and value is not None and not isinstance(value, str):  # three numbers
        return ",".join(repr(float(v)) for v in checks.finite_array(name, value, (3,)))
    if name in ("kp", "kv") and isinstance(value, tuple | list | np.ndarray):
        return tuple(float(declaration.convert(v, where=f"{name}[{i}]")) for i, v in enumerate(value))  # type: ignore[arg-type]
    return declaration.convert(value)


def _upper(bound: float, given: Value, gain: Gain) -> float:
    """A GA's upper bound: the one given (``kp_max``), else the case's, grown to the largest gain."""
    if given is not None:
        return float(given)
    return max(bound, float(np.max(gain)))


def _robot_of_file(file: str | None) -> Robot:
    """The robot of a file (read again at each call: it may have changed), or the paper's (built once per process)."""
    return _paper_robot() if file is None else load_robot(file)


@functools.cache
def _paper_robot() -> Robot:
    return load_robot()


def robot_of_text(text: str, source: str = "<robot file>") -> Robot:
    """A robot from a robot or stack file's text (a study ships it to its workers), built once per
    process; ``source``: the file's name, as the record says where the robot was read."""
    return _robot_of_text(text, source)


@functools.lru_cache(maxsize=8)
def _robot_of_text(text: str, source: str) -> Robot:
    return robot_from_dict(tomllib.loads(text), source=source)
