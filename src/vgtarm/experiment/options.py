"""The options of an experiment beyond the simulation's :class:`~vgtarm.simulation.Scenario`, declared once.

An experiment (:class:`vgtarm.experiment.Experiment`) is a run from the robot to its results:
the path (a case or a file), the reference's inverse kinematics and its criterion, the controller
and its gains, the switching method's settings, the tool force, the controller model's errors, and
the :class:`~vgtarm.simulation.Scenario`. Each option is an :class:`~vgtarm.option.Option`: the
experiment's own are declared here, the scenario's on its fields; :func:`all_options` gives them all
in one table, from which ``vgtarm simulate``'s flags (:func:`add_flags`), the study file's parameters
(:mod:`vgtarm.study.spec`) and the presets' keys (:mod:`.presets`) are generated.
"""

from __future__ import annotations

import argparse
import functools

from ..control.scm import MAX_HORIZON, SWITCH_ON, VARIANTS
from ..ik.effort import CRITERIA, DEFAULT_JOINT_LIMIT_WEIGHT
from ..option import ID_ALWAYS, Option
from ..simulation.scenario import Scenario

CONTROLLERS = ("cfc", "scm")
RATES = ("exact", "finite_difference")
PREDICTIONS = ("exact", "linear", "quadratic")


def _factor(name: str) -> Option:
    return Option(
        f"model_{name}",
        float,
        1.0,
        "a factor > 0",
        low=0.0,
        strict=True,
        metavar="FACTOR",
        in_id=ID_ALWAYS,
        help=f"scale the controller model's {name} (a wrong model; default 1)",
    )


def _gain(name: str, unit: str) -> Option:
    return Option(
        name, float, None, f"a gain > 0 ({unit}; default: the case's)", low=0.0, strict=True, flag="", in_id=ID_ALWAYS
    )  # the command line takes one per joint (its own flag)


#: The experiment's own options, in the order of a study point's inputs (the controller, the
#: switching method, the tool force, the controller model's errors).
EXPERIMENT_OPTIONS: tuple[Option, ...] = (
    Option(
        "controller",
        str,
        "cfc",
        f"one of {list(CONTROLLERS)}",
        choices=CONTROLLERS,
        in_id=ID_ALWAYS,
        help="computed force control or the GA switching method",
    ),
    _gain("kp", "1/s^2"),
    _gain("kv", "1/s"),
    Option(
        "threshold",
        float,
        None,
        "a tip error > 0 (m; SCM; default: the case's)",
        low=0.0,
        strict=True,
        flag="",
        in_id=ID_ALWAYS,
    ),
    Option(
        "horizon",
        int,
        20,
        f"a whole number from 1 to {MAX_HORIZON:,} (control periods; SCM)",
        low=1,
        high=MAX_HORIZON,
        needs=("controller", "scm"),
        in_id=ID_ALWAYS,
        help="GA fitness prediction horizon in control periods (default 20)",
    ),
    Option(
        "scm_variant",
        str,
        "safe",
        f"one of {list(VARIANTS)} (SCM)",
        choices=VARIANTS,
        needs=("controller", "scm"),
        in_id=ID_ALWAYS,
        help="switching method: the paper's GA, or safe (gains admitted on the discrete loop first; default)",
    ),
    Option(
        "scm_hold",
        int,
        None,
        "a whole number of control periods from 1 to the horizon (safe SCM; default half the horizon)",
        low=1,
        high=MAX_HORIZON,
        metavar="N",
        needs=("scm_variant", "safe"),
        help="--scm-variant safe: control periods an admitted gain set is held from its switch, unless the error "
        "it sees rises above its value at the switch (1 to the horizon; default half the horizon)",
    ),
    Option(
        "scm_switch_on",
        str,
        None,
        f"one of {list(SWITCH_ON)} (safe SCM; default 'measured')",
        choices=SWITCH_ON,
        needs=("scm_variant", "safe"),
        help="--scm-variant safe: the tip error the threshold is tested on: measured (the controller model's tip "
        "at the encoder readings; default) or true (the plant's, as the paper's variant)",
    ),
    Option(
        "prediction", str, "quadratic", f"one of {list(PREDICTIONS)}", choices=PREDICTIONS, flag="", in_id=ID_ALWAYS
    ),
    Option(
        "kp_max",
        float,
        None,
        "an upper GA bound > 0 (1/s^2; default: the case's)",
        low=0.0,
        strict=True,
        flag="",
        in_id=ID_ALWAYS,
    ),
    Option(
        "kv_max",
        float,
        None,
        "an upper GA bound > 0 (1/s; default: the case's)",
        low=0.0,
        strict=True,
        flag="",
        in_id=ID_ALWAYS,
    ),
    Option("ga_population", int, 50, "a whole number >= 2", low=2, flag="", in_id=ID_ALWAYS),
    Option("ga_generations", int, 50, "a whole number >= 0", low=0, flag="", in_id=ID_ALWAYS),
    Option(
        "external_force",
        bool,
        False,
        "true or false",
        in_id=ID_ALWAYS,
        help="cutting force (20 N) and disturbance (5 N) on the tool",
    ),
    Option("cutting_force", float, 20.0, "a force >= 0 (N)", low=0.0, flag="", in_id=ID_ALWAYS),
    Option("disturbance", float, 5.0, "a bound >= 0 (N, each axis)", low=0.0, flag="", in_id=ID_ALWAYS),
    _factor("mass"),
    _factor("inertia"),
    _factor("friction"),
)

#: The reference's inverse kinematics: its redundancy criterion and the weight of eq. 12 beside the
#: efforts (they count in a study point's id only away from their default).
IK_OPTIONS: tuple[Option, ...] = (
    Option(
        "criterion",
        str,
        "joint_limits",
        f"one of {list(CRITERIA)}",
        choices=CRITERIA,
        help="redundancy criterion of the reference: eq. 12 (default) or the static actuator efforts",
    ),
    Option(
        "joint_limit_weight",
        float,
        DEFAULT_JOINT_LIMIT_WEIGHT,
        "a weight > 0 (of eq. 12 in the effort criterion)",
        low=0.0,
        strict=True,
        metavar="W",
        needs=("criterion", "effort"),
        help=f"--criterion effort: the weight of eq. 12's joint-limit cost beside the efforts "
        f"(default {DEFAULT_JOINT_LIMIT_WEIGHT:g})",
    ),
    Option(
        "axis",
        str,
        None,
        "a unit vector written x,y,z (F0)",
        metavar="X,Y,Z",
        help="a tool-axis task: the tool's axis held along this unit vector while the tip follows the path, "
        "its spin free (default: the tip alone)",
    ),
    Option(
        "cone_degrees",
        float,
        None,
        "a half-angle in (0, 90) degrees",
        low=0.0,
        high=90.0,
        strict=True,
        flag="--cone",
        metavar="DEG",
        help="with --axis: the axis only within this half-angle of it (degrees)",
    ),
    Option(
        "entry_point",
        str,
        None,
        "a point written x,y,z (m, F0)",
        metavar="X,Y,Z",
        help="a tool-axis task: the tool's axis through this point while the tip follows the path (keyhole work)",
    ),
)

#: The path's sampling of the reference and how much of it is run (a study gives them in its
#: ``[study]`` table, once for all its points).
PATH_OPTIONS: tuple[Option, ...] = (
    Option(
        "rates",
        str,
        "exact",
        f"one of {list(RATES)}",
        choices=RATES,
        study=False,
        help="how the reference rates are computed (default: exact)",
    ),
    Option(
        "duration",
        float,
        None,
        "a time > 0 (s)",
        low=0.0,
        strict=True,
        metavar="S",
        study=False,
        help="run only the first S seconds of the path",
    ),
)


@functools.cache
def all_options() -> dict[str, Option]:
    """Every option of an experiment by name: the experiment's own, the scenario's integrator and
    substeps, the inverse kinematics', then the rest of the scenario's and the path's (the order of
    a study point's inputs)."""
    scenario = Scenario.options()
    first = ("integrator", "substeps")
    table = {o.name: o for o in EXPERIMENT_OPTIONS}
    table.update({name: scenario[name] for name in first})
    table.update({o.name: o for o in IK_OPTIONS})
    table.update({name: o for name, o in scenario.items() if name not in first})
    table.update({o.name: o for o in PATH_OPTIONS})
    return table


def study_options() -> dict[str, Option]:
    """The options a study file may set, in the order of a point's inputs."""
    return {name: o for name, o in all_options().items() if o.study}


def scenario_names() -> frozenset[str]:
    """The names of the options that are the :class:`~vgtarm.simulation.Scenario`'s."""
    return frozenset(Scenario.options())


def add_flags(parser: argparse.ArgumentParser, names: tuple[str, ...] | None = None) -> None:
    """Add the command-line flags of the options ``names`` (default: every option that has one) to ``parser``."""
    table = all_options()
    for name in names if names is not None else tuple(table):
        if table[name].cli_flag:
            table[name].add_to(parser)
