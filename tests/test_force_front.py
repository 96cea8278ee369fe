"""The trade-off table's front and the low-force preset's arguments (issue 22)."""

from __future__ import annotations

import argparse

from vgtarm.app.cli.presets import PRESETS, add_simulate_options, apply_preset, simulate_options
from vgtarm.app.reports.force_front import pareto


def test_pareto_keeps_exactly_the_non_dominated_points():
    points = [(1.0, 5.0), (2.0, 3.0), (2.5, 3.5), (3.0, 1.0), (3.0, 1.0), (4.0, 4.0)]
    assert pareto(points) == [True, True, False, True, True, False]  # equal points do not dominate each other
    assert pareto([(1.0, 2.0), (2.0, 1.0), (3.0, 3.0)]) == [True, True, False]


def test_the_preset_sets_its_arguments_and_the_default_adds_no_option():
    parser = argparse.ArgumentParser()
    parser.add_argument("--criterion", default="joint_limits")
    parser.add_argument("--observer", default="none")
    parser.add_argument("--observer-gain", type=float, default=None)
    add_simulate_options(parser)
    plain = parser.parse_args([])
    apply_preset(plain)
    assert simulate_options(plain) == {} and plain.criterion == "joint_limits"
    low = parser.parse_args(["--preset", "low-force"])
    apply_preset(low)
    assert low.criterion == "effort" and low.observer_gain == PRESETS["low-force"]["observer_gain"]
    bandwidth = PRESETS["low-force"]["estimator_bandwidth"]
    assert simulate_options(low) == {"estimator": "kalman", "estimator_bandwidth_hz": bandwidth}  # no tool force
