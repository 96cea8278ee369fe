"""The simulation's front door: the scenario record, its keyword form, and the engines behind one
interface, each giving the same run as before bit for bit."""

from __future__ import annotations

import json

import numpy as np
import pytest

import vgtarm
from vgtarm.control import ComputedForceControl, SwitchingControl
from vgtarm.ga import GAOptions
from vgtarm.model.compiled import InterpretedBackend, build_functions
from vgtarm.simulation import ExternalForce, Scenario, SimulationResult, engines, simulate
from vgtarm.simulation.result import MODE_FIXED
from vgtarm.simulation.simulator import drive, prepare

from .test_simulation import smooth_reference

CFC = ComputedForceControl.with_gains(15000.0, 600.0)
ARRAYS = ("q", "qd", "effort", "f_ext", "tip", "tip_error", "mode")


def _same_run(a: SimulationResult, b: SimulationResult) -> None:
    for name in ARRAYS:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert [(x.sample, x.best_fitness) for x in a.activations] == [(x.sample, x.best_fitness) for x in b.activations]


def test_the_keyword_form_builds_the_scenario_bit_for_bit(robot):
    ref = smooth_reference(robot, duration=0.08)
    options = dict(external_force=ExternalForce(), seed=4, observer="momentum", encoder_resolution=1e-6)
    by_keywords = simulate(robot, ref, CFC, **options)
    by_record = simulate(robot, ref, CFC, Scenario(**options))
    _same_run(by_keywords, by_record)
    assert by_keywords.metadata["scenario"] == by_record.metadata["scenario"] == Scenario(**options).record()


def test_a_scenario_and_keywords_together_or_an_unknown_option_are_refused(robot):
    ref = smooth_reference(robot, duration=0.01)
    with pytest.raises(vgtarm.InputError, match=r"a scenario and the options \['seed'\]"):
        simulate(robot, ref, CFC, Scenario(), seed=3)
    with pytest.raises(vgtarm.InputError, match=r"unknown option 'integrater': expected one of \[.*'integrator'"):
        simulate(robot, ref, CFC, integrater="rk4")
    with pytest.raises(vgtarm.InputError, match="scenario = 'fast': expected None or a vgtarm.simulation.Scenario"):
        simulate(robot, ref, CFC, "fast")  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("integrator", "leapfrog", "integrator = 'leapfrog': expected one of"),
        ("substeps", 0, "substeps = 0: expected a whole number from 1 to 1,000,000"),
        ("substeps", True, "substeps = True: expected a whole number"),
        ("seed", -1, "seed = -1: expected a whole number from 0 to 2"),
        ("observer", "kalman", "observer = 'kalman': expected one of"),
        ("transient_s", float("nan"), "transient_s = nan: expected a duration >= 0"),
        ("external_force", 20.0, "external_force = 20.0: expected None or a vgtarm.simulation.ExternalForce"),
        ("controller_model", "heavy", "controller_model = 'heavy': expected None, a Robot"),
        ("plant_engine", 3, "plant_engine = 3: expected a name"),
    ],
)
def test_the_scenario_is_validated_when_built(field, value, message):
    with pytest.raises(vgtarm.InputError, match=message):
        Scenario(**{field: value})
    with pytest.raises(vgtarm.InputError, match=message):
        Scenario().replace(**{field: value})  # a frozen record: a change is a new, checked one


def test_the_scenario_is_stored_whole_and_runs_again_from_the_summary(robot, tmp_path):
    ref = smooth_reference(robot, duration=0.08)
    model = robot.parameters.scaled(mass=1.1)
    scenario = Scenario(
        external_force=ExternalForce(cutting_force=12.0, eta=(1.0, 2.0, 3.0)),
        controller_model=model,
        integrator="rk4",
        substeps=2,
        seed=9,
        initial_state=(ref.q[0], np.full(robot.n_joints, 1e-3)),
        encoder_resolution=1e-6,
        velocity_noise=1e-4,
    )
    first = simulate(robot, ref, CFC, scenario)
    folder = first.save(tmp_path / "run")
    stored = json.loads((folder / "summary.json").read_text())["scenario"]
    assert stored["controller_model"] == model.name and stored["external_force"]["eta"] == [1.0, 2.0, 3.0]
    assert SimulationResult.load(folder).metadata["scenario"] == stored
    again = Scenario.from_record(stored, controller_model=model)
    assert again.record() == scenario.record()
    _same_run(first, simulate(robot, ref, CFC, again))
    with pytest.raises(vgtarm.InputError, match="scenario record field 'speed'"):
        Scenario.from_record({**stored, "speed": 2})


def _engine(robot, controller, **options):
    run = prepare(robot, smooth_reference(robot, duration=0.1), controller, Scenario(**options))
    return engines.engine_for(run.plant, run.scenario.plant_engine, run.job)


def test_each_engine_is_picked_by_the_plant_and_the_controller(robot, monkeypatch):
    scm = SwitchingControl.with_gains(5000.0, 300.0, variant="paper", threshold=5e-5, ga=GAOptions(max_generations=3))
    assert type(_engine(robot, CFC)) is engines.CompiledLoop
    assert type(_engine(robot, scm)) is engines.CompiledSwitchingLoop
    monkeypatch.setattr(engines, "GA_IN_LOOP", False)
    assert type(_engine(robot, scm)) is engines.CompiledLoop
    slow = vgtarm.Robot(robot.parameters, InterpretedBackend(build_functions()))
    assert type(_engine(slow, scm)) is engines.NumpyLoop
    monkeypatch.setitem(engines.PLANT_ENGINES, "twin", lambda plant, model: engines.PythonLoop(plant, model))
    assert type(_engine(robot, CFC, plant_engine="twin")) is engines.RegisteredLoop


def test_every_engine_gives_the_same_switching_run(robot, monkeypatch):
    """The compiled GA inside the loop and the same GA called from Python per activation: one
    bookkeeping of modes, activations and GA time, bit for bit."""
    ref = smooth_reference(robot, duration=0.1)
    scm = SwitchingControl.with_gains(5000.0, 300.0, variant="paper", threshold=5e-5, ga=GAOptions(max_generations=3))
    inside = simulate(robot, ref, scm, external_force=ExternalForce(), seed=2)
    monkeypatch.setattr(engines, "GA_IN_LOOP", False)
    outside = simulate(robot, ref, scm, external_force=ExternalForce(), seed=2)
    _same_run(inside, outside)
    assert inside.activations and all(a.error_after_m >= 0 for a in inside.activations)
    assert inside.ga_time_s == pytest.approx(sum(a.wall_time_s for a in inside.activations))


def test_drive_reports_progress_and_marks_every_sample(robot):
    ref = smooth_reference(robot, duration=0.2)
    calls: list[tuple[int, int]] = []
    run = prepare(robot, ref, CFC, Scenario())
    outcome = drive(run, lambda done, total: calls.append((done, total)))
    n = len(ref.t)
    assert outcome.success and calls[-1] == (n, n) and len(calls) >= 50
    assert [done for done, _ in calls] == sorted({done for done, _ in calls})
    assert (outcome.mode == MODE_FIXED).all() and not outcome.activations
    _same_run(simulate(robot, ref, CFC), simulate(robot, ref, CFC, progress=lambda *_: None))


def test_the_scenario_documents_every_field_and_simulate_points_to_it():
    """A new scenario field is one field, one check, one use, and one entry of the Scenario's
    attributes; simulate's docstring sends its reader there instead of repeating them."""
    import inspect
    import re

    doc = inspect.getdoc(Scenario) or ""
    attributes = doc.split("Attributes:", 1)[1]
    # each entry: indented names, comma-separated, before the colon that opens its text
    documented = {
        name.strip()
        for line in attributes.splitlines()
        if (entry := re.match(r"^    ([a-z_0-9, ]+):", line))
        for name in entry.group(1).split(",")
    }
    assert [f for f in Scenario.option_names() if f not in documented] == []
    assert ":class:`~vgtarm.simulation.Scenario`" in (inspect.getdoc(simulate) or "")


def test_the_record_names_the_feedforward_speed_used():
    """With the feedforward, the record keeps the smoothing speed it used (the default has changed
    before: a record saying "the default" would run differently later); without it, as given."""
    from vgtarm.simulation.external import DEFAULT_FEEDFORWARD_SPEED

    fed = Scenario(external_force=ExternalForce(), tool_force_feedforward=True)
    record = fed.record()
    assert record["tool_force_speed"] == DEFAULT_FEEDFORWARD_SPEED
    again = Scenario.from_record(json.loads(json.dumps(record)))
    assert again.feedforward_speed == fed.feedforward_speed and again.tool_force_speed == DEFAULT_FEEDFORWARD_SPEED
    assert Scenario(external_force=ExternalForce()).record()["tool_force_speed"] is None
