"""The named settings of the toolkit (issue 22): one definition, read by ``vgtarm simulate --preset``
(:mod:`.cli.presets`) and by ``vgtarm reproduce``'s low-force rows (:mod:`.reports.low_force`).

A preset is a table of ``vgtarm simulate``'s parsed arguments (each replaces the option of the same
name); :func:`preset_options` turns it into the inverse kinematics' and the simulation's keyword
options, as ``vgtarm simulate`` passes them, so a run made from a preset here equals the command's
run with ``--preset``. The choice of ``low-force`` and the measured front it is taken from are in
``docs/control.md`` ("The trade-off: tip error against force").
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..errors import InputError
from .options import all_options

#: Named settings: the parsed arguments of ``vgtarm simulate`` they set. ``low-force``: the effort
#: criterion, the Kalman estimator and the momentum observer; with the tool force
#: (``--external-force``) also the expected cutting force fed forward (``tool_feedforward``) and the
#: gains chosen with it on case 2's measured front (``kp``, ``kv``; without the tool force the case's
#: gains). The choice: the point of the front whose worst tip error over seeds 0 to 4 is the least
#: among those with a peak leg force under 80 N and under 4 N of chatter on seed 0.
PRESETS: dict[str, dict[str, Any]] = {
    "low-force": {
        "criterion": "effort",
        "observer": "momentum",
        "observer_gain": 400.0,
        "estimator": "kalman",
        "estimator_bandwidth_hz": 120.0,
        "tool_force_feedforward": True,
        "kp": 20000.0,
        "kv": 450.0,
    },
}

#: Preset arguments that apply only with the tool force (``--external-force``).
WITH_TOOL_FORCE = frozenset({"tool_force_feedforward", "kp", "kv"})
#: Preset arguments that apply only with computed force control (``--controller cfc``, as the
#: runs of :func:`preset_options`): the gains were chosen on its measured front; the switching
#: method starts from the case's gains (its GA's genes must hit the fixed gains exactly).
WITH_CFC = frozenset({"kp", "kv"})
#: Preset settings that apply only with the value another option has once the preset is applied
#: (the observer's gain with the momentum observer, the Kalman filter's bandwidth with the Kalman
#: filter): an option given beside the preset that turns the first off takes the second with it.
#: Read from the options' declarations (:attr:`vgtarm.option.Option.needs`).
NEEDS: dict[str, tuple[str, Any]] = {
    name: all_options()[name].needs  # type: ignore[misc]
    for settings in PRESETS.values()
    for name in settings
    if all_options()[name].needs is not None and all_options()[name].needs[0] not in ("controller",)  # type: ignore[index]
}
#: Preset arguments a force sensor (``--force-sensor``) replaces: the sensor feeds the measured tool
#: force forward, so neither the observer nor the expected force is wanted beside it.
NOT_WITH_FORCE_SENSOR = frozenset({"observer", "observer_gain", "tool_force_feedforward"})


def preset_options(name: str, *, tool_force: float) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(ik_options, simulation_options)`` of the preset ``name``, as ``vgtarm simulate --preset`` uses
    them: ``ik_options`` for the inverse kinematics of the reference (a criterion other than eq. 12
    with the expected cutting force ``tool_force``, N: the case's with the tool force, else 0),
    ``simulation_options`` for :func:`vgtarm.experiment.cases.run_case` (the feedforward and the gains only
    with a tool force)."""
    if name not in PRESETS:
        raise InputError(f"preset = {name!r}: expected one of {sorted(PRESETS)}")
    ik: dict[str, Any] = {}
    simulation: dict[str, Any] = {}
    for key, value in PRESETS[name].items():
        if key == "criterion":
            if value != "joint_limits":
                ik = {"criterion": value, "tool_force": float(tool_force)}
        elif key in WITH_TOOL_FORCE and not tool_force:
            continue  # chosen with the feedforward of the expected cutting force: not without it
        else:
            simulation[key] = value
    return ik, simulation


def preset_text(name: str) -> str:
    """The settings of preset ``name`` in the command line's words, those that need the tool force apart."""
    settings = PRESETS[name]

    def words(key: str) -> str:
        flag = (all_options()[key].cli_flag or f"--{key}").removeprefix("--")
        value = settings[key]
        return flag if value is True else f"{flag} {value:g}" if isinstance(value, float) else f"{flag} {value}"

    def text(keys: list[str]) -> str:
        return ", ".join(words(key) for key in keys)

    always = [key for key in settings if key not in WITH_TOOL_FORCE]
    tool = [key for key in settings if key in WITH_TOOL_FORCE]
    return text(always) + (f"; with --external-force also {text(tool)}" if tool else "")


def applies(key: str, values: Mapping[str, Any]) -> bool:
    """Whether the preset setting ``key`` applies beside the options ``values`` (the feedforward and
    the gains only with the tool force, the gains only with computed force control, none of the
    observer's or the feedforward's settings with a force sensor, a setting whose option needs
    another's value only with it)."""
    if key in WITH_TOOL_FORCE and not values.get("external_force", False):
        return False
    if key in WITH_CFC and values.get("controller", "cfc") != "cfc":
        return False
    if key in NOT_WITH_FORCE_SENSOR and values.get("force_sensor", False):
        return False
    if key in NEEDS:
        other, value = NEEDS[key]
        return bool(values.get(other) == value)
    return True


def applied_settings(name: str, given: Mapping[str, Any], context: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The settings of preset ``name`` that apply beside the options ``given`` (an option given keeps
    its value; a setting that needs what it replaced gives way: :func:`applies`), in order;
    ``context``: the values of the options not given (default: their defaults)."""
    if name not in PRESETS:
        raise InputError(f"preset = {name!r}: expected one of {sorted(PRESETS)}")
    values = {key: o.default for key, o in all_options().items()}
    values.update(context or {})
    values.update(given)
    applied: dict[str, Any] = {}
    for key, value in PRESETS[name].items():
        if key in given or not applies(key, {**values, **applied}):
            continue
        applied[key] = value
    return applied
