"""The mechanism drawn with Matplotlib: legs, platforms, twist axis, tool and frames, to scale.

:func:`draw_mechanism` draws one :class:`~vgtarm.app.geometry.MechanismGeometry` into a 3-D Axes
and returns the artists, which :meth:`MechanismArtists.update` moves to another configuration
(the animation uses that). :func:`pose_figure` makes the picture of ``vgtarm draw``: the plane of
module 1, the plane of module 2 and an isometric view side by side, legs coloured by how close
they are to their limits, with a colour bar. Coordinates are drawn in mm with equal scaling on
every axis; every bar's Line3D carries the segment's name as its ``gid``, so its drawn data can be
read back (the tests do).

Nothing here touches pyplot; the figures render headless with the Agg canvas.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Colormap, LinearSegmentedColormap, Normalize
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator
from mpl_toolkits.mplot3d.art3d import Line3D, Poly3DCollection
from mpl_toolkits.mplot3d.axes3d import Axes3D
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError
from ..model.parameters import JOINT_NAMES
from ..model.robot import Robot
from .geometry import MechanismGeometry, mechanism_geometry

#: Drawing unit: metres to millimetres.
MM = 1e3
#: Colours of the legs' closeness to a limit at 0, 0.5 and 1: green in mid-range, amber, red at a limit.
CLOSENESS_COLOURS = ("#1a9850", "#e8a200", "#d73027")
#: Colour map of the legs' closeness to a limit.
LEG_CMAP = LinearSegmentedColormap.from_list("vgtarm_closeness", CLOSENESS_COLOURS)
#: Colour scale of the closeness: 0 (mid-range) to 1 (at a limit).
CLOSENESS_NORM = Normalize(vmin=0.0, vmax=1.0)
#: Label of the colour bar.
CLOSENESS_LABEL = "closeness to a joint limit (0 mid-range, 1 at a limit)"
#: The three views of :func:`pose_figure`: title, (elevation, azimuth), axis seen end-on (hidden).
VIEWS: tuple[tuple[str, tuple[float, float], int | None], ...] = (
    ("module 1's plane (u2-u3 of F0)", (0.0, 0.0), 0),
    ("module 2's plane (u1-u3 of F1)", (0.0, -90.0), 1),
    ("isometric", (22.0, -52.0), None),
)
_STYLE: dict[str, dict[str, Any]] = {
    "base": {"color": "0.25", "linewidth": 4.0},
    "leg": {"linewidth": 3.2, "solid_capstyle": "round"},
    "platform": {"color": "0.15", "linewidth": 3.0},
    "twist_axis": {"color": "0.45", "linewidth": 0.9, "linestyle": (0, (4, 3))},
    "tool": {"color": "black", "linewidth": 2.6},
    "end_effector": {"linewidth": 3.0},
}
_PLATE_COLOURS = {"base": "0.55", "platform1": "tab:blue", "platform2": "tab:purple"}
_FRAME_COLOURS = ("tab:red", "tab:green", "tab:blue")


@dataclass
class MechanismArtists:
    """The artists of one drawn mechanism in ``ax``; :meth:`update` redraws them at a new pose.

    ``lines`` maps each segment's name to its Line3D (data in mm); ``plates`` each plate's name to
    its polygon; ``frames`` each frame's label to its three axis lines and its text; ``joints`` the
    scatter of the legs' joints.
    """

    ax: Axes3D
    cmap: Colormap
    lines: dict[str, Line3D] = field(default_factory=dict)
    plates: dict[str, Poly3DCollection] = field(default_factory=dict)
    frames: dict[str, tuple[list[Line3D], object]] = field(default_factory=dict)
    labels: dict[str, object] = field(default_factory=dict)
    joints: Any = None

    def update(self, geometry: MechanismGeometry) -> None:
        """Move every artist to ``geometry`` (same robot, another configuration)."""
        for seg in geometry.segments:
            line = self.lines[seg.name]
            xyz = np.stack([seg.start, seg.end]) * MM
            line.set_data_3d(xyz[:, 0], xyz[:, 1], xyz[:, 2])
            if seg.closeness is not None:
                line.set_color(self.cmap(CLOSENESS_NORM(seg.closeness)))
            if seg.name in self.labels:
                mid = 0.5 * (seg.start + seg.end) * MM
                self.labels[seg.name].set_position_3d(mid)  # type: ignore[attr-defined]
        for plate in geometry.plates:
            self.plates[plate.name].set_verts([plate.vertices * MM])
        if self.joints is not None:
            points = _joint_points(geometry) * MM
            self.joints._offsets3d = (points[:, 0], points[:, 1], points[:, 2])
        for frame in geometry.frames:
            axes_lines, text = self.frames[frame.label]
            for i, line in enumerate(axes_lines):
                end = frame.origin + geometry.axis_length * frame.rotation[:, i]
                xyz = np.stack([frame.origin, end]) * MM
                line.set_data_3d(xyz[:, 0], xyz[:, 1], xyz[:, 2])
            text.set_position_3d(frame.origin * MM)  # type: ignore[attr-defined]


def _joint_points(geometry: MechanismGeometry) -> NDArray[np.float64]:
    """The legs' end joints (k, 3) in m (platform centres and tip excluded)."""
    return np.stack([p for name, p in geometry.joints.items() if name not in ("O1", "O2", "P")])


def _cmap(cmap: str | Colormap) -> Colormap:
    from matplotlib import colormaps

    return colormaps[cmap] if isinstance(cmap, str) else cmap


def draw_mechanism(
    geometry: MechanismGeometry,
    ax: Axes3D | None = None,
    *,
    cmap: str | Colormap = LEG_CMAP,
    frames: bool = True,
    leg_labels: bool = True,
) -> MechanismArtists:
    """Draw ``geometry`` into the 3-D Axes ``ax`` (a new figure's when None), in mm.

    Returns the :class:`MechanismArtists` (``.ax`` is the Axes). Legs and the end-effector's bar
    are coloured by their joint's closeness to a limit with ``cmap``; ``frames`` draws F0..F3;
    ``leg_labels`` writes each leg's joint name at its middle.
    """
    if ax is None:
        ax = Figure(figsize=(6.0, 6.0), layout="constrained").add_subplot(projection="3d")
    colours = _cmap(cmap)
    artists = MechanismArtists(ax=ax, cmap=colours)
    for plate in geometry.plates:
        poly = Poly3DCollection(
            [plate.vertices * MM],
            facecolor=_PLATE_COLOURS.get(plate.name, "0.6"),
            edgecolor="none",
            alpha=0.28,
        )
        poly.set_gid(plate.name)
        ax.add_collection3d(poly)
        artists.plates[plate.name] = poly
    for seg in geometry.segments:
        style = dict(_STYLE[seg.kind])
        if seg.closeness is not None:
            style["color"] = colours(CLOSENESS_NORM(seg.closeness))
        xyz = np.stack([seg.start, seg.end]) * MM
        (line,) = ax.plot(xyz[:, 0], xyz[:, 1], xyz[:, 2], gid=seg.name, **style)
        artists.lines[seg.name] = line
        if leg_labels and seg.kind == "leg":
            mid = 0.5 * (seg.start + seg.end) * MM
            artists.labels[seg.name] = ax.text(*mid, f" {seg.name}", fontsize=7, color="0.1")
    joints = _joint_points(geometry) * MM
    artists.joints = ax.scatter(
        joints[:, 0], joints[:, 1], joints[:, 2], s=9, color="0.1", depthshade=False, gid="joints"
    )
    if frames:
        for frame in geometry.frames:
            axis_lines = []
            for i in range(3):
                end = frame.origin + geometry.axis_length * frame.rotation[:, i]
                xyz = np.stack([frame.origin, end]) * MM
                (line,) = ax.plot(
                    xyz[:, 0],
                    xyz[:, 1],
                    xyz[:, 2],
                    color=_FRAME_COLOURS[i],
                    linewidth=1.2,
                    gid=f"{frame.label}.u{i + 1}",
                )
                axis_lines.append(line)
            text = ax.text(*(frame.origin * MM), f"  {frame.label}", fontsize=7, color="0.3")
            artists.frames[frame.label] = (axis_lines, text)
    return artists


def set_equal_extent(
    ax: Axes3D, points: ArrayLike, *, pad: float = 0.06, hidden: int | None = None, zoom: float = 1.0
) -> None:
    """Limits that hold ``points`` (k, 3) in drawing units with one scale on every axis.

    The box's sides are proportional to the data's ranges (true proportions); ``hidden`` is the
    axis seen end-on in a plane view, whose ticks are dropped.
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    span = float((hi - lo).max())
    margin = pad * span
    lo, hi = lo - margin, hi + margin
    ranges = np.maximum(hi - lo, 0.05 * span)
    centre = 0.5 * (lo + hi)
    lo, hi = centre - ranges / 2, centre + ranges / 2
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(tuple(ranges), zoom=zoom)
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MaxNLocator(5))
    if hidden is not None:
        [ax.set_xticks, ax.set_yticks, ax.set_zticks][hidden]([])
        [ax.set_xlabel, ax.set_ylabel, ax.set_zlabel][hidden]("")


def label_axes(ax: Axes3D) -> None:
    """Axis labels in mm."""
    ax.set_xlabel("x (mm)", fontsize=8)
    ax.set_ylabel("y (mm)", fontsize=8)
    ax.set_zlabel("z (mm)", fontsize=8)
    ax.tick_params(labelsize=7)


def pose_figure(
    robot: Robot,
    q: ArrayLike,
    *,
    title: str | None = None,
    cmap: str | Colormap = LEG_CMAP,
    views: Sequence[tuple[str, tuple[float, float], int | None]] = VIEWS,
    figsize: tuple[float, float] = (11.0, 5.6),
    dpi: float = 100.0,
) -> Figure:
    """The robot at ``q`` (n,) seen in each of ``views`` (default: both operating planes and an
    isometric view), legs coloured by closeness to their limits, with a colour bar."""
    qa = np.asarray(q, dtype=float)
    n = len(robot.parameters.home)
    if qa.shape != (n,):
        raise InputError(f"q must hold {n} joint values {list(JOINT_NAMES)}, got shape {qa.shape}")
    geometry = mechanism_geometry(robot, qa)
    fig = Figure(figsize=figsize, dpi=dpi, layout="constrained")
    axes = []
    for i, (name, (elev, azim), hidden) in enumerate(views):
        ax = fig.add_subplot(1, len(views), i + 1, projection="3d")
        ax.set_proj_type("ortho")
        draw_mechanism(geometry, ax, cmap=cmap, leg_labels=hidden is None)
        ax.view_init(elev=elev, azim=azim)
        label_axes(ax)
        set_equal_extent(ax, geometry.points() * MM, hidden=hidden, zoom=1.0 if hidden is None else 1.3)
        ax.set_title(name, fontsize=10)
        axes.append(ax)
    fig.colorbar(
        ScalarMappable(norm=CLOSENESS_NORM, cmap=_cmap(cmap)),
        ax=axes,
        shrink=0.6,
        label=CLOSENESS_LABEL,
        location="right",
    )
    values = ", ".join(f"{name} = {value:.4g}" for name, value in zip(JOINT_NAMES, qa, strict=True))
    tip = geometry.tip * MM
    fig.suptitle(
        title or f"{robot.parameters.name}\n{values} (m, rad); tip ({tip[0]:.1f}, {tip[1]:.1f}, {tip[2]:.1f}) mm",
        fontsize=10,
    )
    return fig
