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


def test_an_option_given_beside_the_preset_keeps_its_value():
    """``vgtarm simulate``'s parser: the preset fills the options the user did not give; its gains
    apply with the tool force only."""
    from vgtarm.app.cli.command import build_parser

    parser = build_parser()
    low = PRESETS["low-force"]
    given = parser.parse_args(["simulate", "--case", "2", "--external-force", "--preset", "low-force", "--kp", "1e4"])
    apply_preset(given)
    assert given.kp == "1e4" and given.kv == repr(low["kv"]) and given.observer_gain == low["observer_gain"]
    given = parser.parse_args(["simulate", "--case", "2", "--preset", "low-force", "--observer-gain", "250"])
    apply_preset(given)
    assert given.observer_gain == 250.0 and given.estimator == "kalman"
    assert given.kp is None and given.kv is None and not given.tool_feedforward  # no tool force: the case's gains
