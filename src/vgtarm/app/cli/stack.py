"""``vgtarm convert-robot`` and what ``vgtarm describe`` prints without building a model.

Registered in :func:`vgtarm.app.cli.command.build_parser` by :func:`add_parsers`. The stack format
(``vgtarm.model.stack``) describes any stack of VGT modules; ``convert-robot`` turns a robot file
of the fixed 7-joint format (default: the shipped reference robot) into it, value for value, so the
stack's model gives the fixed model's numbers (see ``docs/modelling.md``, "Stacks of modules").

``vgtarm describe`` needs no compiled model, so it builds none (a stack of fifty modules would take
hours): it reads the robot file (:func:`robot_description`), evaluates the tip at home and the mass
matrix there with CasADi's interpreter on those two functions alone (:func:`home_figures`; the mass
matrix only when its construction is estimated short) and says what building the whole model
would cost (:func:`model_state`).
"""

from __future__ import annotations

import argparse
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ... import progress
from ...errors import ConfigError, cut, escape
from ...fileio import atomic_write_text, check_output_file, parse_toml, read_text_limited
from ...memory import size_text
from ...model import budget, codegen, compiled
from ...model.actuators import Actuators
from ...model.parameters import ROBOT_FILE_LIMIT, JointStiffness, RobotParameters, load_parameters
from ...model.recursive import RecursiveModel
from ...model.robot import default_model, definition_of, robot_parameters_from_dict
from ...model.stack import Stack, stack_from_parameters, stack_to_toml

#: ``vgtarm describe`` evaluates the mass matrix at home when building its function alone is
#: estimated shorter than this (s): about 11 modules (a stack of 50 would take minutes).
DESCRIBE_MASS_LIMIT = 1.0


def _vector(values: object, digits: int = 6) -> str:
    return "[" + ", ".join(f"{float(v):.{digits}g}" for v in values) + "]"  # type: ignore[attr-defined]


def robot_description(config: Path | None) -> RobotParameters | Stack:
    """The validated parameters of the robot file ``config`` (either format; the shipped reference
    robot for None), read as :func:`vgtarm.load_robot` reads them, without building its model."""
    if config is None:
        return load_parameters(None)
    text = read_text_limited(config, ROBOT_FILE_LIMIT, "configuration file", error=ConfigError)
    data = parse_toml(text, cut(str(config), 200), error=ConfigError)
    return robot_parameters_from_dict(data, source=str(config))


@dataclass(frozen=True)
class HomeFigures:
    """What ``vgtarm describe`` evaluates at the home pose.

    Attributes:
        tip: ``(3,)`` tip point (m).
        eigenvalues: eigenvalues of the mass matrix (kg, kg m^2), or None when not evaluated.
        mass_note: why the mass matrix was not evaluated (empty when it was).
    """

    tip: NDArray[np.float64]
    eigenvalues: NDArray[np.float64] | None
    mass_note: str


def home_figures(parameters: RobotParameters | Stack) -> HomeFigures:
    if (
        isinstance(parameters, Stack)
        and (os.environ.get("VGTARM_MODEL", "") or default_model(parameters)) == "recursive"
    ):
        model = RecursiveModel(parameters)
        tip = model.forward_kinematics(parameters.home)["tip"]
        eigenvalues = np.asarray(np.linalg.eigvalsh(model.mass_matrix(parameters.home)), dtype=np.float64)
        return HomeFigures(tip, eigenvalues, "")
    return _symbolic_home_figures(parameters)


def _symbolic_home_figures(parameters: RobotParameters | Stack) -> HomeFigures:
    """The tip and the mass matrix's eigenvalues at home, from the functions of the model's one
    definition run by CasADi's interpreter: the tip always (the kinematics alone: 0.06 s for fifty
    modules), the mass matrix when its construction is estimated shorter than
    :data:`DESCRIBE_MASS_LIMIT`. Nothing is compiled or written."""
    definition = definition_of(parameters)
    cost = budget.estimate(definition)
    names = ["tip"] + (["mass"] if cost.mass_seconds <= DESCRIBE_MASS_LIMIT else [])
    steps = len(names) + 1  # each function built, then their evaluation
    builders, built = codegen.builders_for(definition), {}
    for k, name in enumerate(names):  # compiled.functions_of, one function at a time to report progress
        built[name] = builders[name]()
        progress.report(k + 1, steps)
    functions = compiled.InterpretedBackend(built)
    home, p, n = parameters.home, parameters.vector(), parameters.n_joints
    tip = functions.evaluate("tip", [home, p], 1)[0][0]
    if "mass" not in names:
        note = (
            f"not evaluated: its function alone takes about {budget.time_text(cost.mass_seconds)} to build "
            f"for {n} joints (describe builds no model)"
        )
        return HomeFigures(tip, None, note)
    mass = functions.evaluate("mass", [home, p], 1)[0].reshape(n, n)
    progress.report(steps, steps)
    return HomeFigures(tip, np.asarray(np.linalg.eigvalsh(mass), dtype=np.float64), "")


def model_state(parameters: RobotParameters | Stack) -> str:
    """What a command that needs the model would do: load the compiled library from the cache, or
    build it (its estimated cost, and whether it would be refused), or use the interpreter."""
    definition = definition_of(parameters)
    chosen = os.environ.get("VGTARM_MODEL", "") or default_model(parameters)
    if isinstance(parameters, Stack) and chosen == "recursive":
        return "the recursive model (nothing to build per arm; --model symbolic for the compiled symbolic library)"
    cost = budget.estimate(definition)
    choice = compiled.backend_choice()
    if choice == "interpreted":
        kind, what = "interpreted", "symbolic model for CasADi's interpreter (VGTARM_BACKEND)"
    elif choice == "auto" and compiled.find_compiler() is None:
        kind, what = "interpreted", "no C compiler; symbolic model for CasADi's interpreter"
    elif compiled.library_cached(definition):
        return "compiled library in the cache"
    else:
        kind, what = "compiled", "compiled library"
    text = (
        f"{what} not built yet: about {budget.time_text(cost.seconds(kind))} and "
        f"{size_text(cost.bytes(kind))} to build on first use (estimated)"
    )
    try:
        budget.check(cost, kind)
    except budget.BuildRefused:
        return f"{text}, more than allowed here: commands that need it refuse to build it"
    return text


def describe_stack(stack: Stack) -> int:
    """``vgtarm describe`` of a stack: modules, joints, bodies, tip and reach at home, mass matrix."""
    home = stack.home
    state, figures = model_state(stack), home_figures(stack)  # before any line: either may refuse in one line
    tip = figures.tip
    print(f"robot      {escape(stack.name)}")  # a name from a user's file never drives the terminal
    print(f"source     {escape(stack.source)}")
    print(f"model      a stack of {stack.n_modules} modules, {stack.n_joints} joints; {state}")
    for k, module in enumerate(stack.modules, start=1):
        twist = "" if module.twist is None else f", then twist psi{k + 1} (height {module.twist.height:g} m)"
        print(f"module {k:<3} b = {module.b:g} m, d = {module.d:g} m, plane {module.plane:g} deg{twist}")
    print("joints     name   min        max        home")
    lower, upper = stack.lower, stack.upper
    for i, name in enumerate(stack.joint_names):
        print(f"           {name:<6} {lower[i]:<10.6g} {upper[i]:<10.6g} {home[i]:.10g} {stack.joint_units[i]}")
    for name, body in zip(stack.body_names, stack.bodies, strict=True):
        print(f"body       {name:<13} mass {body.mass:g} kg, com {_vector(body.com)} m")
    print(f"tool       {_vector(stack.tool)} m from the last mount point")
    print(f"tool axis  {_vector(stack.tool_axis)}, edge {_vector(stack.tool_edge)} in the end-effector frame")
    print(f"friction   {_vector(stack.viscous)} (N s/m legs; N m s/rad twists)")
    print_actuators(stack.actuators)
    print_stiffness(stack.stiffness)
    print(f"gravity    {_vector(stack.gravity)} m/s^2")
    print(f"tip @ home {_vector(tip, 10)} m; reach {float(np.linalg.norm(tip)):.6g} m")
    if figures.eigenvalues is None:
        print(f"M @ home   {figures.mass_note}")
    else:
        print(f"M @ home   eigenvalues {_vector(figures.eigenvalues, 5)} (kg, kg m^2)")
    return 0


def print_stiffness(stiffness: JointStiffness | None) -> None:
    """The joints' stiffness of the ``[stiffness]`` table (``vgtarm describe``), or that there is none."""
    if stiffness is None:
        print("stiffness  none (rigid joints: add a [stiffness] table, docs/stiffness.md)")
        return
    print(
        "stiffness  "
        + ", ".join(
            f"{name} {k:.6g} {'N m/rad' if name.startswith('psi') else 'N/m'}"
            for name, k in zip(stiffness.names, stiffness.values, strict=True)
        )
    )


def print_actuators(actuators: Actuators | None) -> None:
    """``vgtarm describe``'s lines of the actuators: one per joint that has one (peak force, no-load
    speed, acceleration limit, whether the force-speed line holds), or that there are none."""
    if actuators is None:
        print("actuators  none (no limits: add an [actuators] table, docs/actuators.md)")
        return
    print("actuators  joint  force      speed      accel      force-speed line")
    for name, actuator in zip(actuators.names, actuators.joints, strict=True):
        if actuator is None:
            print(f"           {name:<6} none")
            continue
        twist = name.startswith("psi")
        units = ("N m", "rad/s", "rad/s^2") if twist else ("N", "m/s", "m/s^2")
        accel = "none" if math.isinf(actuator.acceleration) else f"{actuator.acceleration:.6g}"
        print(
            f"           {name:<6} {actuator.force:<10.6g} {actuator.speed:<10.6g} {accel:<10} "
            f"{'yes' if actuator.force_speed else 'no'}  ({', '.join(units)})"
        )


def cmd_convert_robot(args: argparse.Namespace) -> int:
    """Convert a 7-joint robot file into a stack file."""
    check_output_file(args.out, "--out", inputs=[args.config])
    parameters = load_parameters(args.config)
    stack = stack_from_parameters(parameters)
    origin = "the shipped reference robot" if args.config is None else cut(str(args.config), 200)
    header = (
        f"Written by `vgtarm convert-robot` from {origin}.\n"
        "A stack of VGT modules (see docs/modelling.md, 'Stacks of modules'); units SI, plane angles in degrees.\n"
        f"Joints: {' '.join(stack.joint_names)}."
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(args.out, stack_to_toml(stack, header=header))
    print(f"stack of {stack.n_modules} modules and {stack.n_twists} twist joint written to {escape(str(args.out))}")
    return 0


def add_parsers(sub: Any) -> None:
    """Add ``convert-robot`` to the subparsers ``sub``."""
    convert = sub.add_parser("convert-robot", help="write a robot file as a stack of VGT modules")
    convert.add_argument(
        "--config", type=Path, default=None, metavar="FILE", help="robot TOML file (default: the reference robot)"
    )
    convert.add_argument("--out", type=Path, required=True, metavar="FILE", help="stack TOML file to write")
    convert.set_defaults(run=cmd_convert_robot)
