"""The compiled drilling loop (``drill_loop.c``, ``vgt_drill_control.h``) against the NumPy loop
(``vgtarm.drilling.loop``), its independent reference: with exact sensing the two runs are the same
path to rounding in both force-control modes and with either feedback; with the encoders, where a
rounding can move one reading by a step and the two noise sequences part, every measure of the
summary agrees; the robot without the compiled library is refused one line."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vgtarm.drilling import bone_from_dict, load_bone
from vgtarm.drilling import compiled as compiled_loop
from vgtarm.drilling.control import DrillingSettings
from vgtarm.drilling.loop import ENGINES, SERIES, drilling_run
from vgtarm.errors import InputError
from vgtarm.model.recursive.backend import RecursiveBackend
from vgtarm.model.robot import Robot

from .conftest import small_bone_of
from .test_drilling_control import FEMUR

SMALL = {"feed_limit": 2.0e-3, "gap": 0.2e-3, "duration": 8.0}
EXACT = {"encoder_resolution": 0.0, "twist_resolution": 0.0}


@pytest.fixture(scope="module")
def small_bone():
    return small_bone_of(1.0e-3, 1.2e-3, 1.0e-3)


def _pair(robot, bone, **settings):
    s = DrillingSettings(**SMALL, **settings)
    return drilling_run(robot, bone, s, engine="compiled"), drilling_run(robot, bone, s, engine="numpy")


@pytest.mark.parametrize(
    ("mode", "feedback"), [("admittance", "observer"), ("explicit", "observer"), ("admittance", "sensor")]
)
def test_exact_sensing_is_the_numpy_path(robot, small_bone, mode, feedback):
    fast, slow = _pair(robot, small_bone, mode=mode, feedback=feedback, **EXACT)
    assert fast.success and slow.success
    assert fast.series.shape == slow.series.shape
    assert [(k, layer) for _, k, layer in fast.events] == [(k, layer) for _, k, layer in slow.events]
    np.testing.assert_allclose([t for t, *_ in fast.events], [t for t, *_ in slow.events], atol=1e-12)
    for i, name in enumerate(SERIES):
        scale = max(float(np.max(np.abs(slow.series[:, i]))), 1e-9)
        error = float(np.max(np.abs(fast.series[:, i] - slow.series[:, i])))
        assert error <= 1e-8 * scale, (name, error, scale)
    np.testing.assert_allclose(fast.efforts, slow.efforts, rtol=0, atol=1e-8 * np.max(np.abs(slow.efforts)))


def test_with_encoders_every_measure_agrees(robot, small_bone):
    fast, slow = _pair(robot, small_bone, mode="admittance")
    a, b = fast.summary(), slow.summary()
    assert a["success"] and b["success"]
    assert a["false_detections"] == b["false_detections"] == 0
    assert abs(a["protrusion"] - b["protrusion"]) <= 5e-6
    assert abs(a["detection_delay"] - b["detection_delay"]) <= 0.005
    for x, y in zip(a["layers"], b["layers"], strict=True):
        assert x["thrust_error_rms"] == pytest.approx(y["thrust_error_rms"], rel=0.05, abs=0.02)
    assert a["lateral_deviation_max"] == pytest.approx(b["lateral_deviation_max"], rel=0.2)
    assert a["axis_error_max"] == pytest.approx(b["axis_error_max"], rel=0.2)


def test_the_run_without_a_breakthrough_ends_at_its_duration(robot, small_bone):
    s = DrillingSettings(**{**SMALL, "duration": 0.3})
    fast = drilling_run(robot, small_bone, s, engine="compiled")
    slow = drilling_run(robot, small_bone, s, engine="numpy")
    assert not fast.success and fast.reason == slow.reason == "no breakthrough detected within 0.3 s"
    assert fast.series.shape == slow.series.shape == (301, len(SERIES))


def test_a_robot_without_the_loops_functions_is_refused(robot):
    from vgtarm.model.stack.description import reference_stack

    stack = reference_stack()
    recursive = Robot(stack, RecursiveBackend(stack))
    assert not compiled_loop.available(recursive) and compiled_loop.available(robot)
    bone = load_bone(FEMUR)
    for engine in ENGINES:
        with pytest.raises(InputError, match=r"^robot backend = '\w+': expected the symbolic model"):
            drilling_run(recursive, bone, DrillingSettings(duration=0.01), engine=engine)
    with pytest.raises(InputError, match=r"^engine = 'fast': expected one of"):
        drilling_run(robot, bone, DrillingSettings(duration=0.01), engine="fast")


def test_the_actuators_clip_the_efforts_in_both_loops(tight_robot, small_bone):
    fast, slow = _pair(tight_robot, small_bone, **EXACT)
    force = tight_robot.actuators.force
    assert fast.success and slow.success
    at_limit = np.abs(fast.efforts) >= force - 1e-12
    assert at_limit.any() and np.all(np.abs(fast.efforts) <= force)  # clipped, and never beyond
    assert np.array_equal(at_limit, np.abs(slow.efforts) >= force - 1e-12)
    for i, name in enumerate(SERIES):
        scale = max(float(np.max(np.abs(slow.series[:, i]))), 1e-9)
        assert float(np.max(np.abs(fast.series[:, i] - slow.series[:, i]))) <= 1e-8 * scale, name


def test_a_hidden_transition_arms_the_breakthrough_in_both_loops(robot, small_bone):
    """A near cortex as soft as the cancellous bone (1000 kg/m^3: 6.6 N against 5.6 N) hides the
    first transition; both loops arm the breakthrough by depth and stop at the same sample."""
    data = small_bone.to_dict()
    data["layers"][0]["density"] = 1000.0
    soft = bone_from_dict(data, source="soft near cortex")
    s = DrillingSettings(**{**SMALL, "feed_limit": 1.0e-3, "duration": 10.0}, **EXACT)
    fast = drilling_run(robot, soft, s, engine="compiled", nominal=small_bone)
    slow = drilling_run(robot, soft, s, engine="numpy", nominal=small_bone)
    assert [k for _, k, _ in fast.events] == [k for _, k, _ in slow.events] == ["contact", "armed", "breakthrough"]
    assert [t for t, *_ in fast.events] == pytest.approx([t for t, *_ in slow.events], abs=1e-12)
    assert fast.summary()["protrusion"] == pytest.approx(slow.summary()["protrusion"], abs=1e-9)
    assert fast.summary()["protrusion"] < 0.2e-3


def test_the_cap_breaks_out_the_same_in_both_loops_and_is_caught_at_once(robot, small_bone):
    """With a cap strength the far cortex's cap breaks out before the apex reaches the far surface
    (at ``cap_thickness`` under the thrust); both loops break it at the same plant step and detect
    it within the target's 20 ms, the apex stopping short of the surface."""
    from vgtarm.drilling.bone import cap_thickness

    data = small_bone.to_dict()
    data["model"]["cap_strength"] = 1.5e8
    capped = bone_from_dict(data, source="capped")
    assert capped.to_dict()["model"]["cap_strength"] == 1.5e8
    s = DrillingSettings(**SMALL, **EXACT)
    fast = drilling_run(robot, capped, s, engine="compiled")
    slow = drilling_run(robot, capped, s, engine="numpy")
    assert math.isfinite(fast.fracture_time) and fast.fracture_time == slow.fracture_time
    for i, name in enumerate(SERIES):
        scale = max(float(np.max(np.abs(slow.series[:, i]))), 1e-9)
        assert float(np.max(np.abs(fast.series[:, i] - slow.series[:, i]))) <= 1e-8 * scale, name
    summary = fast.summary()
    assert summary["breakthrough_true_time"] == fast.fracture_time
    assert 0.0 < summary["detection_delay"] <= 0.020 and summary["false_detections"] == 0
    assert summary["protrusion"] < 0.0  # the apex never reached the far surface
    # the cap went where the plate formula puts it: the bone left ahead of the apex at the fracture
    k = int(np.searchsorted(fast.column("t"), fast.fracture_time))
    left = capped.thickness - fast.column("depth")[k - 1]
    assert left == pytest.approx(cap_thickness(capped, float(fast.column("thrust")[k - 1])), rel=0.05)
