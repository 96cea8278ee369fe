"""Figures of closed-loop runs, checked on small synthetic results (no simulator needed)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from mpl_toolkits.mplot3d.axes3d import Axes3D

from vgtarm.app.pictures.plotting import (
    comparison_figure,
    label_of,
    plot_efforts,
    plot_joint_errors,
    plot_path_3d,
    plot_tip_error,
    save_figure,
)
from vgtarm.errors import InputError
from vgtarm.model.parameters import JOINT_NAMES
from vgtarm.simulation.result import MODE_FIXED, MODE_GA, MODE_NOT_RUN, GAActivation, SimulationResult

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
N = 200
N_NAN = 5


def make_result(
    controller: str = "scm",
    *,
    external_force: bool = False,
    rates: str = "exact",
    ga: bool = True,
    nan_tail: bool = True,
    seed: int = 0,
) -> SimulationResult:
    """A run of N samples on a circle, a GA span at samples 40-59 and NaN trailing samples."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 2.0, N)
    angle = np.pi * t
    tip_desired = np.column_stack([0.05 * np.cos(angle), 0.05 * np.sin(angle), 0.6 + 0.01 * np.sin(2 * angle)])
    tip = tip_desired + 2e-4 * rng.standard_normal((N, 3))
    q_desired = 0.1 + 0.01 * np.sin(angle[:, None] + np.arange(7))
    q = q_desired + 1e-4 * rng.standard_normal((N, 7))
    effort = np.column_stack([50 * np.sin(angle + k) for k in range(6)] + [0.5 * np.cos(angle)])
    mode = np.full(N, MODE_FIXED, dtype=np.int8)
    activations: tuple[GAActivation, ...] = ()
    if ga:
        mode[40:60] = MODE_GA
        activations = (GAActivation(40, float(t[40]), 10, 200, 1e-4, 3e-4, 3e-4, 1e-4, 0.01),)
    arrays = dict(tip=tip, q=q, qd=np.zeros((N, 7)), effort=effort, f_ext=np.zeros((N, 3)))
    if nan_tail:
        mode[-N_NAN:] = MODE_NOT_RUN
        for value in arrays.values():
            value[-N_NAN:] = np.nan
    metadata = {"controller": controller, "external_force": external_force, "reference_rates": rates, "dt_s": t[1]}
    if controller == "scm":
        metadata["threshold_m"] = 2e-4
    return SimulationResult(
        t=t,
        tip_desired=tip_desired,
        tip=arrays["tip"],
        tip_error=np.linalg.norm(arrays["tip"] - tip_desired, axis=1),
        q_desired=q_desired,
        qd_desired=np.zeros((N, 7)),
        q=arrays["q"],
        qd=arrays["qd"],
        effort=arrays["effort"],
        f_ext=arrays["f_ext"],
        mode=mode,
        activations=activations,
        success=not nan_tail,
        message="synthetic",
        wall_time_s=1.0,
        ga_time_s=0.01 if ga else 0.0,
        metadata=metadata,
    )


@pytest.fixture(scope="module")
def scm() -> SimulationResult:
    return make_result("scm")


@pytest.fixture(scope="module")
def cfc() -> SimulationResult:
    return make_result("cfc", ga=False, nan_tail=False, seed=1)


@pytest.mark.parametrize(
    ("controller", "external_force", "rates", "expected"),
    [
        ("cfc", False, "exact", "CFC"),
        ("scm", False, "exact", "SCM"),
        ("cfc", True, "exact", "CFC + tool force"),
        ("cfc", False, "finite_difference", "CFC (FD rates)"),
        ("scm", True, "finite_difference", "SCM + tool force (FD rates)"),
    ],
)
def test_label_of(controller: str, external_force: bool, rates: str, expected: str) -> None:
    result = make_result(controller, external_force=external_force, rates=rates, ga=False, nan_tail=False)
    assert label_of(result) == expected


def test_path_3d_draws_desired_and_actual(scm: SimulationResult, cfc: SimulationResult) -> None:
    ax = plot_path_3d([cfc, scm])
    assert isinstance(ax, Axes3D)
    assert isinstance(ax.figure, Figure)
    labels = [line.get_label() for line in ax.get_lines()]
    assert labels.count("desired") == 1
    assert [label for label in labels if label.startswith("actual")] == ["actual, CFC", "actual, SCM"]
    assert ax.get_xlabel() == "x (mm)" and ax.get_ylabel() == "y (mm)" and ax.get_zlabel() == "z (mm)"
    assert ax.get_legend() is not None
    # Data in mm: the circle of radius 0.05 m spans about 100 mm in x.
    x_lo, x_hi = ax.get_xlim()
    assert 90 < x_hi - x_lo < 130
    # Planar-ish paths keep a visible depth.
    aspect = ax.get_box_aspect()
    assert aspect is not None and min(aspect) > 0.1 * max(aspect)


def test_path_3d_single_result_and_given_axes(scm: SimulationResult) -> None:
    ax = Figure().add_subplot(projection="3d")
    assert plot_path_3d(scm, labels=["mine"], ax=ax, title="Fig. 4") is ax
    assert "actual, mine" in [line.get_label() for line in ax.get_lines()]
    assert ax.get_title() == "Fig. 4"


def test_tip_error_one_line_per_run_plus_threshold(scm: SimulationResult, cfc: SimulationResult) -> None:
    ax = plot_tip_error([cfc, scm])
    assert isinstance(ax, Axes)
    lines = ax.get_lines()
    assert len(lines) == 3
    assert [line.get_label() for line in lines] == ["CFC", "SCM", "SCM threshold"]
    threshold = lines[-1]
    assert threshold.get_linestyle() == "--"
    assert np.allclose(threshold.get_ydata(), 0.2)  # 2e-4 m from the SCM run's metadata, in mm
    assert "mm" in ax.get_ylabel() and "s" in ax.get_xlabel()
    # In mm: the plotted data are the errors times 1000, NaN samples kept as gaps.
    y = np.asarray(lines[1].get_ydata(), dtype=float)
    assert np.allclose(y[:-N_NAN], scm.tip_error[:-N_NAN] * 1e3)
    assert np.isnan(y[-N_NAN:]).all()
    # The GA span of the SCM run is marked (one bar collection, labelled), the CFC run has none;
    # the bars sit in a strip below 0 mm, and no negative error is labelled on the axis.
    assert [c.get_label() for c in ax.collections] == ["GA gains, SCM"]
    assert ax.get_ylim()[0] < 0
    assert min(ax.get_yticks()) >= 0
    legend = ax.get_legend()
    assert legend is not None
    assert "SCM threshold" in [text.get_text() for text in legend.get_texts()]


def test_tip_error_explicit_threshold_log_and_no_threshold(cfc: SimulationResult) -> None:
    ax = plot_tip_error(cfc)
    assert len(ax.get_lines()) == 1  # CFC has no threshold in its metadata
    ax = plot_tip_error(cfc, threshold=4e-4, log=True, title="Fig. 8")
    assert ax.get_yscale() == "log"
    assert ax.get_ylim()[0] > 0
    assert np.allclose(ax.get_lines()[-1].get_ydata(), 0.4)
    assert ax.get_title() == "Fig. 8"


def test_tip_error_log_with_ga_strip(scm: SimulationResult) -> None:
    ax = plot_tip_error(scm, log=True)
    low, high = ax.get_ylim()
    assert 0 < low < np.nanmin(scm.tip_error) * 1e3 < high
    assert len(ax.collections) == 1


def test_efforts_forces_and_twin_torque(scm: SimulationResult) -> None:
    ax = plot_efforts(scm)
    assert isinstance(ax, Axes)
    assert [line.get_label() for line in ax.get_lines()] == [f"F_{name}" for name in JOINT_NAMES[:6]]
    assert ax.get_ylabel() == "leg force (N)"
    twins = [other for other in ax.figure.axes if other is not ax]
    assert len(twins) == 1
    assert len(twins[0].get_lines()) == 1
    assert "N m" in twins[0].get_ylabel()
    (shading,) = ax.collections  # the GA spans, one full-height bar each: samples 40-59
    (bar,) = shading.get_paths()
    np.testing.assert_allclose([bar.vertices[:, 0].min(), bar.vertices[:, 0].max()], scm.t[[40, 60]], rtol=1e-12)
    assert shading.get_transform().contains_branch_seperately(ax.transData) == (True, False)  # y: the axes' height


def test_efforts_subset_of_joints(cfc: SimulationResult) -> None:
    ax = plot_efforts(cfc, joints=["s1", "p2"])
    assert [line.get_label() for line in ax.get_lines()] == ["F_s1", "F_p2"]
    assert len(ax.figure.axes) == 1  # no twist, no twin axis
    assert not ax.collections and not ax.patches  # no GA span


def test_joint_errors_units(scm: SimulationResult) -> None:
    ax = plot_joint_errors(scm)
    assert isinstance(ax, Axes)
    assert len(ax.get_lines()) == 6
    assert "mm" in ax.get_ylabel()
    twin = next(other for other in ax.figure.axes if other is not ax)
    assert "mrad" in twin.get_ylabel()
    y = np.asarray(ax.get_lines()[0].get_ydata(), dtype=float)
    assert np.allclose(y[:-N_NAN], (scm.q_desired - scm.q)[:-N_NAN, 0] * 1e3)


@pytest.mark.parametrize(("n_runs", "n_effort_panels"), [(1, 1), (2, 2), (3, 1)])
def test_comparison_figure_panels(n_runs: int, n_effort_panels: int) -> None:
    runs = [make_result("cfc", ga=False, nan_tail=False), make_result("scm"), make_result("scm", external_force=True)]
    fig = comparison_figure(runs[:n_runs], title="case 1")
    assert isinstance(fig, Figure)
    assert sum(isinstance(ax, Axes3D) for ax in fig.axes) == 1
    titles = [ax.get_title() for ax in fig.axes]
    assert titles.count("Tip position error") == 1
    assert sum(title.startswith("Actuator efforts") for title in titles) == n_effort_panels
    assert fig.get_suptitle() == "case 1"


def test_save_figure_png(tmp_path: Path, cfc: SimulationResult) -> None:
    fig = plot_tip_error(cfc).figure
    assert isinstance(fig, Figure)
    out = save_figure(fig, tmp_path / "sub" / "error.png", dpi=50)
    assert out == tmp_path / "sub" / "error.png"
    data = out.read_bytes()
    assert data.startswith(PNG_SIGNATURE) and len(data) > 1000
    assert [p.name for p in out.parent.iterdir()] == ["error.png"]


@pytest.mark.parametrize("suffix", [".pdf", ".svg"])
def test_save_figure_other_formats(tmp_path: Path, cfc: SimulationResult, suffix: str) -> None:
    fig = plot_tip_error(cfc).figure
    assert isinstance(fig, Figure)
    out = save_figure(fig, tmp_path / f"error{suffix}")
    assert out.stat().st_size > 0
    assert list(tmp_path.iterdir()) == [out]


def test_save_figure_unknown_suffix_leaves_nothing(tmp_path: Path, cfc: SimulationResult) -> None:
    fig = plot_tip_error(cfc).figure
    assert isinstance(fig, Figure)
    with pytest.raises(InputError, match="suffix"):
        save_figure(fig, tmp_path / "error.xyz")
    assert list(tmp_path.iterdir()) == []


def test_save_figure_failure_removes_temp_and_keeps_old_file(
    tmp_path: Path, cfc: SimulationResult, monkeypatch: pytest.MonkeyPatch
) -> None:
    fig = plot_tip_error(cfc).figure
    assert isinstance(fig, Figure)
    target = tmp_path / "error.png"
    target.write_bytes(b"old")

    def broken_savefig(fname: str, **kwargs: object) -> None:
        Path(fname).write_bytes(b"partial")
        raise RuntimeError("disk full")

    monkeypatch.setattr(fig, "savefig", broken_savefig)
    with pytest.raises(RuntimeError, match="disk full"):
        save_figure(fig, target)
    assert list(tmp_path.iterdir()) == [target]
    assert target.read_bytes() == b"old"


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda r: plot_tip_error([]), "results is empty"),
        (lambda r: plot_path_3d([]), "results is empty"),
        (lambda r: comparison_figure([]), "results is empty"),
        (lambda r: plot_tip_error([r, "run"]), r"results\[1\]"),
        (lambda r: plot_tip_error(42), "results must be"),
        (lambda r: plot_tip_error([r, r], labels=["only one"]), "labels has 1 entries"),
        (lambda r: plot_path_3d(r, labels=["a", "b"]), "labels"),
        (lambda r: comparison_figure([r], labels="abc"), "labels"),
        (lambda r: plot_efforts("run"), "result must be"),
        (lambda r: plot_efforts(r, joints=["s9"]), "joints"),
        (lambda r: plot_joint_errors(None), "result must be"),
        (lambda r: label_of({"controller": "cfc"}), "result must be"),
        (lambda r: plot_path_3d(r, ax=Figure().add_subplot()), "ax must be a 3-D Axes"),
        (lambda r: plot_tip_error(r, ax="axes"), "ax must be"),
        (lambda r: plot_tip_error(r, threshold=-1.0), "threshold"),
        (lambda r: save_figure("figure", "out.png"), "fig must be"),
    ],
)
def test_bad_input_raises_input_error(scm: SimulationResult, call, match: str) -> None:
    with pytest.raises(InputError, match=match):
        call(scm)
