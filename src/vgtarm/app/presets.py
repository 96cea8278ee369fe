"""The named settings of the toolkit (issue 22): one definition, read by ``vgtarm simulate --preset``
(:mod:`.cli.presets`) and by ``vgtarm reproduce``'s low-force rows (:mod:`.reports.low_force`).

A preset is a table of ``vgtarm simulate``'s parsed arguments (each replaces the option of the same
name); :func:`preset_options` turns it into the inverse kinematics' and the simulation's keyword
options, as ``vgtarm simulate`` passes them, so a run made from a preset here equals the command's
run with ``--preset``. The choice of ``low-force`` and the measured front it is taken from are in
``docs/control.md`` ("The trade-off: tip error against force").
"""

from __future__ import annotations

from typing import Any

from ..errors import InputError

#: Named settings: the parsed arguments of ``vgtarm simulate`` they set. ``low-force``: the effort
#: criterion, the Kalman estimator and the momentum observer, with the expected cutting force fed
#: forward when the tool force acts (``tool_feedforward``; without it, left off): the point of the
#: measured front with the least tip error under 4 N of chatter.
PRESETS: dict[str, dict[str, Any]] = {
    "low-force": {
        "criterion": "effort",
        "observer": "momentum",
        "observer_gain": 1000.0,
        "estimator": "kalman",
        "estimator_bandwidth": 100.0,
        "tool_feedforward": True,
    },
}

#: Preset arguments that apply only with the tool force (``--external-force``).
WITH_TOOL_FORCE = frozenset({"tool_feedforward"})

#: The simulation's keyword of each preset argument that is a simulation option.
_SIMULATION = {
    "observer": "observer",
    "observer_gain": "observer_gain",
    "estimator": "estimator",
    "estimator_bandwidth": "estimator_bandwidth_hz",
    "tool_feedforward": "tool_force_feedforward",
}


def preset_options(name: str, *, tool_force: float) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(ik_options, simulation_options)`` of the preset ``name``, as ``vgtarm simulate --preset`` uses
    them: ``ik_options`` for the inverse kinematics of the reference (a criterion other than eq. 12
    with the expected cutting force ``tool_force``, N: the case's with the tool force, else 0),
    ``simulation_options`` for :func:`vgtarm.app.cases.run_case` (the feedforward only with a tool
    force)."""
    if name not in PRESETS:
        raise InputError(f"preset = {name!r}: expected one of {sorted(PRESETS)}")
    ik: dict[str, Any] = {}
    simulation: dict[str, Any] = {}
    for key, value in PRESETS[name].items():
        if key == "criterion":
            if value != "joint_limits":
                ik = {"criterion": value, "tool_force": float(tool_force)}
        elif key in WITH_TOOL_FORCE and not tool_force:
            continue  # the feedforward of the expected cutting force: nothing to feed without it
        else:
            simulation[_SIMULATION[key]] = value
    return ik, simulation
