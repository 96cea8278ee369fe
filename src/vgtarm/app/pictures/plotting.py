"""Figures of closed-loop runs, like the paper's Figs. 4-9.

Every function draws into an Axes passed as ``ax`` (or into a new :class:`~matplotlib.figure.Figure`
when ``ax`` is None) and returns it; nothing here touches pyplot's global state or calls
``show()``, so the module works headless without choosing a backend. Lengths are plotted in mm,
angles in mrad, forces in N and torques in N m; the result records stay in SI units.

Joint plots draw one line per joint of the run's robot, named by :attr:`SimulationResult.joint_names`
(the paper's ``s1 .. psi3``, or a stack's ``s1, v1, p1, ..., psi7``): legs (lengths, forces) on
the left axis, twist joints (angles, torques) on a twin axis on the right.

- :func:`plot_path_3d`: desired and actual tip paths in 3-D (Figs. 4 and 7).
- :func:`plot_tip_error`: tip position error against time for compared runs (Figs. 5 and 8).
- :func:`plot_efforts`: leg forces and twist torques of one run (Figs. 6 and 9).
- :func:`plot_joint_errors`: joint tracking errors ``q_d - q`` of one run.
- :func:`plot_efforts_by_module`: the efforts of one run, one panel per module (and the twists).
- :func:`comparison_figure`: the three views above in one figure (a run's ``figure.png``).
- :func:`save_figure`: write a figure atomically, format from the suffix.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib import colormaps
from matplotlib.axes import Axes
from matplotlib.colors import to_hex
from matplotlib.figure import Figure
from matplotlib.patches import Patch
from matplotlib.ticker import MaxNLocator
from mpl_toolkits.mplot3d.axes3d import Axes3D
from numpy.typing import NDArray

from ... import checks
from ...errors import InputError
from ...fileio import atomic_path
from ...markup import mpl_text
from ...simulation.result import MODE_GA, SimulationResult

__all__ = [
    "comparison_figure",
    "label_of",
    "plot_efforts",
    "plot_efforts_by_module",
    "plot_joint_errors",
    "plot_path_3d",
    "plot_tip_error",
    "save_figure",
]

#: Metres to millimetres, radians to milliradians.
_MILLI = 1e3
#: Beginning of a twist joint's name (an angle in rad, its effort a torque in N m); the others are legs.
TWIST_PREFIX = "psi"
#: Line styles of the twist joints on the right axis, in order (black lines).
_TWIST_STYLES = ("--", ":", "-.", (0, (5, 1, 1, 1, 1, 1)), (0, (8, 2)))
#: Colours of the leg lines when there are more than Matplotlib's default cycle holds (10).
_MANY_LEGS_CMAP = "tab20"
#: Smallest 3-D box side, as a fraction of the largest, so planar paths keep some depth.
_MIN_BOX_FRACTION = 0.15
#: Fill colour of spans in GA mode.
_GA_COLOR = "tab:orange"
#: Default size of a new figure of one panel (inches).
_PANEL_SIZE = (7.0, 4.0)


#: Largest ratio of the largest to the smallest positive error shown on a linear axis: errors
#: that span more (two decades) get a logarithmic axis.
DECADES_RATIO = 100.0


def spans_decades(values: Sequence[Any], ratio: float = DECADES_RATIO) -> bool:
    """Whether the positive finite numbers among ``values`` (arrays of any shape) span more than
    ``ratio`` from the smallest to the largest: then an axis of them is logarithmic."""
    parts = [np.asarray(v, dtype=float).ravel() for v in values]
    flat = np.concatenate(parts) if parts else np.zeros(0)
    positive = flat[np.isfinite(flat) & (flat > 0)]
    return bool(positive.size) and float(positive.max()) > ratio * float(positive.min())


def joint_groups(names: Sequence[str]) -> list[tuple[str, list[int]]]:
    """The joints of a robot grouped for one panel each: the legs of each module (``s2, v2, p2``:
    ``module 2``, in N), then the twist joints together (``psi...``, in N m); returns
    ``(title, joint indices)`` in order. A name without a module number is a group of its own."""
    legs: dict[str, list[int]] = {}
    twists: list[int] = []
    for j, name in enumerate(names):
        if _is_twist(name):
            twists.append(j)
            continue
        digits = name.lstrip("abcdefghijklmnopqrstuvwxyz_")
        key = f"module {digits}" if digits.isdigit() else name
        legs.setdefault(key, []).append(j)
    groups = list(legs.items())
    if twists:
        groups.append(("twist" if len(twists) == 1 else "twists", twists))
    return groups


def label_of(result: SimulationResult) -> str:
    """Short legend label of a run from its metadata.

    The controller name upper-cased (``"CFC"``, ``"SCM"``), then ``" + tool force"`` when
    ``metadata["external_force"]`` is true and ``" (FD rates)"`` when the reference rates were
    obtained by finite differences, e.g. ``"CFC + tool force (FD rates)"``. The controller's name
    comes from the run's file: a ``$`` in it shows as written (:func:`vgtarm.markup.mpl_text`).
    """
    _check_result(result, "result")
    meta = result.metadata
    label = mpl_text(str(meta.get("controller", "run")).upper())
    if meta.get("external_force"):
        label += " + tool force"
    if meta.get("reference_rates") == "finite_difference":
        label += " (FD rates)"
    return label


def plot_path_3d(
    results: SimulationResult | Sequence[SimulationResult],
    *,
    labels: Sequence[str] | None = None,
    ax: Axes3D | None = None,
    title: str | None = None,
) -> Axes3D:
    """Desired tip path (of the first run) and the actual tip path of each run, in 3-D.

    Args:
        results: one run or a sequence of runs; ``tip_desired`` and ``tip`` are (N, 3) m.
        labels: one legend label per run (default: :func:`label_of`).
        ax: a 3-D Axes to draw into (``projection="3d"``); a new figure when None.
        title: Axes title (default: "Tip path").

    Returns:
        The 3-D Axes; coordinates in mm, box aspect from the data ranges so that a millimetre
        has about the same length along each axis. NaN samples (runs that stopped early) are
        left out of the lines.
    """
    runs, names = _runs_and_labels(results, labels)
    if ax is None:
        ax = Figure(figsize=(6.5, 5.5), layout="constrained").add_subplot(projection="3d")
    elif not isinstance(ax, Axes3D):
        raise InputError(f"ax must be a 3-D Axes (projection='3d'), got {type(ax).__name__}")
    desired = runs[0].tip_desired * _MILLI
    ax.plot(desired[:, 0], desired[:, 1], desired[:, 2], "k--", lw=1.2, label="desired")
    points = [desired]
    for run, name in zip(runs, names, strict=True):
        tip = run.tip * _MILLI
        ax.plot(tip[:, 0], tip[:, 1], tip[:, 2], lw=1.2, label=f"actual, {name}")
        points.append(tip)
    ax.plot(*desired[0], "ko", ms=4, label="start")
    stacked = np.concatenate(points)
    stacked = stacked[np.isfinite(stacked).all(axis=1)]
    if len(stacked):
        lo, hi = stacked.min(axis=0), stacked.max(axis=0)
        span = hi - lo
        side = max(float(span.max()), 1e-6)
        half = np.maximum(span, _MIN_BOX_FRACTION * side) / 2
        mid = (lo + hi) / 2
        ax.set_xlim(mid[0] - half[0], mid[0] + half[0])
        ax.set_ylim(mid[1] - half[1], mid[1] + half[1])
        ax.set_zlim(mid[2] - half[2], mid[2] + half[2])
        ax.set_box_aspect(tuple(2 * half), zoom=1.1)
        # fewer ticks on a short side of the box, so its labels do not run into each other
        bins = [max(2, min(5, round(5 * h / float(half.max())))) for h in half]
    else:
        bins = [5, 5, 5]
    for axis, n in zip((ax.xaxis, ax.yaxis, ax.zaxis), bins, strict=True):
        axis.set_major_locator(MaxNLocator(nbins=n, steps=[1, 2, 2.5, 5, 10]))
    ax.set_xlabel("x (mm)", labelpad=16)
    ax.set_ylabel("y (mm)", labelpad=10)
    ax.set_zlabel("z (mm)", labelpad=10)
    ax.set_title(title if title is not None else "Tip path")
    ax.legend(loc="upper left", fontsize="small")
    return ax


def plot_tip_error(
    results: SimulationResult | Sequence[SimulationResult],
    *,
    labels: Sequence[str] | None = None,
    ax: Axes | None = None,
    threshold: float | None = None,
    log: bool = False,
    title: str | None = None,
) -> Axes:
    """Absolute tip position error ``|P(q_d) - P(q)|`` (mm) against time (s) of compared runs.

    Args:
        results: one run or a sequence of runs; ``t`` (N,) s, ``tip_error`` (N,) m.
        labels: one legend label per run (default: :func:`label_of`).
        ax: Axes to draw into; a new figure when None.
        threshold: SCM error threshold (m), drawn as a dashed horizontal line. None takes
            ``metadata["threshold_m"]`` of the first run that has one; no line if none has.
        log: logarithmic error axis (non-positive errors are left out).
        title: Axes title (default: "Tip position error").

    Returns:
        The Axes, with one line per run and the threshold line. The spans in GA mode
        (``mode == 1``) of each run are marked by a bar in the run's colour in a grey strip
        below the error axis. NaN samples (runs that stopped early) are left out.
    """
    runs, names = _runs_and_labels(results, labels)
    ax = _new_axes(ax)
    if threshold is None:
        threshold = next((r.metadata["threshold_m"] for r in runs if r.metadata.get("threshold_m") is not None), None)
    if threshold is not None:
        value = _as_float(threshold)
        if value is None or not (np.isfinite(value) and value > 0):
            raise InputError(f"threshold = {threshold!r}: expected a positive tip error (m)")
        threshold = value
    bars: list[tuple[str, list[tuple[float, float]], str]] = []
    for run, name in zip(runs, names, strict=True):
        error = run.tip_error * _MILLI
        if log:
            error = np.where(error > 0, error, np.nan)
        (line,) = ax.plot(run.t, error, lw=1.2, label=name)
        spans = _spans(run.t, run.mode == MODE_GA)
        if spans:
            bars.append((to_hex(line.get_color()), spans, name))
    if threshold is not None:
        ax.axhline(threshold * _MILLI, color="k", ls="--", lw=1.0, label="SCM threshold")
    if log:
        ax.set_yscale("log")
    else:
        ax.set_ylim(bottom=0)
    if bars:
        _ga_strip(ax, bars, log)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("tip error |P(q_d) − P(q)| (mm)")
    ax.set_title(title if title is not None else "Tip position error")
    ax.grid(True, alpha=0.3)
    _legend_above(ax)
    return ax


def plot_efforts(
    result: SimulationResult,
    *,
    ax: Axes | None = None,
    title: str | None = None,
    joints: Sequence[str] | None = None,
) -> Axes:
    """Leg actuator forces (N) and twist torques (N m, right axis) of one run against time (s).

    Args:
        result: the run; ``effort`` (N, n): one column per joint of :attr:`~SimulationResult.joint_names`,
            legs in N, twist joints (``psi...``) in N m.
        ax: Axes to draw into (the force axis); a new figure when None.
        title: Axes title (default: "Actuator efforts, <label>").
        joints: names of the run's joints to draw (default: all); the twist torques get a twin
            y-axis on the right when a twist joint is among them.

    Returns:
        The primary (force) Axes, with one line per leg joint named ``F_<joint>``; spans in GA
        mode (``mode == 1``) are shaded.
    """
    _check_result(result, "result")
    names = result.joint_names
    chosen = _joint_indices(joints, names)
    legs = [j for j in chosen if not _is_twist(names[j])]
    twists = [j for j in chosen if _is_twist(names[j])]
    ax = _new_axes(ax)
    handles: list[Any] = []
    for j, colour in zip(legs, _leg_colours(len(legs)), strict=True):
        handles += ax.plot(result.t, result.effort[:, j], lw=1.0, color=colour, label=f"F_{names[j]}")
    if twists:
        twin = ax.twinx()
        for j, style in zip(twists, _twist_styles(len(twists)), strict=True):
            handles += twin.plot(
                result.t, result.effort[:, j], color="k", ls=style, lw=1.0, label=f"τ_{names[j]} (right)"
            )
        only = names[twists[0]]
        twin.set_ylabel(f"twist torque τ_{only} (N m)" if len(twists) == 1 else "twist torques (N m)")
    handles += _peak_lines(ax, result, legs)
    if _shade_ga(ax, result):
        handles.append(Patch(color=_GA_COLOR, alpha=0.2, label="GA gains"))
    ax.set_xlabel("time (s)")
    ax.set_ylabel("leg force (N)" if legs else "")
    ax.set_title(title if title is not None else f"Actuator efforts, {label_of(result)}")
    ax.grid(True, alpha=0.3)
    _legend_above(ax, handles)
    return ax


def _peak_lines(ax: Axes, result: SimulationResult, joints: Sequence[int]) -> list[Any]:
    """Dashed lines at +-the peak force of the run's actuators on ``joints`` (one pair per distinct
    value; none for a run without actuators or whose robot is unknown); their handles for a legend.
    The force-speed line, where it holds, lowers the limit in the direction of motion below these."""
    actuators = None if result.robot is None else result.robot.actuators
    if actuators is None:
        return []
    peaks = sorted({float(actuators.force[j]) for j in joints if np.isfinite(actuators.force[j])})
    handles: list[Any] = []
    for peak in peaks:
        for sign in (1.0, -1.0):
            line = ax.axhline(sign * peak, color="0.45", ls="--", lw=0.8, label=f"actuator peak ±{peak:g}")
        handles.append(line)
    return handles


def plot_joint_errors(result: SimulationResult, *, ax: Axes | None = None, title: str | None = None) -> Axes:
    """Joint tracking errors ``q_d - q`` of one run against time (s).

    The legs in mm on the left axis, the twist joints (``psi...``) in mrad on a twin axis on the
    right (black lines, dashed for the first); spans in GA mode are shaded.

    Args:
        result: the run; ``q_desired`` and ``q`` (N, n), legs in m, twists in rad, one column
            per joint of :attr:`~SimulationResult.joint_names`.
        ax: Axes to draw into (the leg axis); a new figure when None.
        title: Axes title (default: "Joint tracking errors, <label>").

    Returns:
        The primary (leg) Axes, with one line per leg named by its joint.
    """
    _check_result(result, "result")
    ax = _new_axes(ax)
    names = result.joint_names
    error = (result.q_desired - result.q) * _MILLI
    legs = [j for j, name in enumerate(names) if not _is_twist(name)]
    twists = [j for j, name in enumerate(names) if _is_twist(name)]
    handles: list[Any] = []
    for j, colour in zip(legs, _leg_colours(len(legs)), strict=True):
        handles += ax.plot(result.t, error[:, j], lw=1.0, color=colour, label=names[j])
    if twists:
        twin = ax.twinx()
        for j, style in zip(twists, _twist_styles(len(twists)), strict=True):
            handles += twin.plot(result.t, error[:, j], color="k", ls=style, lw=1.0, label=f"{names[j]} (right)")
        only = names[twists[0]]
        twin.set_ylabel(f"twist error {only}_d − {only} (mrad)" if len(twists) == 1 else "twist errors q_d − q (mrad)")
    if _shade_ga(ax, result):
        handles.append(Patch(color=_GA_COLOR, alpha=0.2, label="GA gains"))
    ax.set_xlabel("time (s)")
    ax.set_ylabel("leg error q_d − q (mm)")
    ax.set_title(title if title is not None else f"Joint tracking errors, {label_of(result)}")
    ax.grid(True, alpha=0.3)
    _legend_above(ax, handles)
    return ax


def plot_efforts_by_module(
    result: SimulationResult, cell: Any, *, title: str | None = None, sharex: Axes | None = None
) -> list[Axes]:
    """Actuator efforts of one run in one panel per group of :func:`joint_groups` (each module's
    legs in N, the twists in N m), stacked in the grid cell ``cell`` (a ``SubplotSpec``) of its
    figure, sharing the time axis (labelled on the bottom panel only); each panel's legend names
    its joints at its right; spans in GA mode are shaded. Returns the panels' Axes, top first."""
    _check_result(result, "result")
    names = result.joint_names
    groups = joint_groups(names)
    figure = cell.get_gridspec().figure
    grid = cell.subgridspec(len(groups), 1, hspace=0.08)
    axes: list[Axes] = []
    for g, (group, joints) in enumerate(groups):
        ax = figure.add_subplot(grid[g, 0], sharex=sharex if sharex is not None else (axes[0] if axes else None))
        unit = "N m" if _is_twist(names[joints[0]]) else "N"
        for j, colour in zip(joints, _leg_colours(len(joints)), strict=True):
            ax.plot(result.t, result.effort[:, j], lw=1.0, color=colour, label=mpl_text(names[j]))
        _peak_lines(ax, result, joints)
        shaded = _shade_ga(ax, result)
        handles, _ = ax.get_legend_handles_labels()
        if shaded and g == 0:
            handles.append(Patch(color=_GA_COLOR, alpha=0.2, label="GA gains"))
        ax.legend(handles=handles, loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize="small", frameon=False)
        ax.set_ylabel(f"{group} ({unit})", fontsize="small")
        ax.yaxis.set_major_locator(MaxNLocator(nbins=4))
        ax.tick_params(labelsize="small")
        ax.grid(True, alpha=0.3)
        if g < len(groups) - 1:
            ax.tick_params(labelbottom=False)
        axes.append(ax)
    axes[-1].set_xlabel("time (s)")
    axes[0].set_title(title if title is not None else f"Actuator efforts, {label_of(result)}")
    return axes


def comparison_figure(
    results: SimulationResult | Sequence[SimulationResult],
    *,
    labels: Sequence[str] | None = None,
    title: str | None = None,
) -> Figure:
    """One figure comparing runs: 3-D tip paths, tip errors and actuator efforts.

    Top row: the 3-D tip paths (left) and the tip errors of all runs (right; a logarithmic axis
    when the errors span more than two decades, :func:`spans_decades`). Below: the actuator
    efforts of each run side by side when there are two runs, else the efforts of the last run
    across the full width, one panel per module and one for the twists
    (:func:`plot_efforts_by_module`), so a many-module arm reads as well as the paper's.

    Args:
        results: one run or a sequence of runs.
        labels: one legend label per run (default: :func:`label_of`).
        title: figure title (default: none).

    Returns:
        The Figure (constrained layout, 14 in wide, taller with more modules); no two of its texts
        overlap.
    """
    runs, names = _runs_and_labels(results, labels)
    shown = list(zip(runs, names, strict=True)) if len(runs) == 2 else [(runs[-1], names[-1])]
    groups = len(joint_groups(shown[0][0].joint_names))
    panel = 1.25  # inches per effort panel
    fig = Figure(figsize=(14.0, 5.6 + panel * groups + 0.8), layout="constrained")
    grid = fig.add_gridspec(2, len(shown) if len(shown) == 2 else 1, height_ratios=(5.6, panel * groups + 0.8))
    # an empty column between the 3-D view and the errors: the 3-D axis labels reach past their box
    top = grid[0, :].subgridspec(1, 3, width_ratios=(1.0, 0.08, 1.1))
    plot_path_3d(runs, labels=names, ax=fig.add_subplot(top[0, 0], projection="3d"))
    log = spans_decades([run.tip_error for run in runs])
    plot_tip_error(runs, labels=names, ax=fig.add_subplot(top[0, 2]), log=log)
    first: Axes | None = None
    for column, (run, name) in enumerate(shown):
        panels = plot_efforts_by_module(run, grid[1, column], title=f"Actuator efforts, {name}", sharex=first)
        first = first or panels[0]
    if title is not None:
        fig.suptitle(title, fontsize="x-large")
    return fig


def save_figure(fig: Figure, path: str | os.PathLike[str], *, dpi: float = 150) -> Path:
    """Write ``fig`` to ``path`` atomically; the format (png, pdf, svg, ...) comes from the suffix.

    The figure is saved to a temporary file in the same folder and renamed into place, so
    ``path`` is either the complete new file or untouched; the temporary file is removed on
    error. The folder is created if needed.

    Returns:
        ``path`` as a :class:`~pathlib.Path`.
    """
    if not isinstance(fig, Figure):
        raise InputError(f"fig must be a matplotlib Figure, got {type(fig).__name__}")
    out = Path(path)
    fmt = out.suffix.lower().lstrip(".")
    supported = sorted(fig.canvas.get_supported_filetypes())
    if fmt not in supported:
        raise InputError(f"path = {str(out)!r}: unknown image suffix {out.suffix!r}, expected one of {supported}")
    checks.positive("dpi", dpi)
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out) as temporary:
        fig.savefig(temporary, dpi=dpi, format=fmt)
    return out


def _check_result(result: object, name: str) -> None:
    if not isinstance(result, SimulationResult):
        raise InputError(f"{name} must be a SimulationResult, got {type(result).__name__}")


def _runs_and_labels(
    results: SimulationResult | Sequence[SimulationResult], labels: Sequence[str] | None
) -> tuple[list[SimulationResult], list[str]]:
    """Validate ``results`` (one run or a non-empty sequence) and ``labels`` (one per run)."""
    if isinstance(results, SimulationResult):
        runs = [results]
    elif isinstance(results, Sequence) and not isinstance(results, str):
        runs = list(results)
    else:
        raise InputError(f"results must be a SimulationResult or a sequence of them, got {type(results).__name__}")
    if not runs:
        raise InputError("results is empty: expected at least one SimulationResult")
    for i, run in enumerate(runs):
        _check_result(run, f"results[{i}]")
    if labels is None:
        return runs, [label_of(run) for run in runs]
    if isinstance(labels, str) or not isinstance(labels, Sequence):
        raise InputError(f"labels must be a sequence of strings, got {type(labels).__name__}")
    if len(labels) != len(runs):
        raise InputError(f"labels has {len(labels)} entries, expected one per run ({len(runs)})")
    return runs, [str(label) for label in labels]


def _is_twist(name: str) -> bool:
    """Whether the joint ``name`` is a twist (an angle), not a leg (a length)."""
    return name.startswith(TWIST_PREFIX)


def _leg_colours(n: int) -> list[Any]:
    """Colours of ``n`` leg lines: Matplotlib's default cycle, or ``tab20`` for more than it holds."""
    if n <= 10:
        return [f"C{i}" for i in range(n)]
    cmap = colormaps[_MANY_LEGS_CMAP]
    return [cmap(i % cmap.N) for i in range(n)]


def _twist_styles(n: int) -> list[Any]:
    return [_TWIST_STYLES[i % len(_TWIST_STYLES)] for i in range(n)]


def _joint_indices(joints: Sequence[str] | None, names: Sequence[str]) -> list[int]:
    if joints is None:
        return list(range(len(names)))
    if isinstance(joints, str) or not isinstance(joints, Sequence) or not joints:
        raise InputError(f"joints = {joints!r}: expected a non-empty sequence of names from {list(names)}")
    unknown = [j for j in joints if j not in names]
    if unknown:
        raise InputError(f"joints = {list(joints)!r}: unknown {unknown}, expected names from {list(names)}")
    return sorted({list(names).index(j) for j in joints})


def _new_axes(ax: Axes | None) -> Axes:
    if ax is None:
        return Figure(figsize=_PANEL_SIZE, layout="constrained").add_subplot()
    if not isinstance(ax, Axes):
        raise InputError(f"ax must be a matplotlib Axes or None, got {type(ax).__name__}")
    return ax


def _as_float(value: object) -> float | None:
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return None


def _spans(t: NDArray[np.float64], mask: NDArray[np.bool_]) -> list[tuple[float, float]]:
    """``(start, width)`` in s of each run of consecutive true samples of ``mask``.

    A sample stands for the interval up to the next sample (the last one for one period).
    """
    if len(t) == 0 or not mask.any():
        return []
    step = float(t[1] - t[0]) if len(t) > 1 else 0.0
    edges = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    starts = np.flatnonzero(edges == 1)
    stops = np.flatnonzero(edges == -1)
    ends = [float(t[k]) if k < len(t) else float(t[-1]) + step for k in stops]
    return [(float(t[a]), e - float(t[a])) for a, e in zip(starts, ends, strict=True)]


def _legend_above(ax: Axes, handles: list[Any] | None = None) -> None:
    """A legend in rows of at most 5 entries between the plot area and the title, clear of the data."""
    if handles is None:
        handles, _ = ax.get_legend_handles_labels()
    if not handles:
        return
    rows = -(-len(handles) // 5)
    legend = ax.legend(
        handles=handles,
        loc="lower center",
        bbox_to_anchor=(0.5, 1.0),
        ncol=-(-len(handles) // rows),
        fontsize="small",
        frameon=False,
        handlelength=1.6,
        columnspacing=1.2,
    )
    # Lift the title above the legend: rows of 1.5 font sizes, plus the border and a gap.
    size = float(legend.get_texts()[0].get_fontsize())
    ax.set_title(ax.get_title(), pad=rows * 1.5 * size + 0.8 * size + 4.0)


def _ga_strip(ax: Axes, bars: list[tuple[str, list[tuple[float, float]], str]], log: bool) -> None:
    """Mark GA spans by bars (one row per run) in a grey strip added below the error axis.

    The strip lies below 0 mm (below the lowest error on a log axis), so the bars never hide
    an error curve or the threshold line; negative tick labels are dropped.
    """
    row = 0.03
    fraction = len(bars) * row + 0.01
    lo, hi = ax.get_ylim()
    if log:
        lo_t, hi_t = np.log10(lo), np.log10(hi)
        bottom = 10 ** (lo_t - fraction / (1 - fraction) * (hi_t - lo_t))
    else:
        bottom = lo - fraction / (1 - fraction) * (hi - lo)
        ax.set_yticks([v for v in ax.get_yticks() if lo <= v <= hi])
    ax.set_ylim(bottom, hi)
    ax.axhspan(bottom, lo, facecolor="0.92", edgecolor="none", zorder=0)
    for i, (color, spans, name) in enumerate(bars):
        ax.broken_barh(
            spans,
            (fraction - (i + 1) * row, row - 0.008),
            transform=ax.get_xaxis_transform(),
            facecolors=color,
            edgecolors=color,
            linewidth=0.8,
            alpha=0.7,
            label=f"GA gains, {name}",
        )


def _shade_ga(ax: Axes, result: SimulationResult) -> bool:
    """Shade the spans of ``result`` in GA mode on ``ax``; whether there were any."""
    spans = _spans(result.t, result.mode == MODE_GA)
    if spans:  # one collection of full-height bars (thousands of activations make hundreds of spans)
        ax.broken_barh(
            spans,
            (0.0, 1.0),
            transform=ax.get_xaxis_transform(),
            facecolors=_GA_COLOR,
            edgecolors=_GA_COLOR,
            alpha=0.2,
            linewidth=0.6,
            zorder=0,
        )
    return bool(spans)
