"""The trade-off table's front and the low-force preset's arguments (issue 22)."""

from __future__ import annotations

import argparse

from vgtarm.app.cli.presets import PRESETS, add_preset_flag, apply_preset
from vgtarm.app.reports.force_front import by_setting, choose, pareto, setting_table
from vgtarm.experiment.options import add_flags


def test_pareto_keeps_exactly_the_non_dominated_points():
    points = [(1.0, 5.0), (2.0, 3.0), (2.5, 3.5), (3.0, 1.0), (3.0, 1.0), (4.0, 4.0)]
    assert pareto(points) == [True, True, False, True, True, False]  # equal points do not dominate each other
    assert pareto([(1.0, 2.0), (2.0, 1.0), (3.0, 3.0)]) == [True, True, False]


def test_the_preset_sets_its_arguments_and_the_default_adds_no_option():
    parser = argparse.ArgumentParser()
    add_flags(parser)  # every declared option's flag, as vgtarm simulate has them
    add_preset_flag(parser)
    plain = parser.parse_args([])
    apply_preset(plain)
    assert plain.criterion == "joint_limits" and plain.estimator == "difference" and plain.observer == "none"
    assert plain.estimator_bandwidth_hz is None and not plain.tool_force_feedforward
    low = parser.parse_args(["--preset", "low-force"])
    apply_preset(low)
    assert low.criterion == "effort" and low.observer_gain == PRESETS["low-force"]["observer_gain"]
    bandwidth = PRESETS["low-force"]["estimator_bandwidth_hz"]
    assert low.estimator == "kalman" and low.estimator_bandwidth_hz == bandwidth
    assert not low.tool_force_feedforward  # no tool force


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
    assert given.kp is None and given.kv is None and not given.tool_force_feedforward  # no tool force: the case's gains


def _row(kp, seed, error_mm, peak, chatter, criterion="effort"):
    return {
        "criterion": criterion,
        "kp": kp,
        "seed": str(seed),
        "max_tip_error_m": str(error_mm * 1e-3),
        "peak_force_n": str(peak),
        "rms_force_n": "25.0",
        "chatter_n": str(chatter),
    }


def test_the_preset_rule_takes_the_least_worst_error_within_the_first_seeds_limits():
    """By setting: the worst error over the seeds; the rule keeps a setting whose first seed's peak and
    chatter are within the limits, and among those the least worst error."""
    rows = [
        _row("1", 0, 0.020, 95.0, 3.0),  # best errors, but the first seed's peak is over 80 N
        _row("1", 1, 0.021, 70.0, 3.0),
        _row("2", 1, 0.040, 70.0, 9.0),  # a later seed's chatter does not count
        _row("2", 0, 0.026, 79.0, 3.5),
        _row("3", 0, 0.025, 78.0, 3.9),
        _row("3", 1, 0.031, 78.0, 3.9),
        _row("4", 0, 0.022, 60.0, 4.1),  # chatter over 4 N
    ]
    groups = by_setting(rows)
    assert [g.value("kp") for g in groups] == ["1", "4", "3", "2"]  # by worst error
    assert groups[0].seeds == (0, 1) and groups[0].worst_mm == 0.021 and groups[0].peak_n == 95.0
    pick = choose(groups)
    assert pick is not None and groups[pick].value("kp") == "3"
    assert choose(groups, peak=50.0) is None
    table = setting_table(groups).splitlines()
    assert len(table) == 2 + len(groups) and [line.endswith("| yes |") for line in table[2:]] == [
        False,
        False,
        True,
        False,
    ]
    rows.append(_row("5|x", 0, 0.01, 10.0, 1.0, criterion="a|b"))  # a cell cannot add a column
    assert all(line.count(" | ") == table[0].count(" | ") for line in setting_table(by_setting(rows)).splitlines())
