"""The paper's case studies: the relations the paper reports must hold for our runs too."""

from __future__ import annotations

import numpy as np
import pytest

from vgtarm.app.reports.reproduce import paper_runs, reproduce
from vgtarm.experiment.cases import PAPER_RESULTS, case_study, joint_reference, run_case


@pytest.fixture(scope="module")
def references(robot):
    return {case: joint_reference(robot, case) for case in (1, 2)}


@pytest.fixture(scope="module")
def runs(robot, references):
    """Every exact-rates combination of the paper, run once for the module."""
    out = {}
    for spec in paper_runs(rates=("exact",)):
        out[(spec.case, spec.controller, spec.external_force)] = run_case(
            robot,
            spec.case,
            controller=spec.controller,
            external_force=spec.external_force,
            reference=references[spec.case],
            scm_variant="paper",  # the paper's numbers: its variant
        )
    return out


def test_references_follow_the_paths(robot, references):
    for case, ref in references.items():
        path = case_study(case).path()
        assert len(ref.t) == len(path.t)
        assert np.abs(robot.tip_position(ref.q) - path.position).max() < 1e-9


@pytest.mark.parametrize("case, force", [(1, False), (2, False), (2, True)])
def test_switching_is_never_worse_and_better_whenever_it_switches(runs, case, force):
    cfc = runs[(case, "cfc", force)].summary()
    scm = runs[(case, "scm", force)].summary()
    threshold = case_study(case).threshold
    assert scm["max_tip_error_m"] <= cfc["max_tip_error_m"]
    if cfc["max_tip_error_m"] > threshold:
        assert scm["ga_activations"] > 0
        assert scm["max_tip_error_m"] < cfc["max_tip_error_m"]
    else:
        assert scm["ga_activations"] == 0
        np.testing.assert_array_equal(runs[(case, "scm", force)].q, runs[(case, "cfc", force)].q)


def test_the_tool_force_raises_the_error(runs):
    free = runs[(2, "cfc", False)].summary()["max_tip_error_m"]
    loaded = runs[(2, "cfc", True)].summary()["max_tip_error_m"]
    assert loaded > 10 * free
    # The paper's SCM keeps the loaded error below 0.4 mm; so does ours.
    assert runs[(2, "scm", True)].summary()["max_tip_error_m"] < PAPER_RESULTS[(2, "scm", True)].value_m


def test_exact_model_and_rates_track_case_2_to_micrometres(runs):
    """Case 2 starts and ends at rest: with an exact model only the control sampling is left."""
    assert runs[(2, "cfc", False)].summary()["max_tip_error_m"] < 1e-5


def test_case_1_error_is_a_start_transient(runs):
    s = runs[(1, "cfc", False)].summary()
    assert s["time_of_max_tip_error_s"] < 0.05
    assert s["max_tip_error_after_transient_m"] < 0.1 * s["max_tip_error_m"]


def test_reproduce_writes_the_report_runs_and_figures(robot, tmp_path):
    specs = [s for s in paper_runs() if s.case == 1]
    # the section beyond the paper and the low-force rows: tests/test_observer.py, test_report_page.py
    made = reproduce(robot, tmp_path, runs=specs, beyond_paper=False)
    text = made.report.read_text()
    assert "| 1 | CFC | no | exact | 0.53 mm" in text
    assert "finite diff." in text
    for spec in specs:
        assert (tmp_path / spec.folder / "summary.json").exists()
        assert spec.folder in text
    for name in ("case1_path.png", "case1_error.png", "case1_error_fd.png", "case1_cfc_efforts.png"):
        assert (tmp_path / name).stat().st_size > 1000
        assert f"]({name})" in text
    assert "## Reading" in text
    assert not list(tmp_path.glob(".*.tmp"))
