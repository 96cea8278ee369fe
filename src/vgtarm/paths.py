"""Desired tip paths sampled at a fixed period.

A :class:`TipPath` holds the desired tip position, velocity and acceleration in the base frame at
uniformly spaced times ``t_k = t0 + k*dt``. It is built by one of the constructors below:

- :func:`case1` -- the closed curve of the paper's first case study (eq. 22);
- :func:`case2` -- the two straight lines of the second case study (eq. 23);
- :func:`waypoints` -- timed waypoints joined by rest-to-rest cubics, quintics or a C2 spline;
- :func:`from_samples` / :func:`from_csv` -- sampled positions, fitted with a C2 spline.

Velocities and accelerations are always exact derivatives of the position model (analytic for
the closed-form paths, the spline's own derivatives for fitted data), never finite differences.
Units are SI throughout: seconds, metres, m/s, m/s^2.
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline

from . import checks
from .errors import PathError, cut, refuse_masked, shown
from .fileio import read_text_limited
from .kinds import found_columns

FloatArray = NDArray[np.float64]

_CSV_COLUMNS = ("t", "x", "y", "z")
_COUNT_TOLERANCE = 1e-9
"""Slack, in units of ``dt``, when counting how many samples fit in a duration."""
_UNIFORM_RTOL = 1e-9
"""Relative tolerance, on ``dt``, for sample times to count as uniformly spaced."""
MIN_DT = 1e-6
"""Shortest sampling period and shortest time between given samples, s (a megahertz: far faster
than any controller; shorter spacings only turn rounding into huge rates)."""
MAX_SAMPLES = 10_000_000
"""Most samples a path may have (80 MB per coordinate array; about 2.8 h at 1 ms)."""
MAX_COORDINATE = 1e3
"""Largest magnitude of a given position coordinate, m (the arm reaches less than a metre)."""
MAX_TIME = 1e12
"""Largest magnitude of a given sample time, s."""
CSV_FILE_LIMIT = 64 * 2**20
"""Largest path CSV file read, bytes (about 1.5 million rows)."""


@dataclass(frozen=True, eq=False)
class TipPath:
    """A desired tip path sampled at a fixed period.

    Attributes:
        name: Label of the path (e.g. ``"case1"``).
        t: Sample times, shape ``(N,)``, s; uniform, ``t_k = t0 + k*dt``, ``N >= 2``.
        position: Tip position in the base frame, shape ``(N, 3)``, m.
        velocity: Tip velocity, shape ``(N, 3)``, m/s.
        acceleration: Tip acceleration, shape ``(N, 3)``, m/s^2.
        jerk: Tip jerk, shape ``(N, 3)``, m/s^3, or None when unknown. Every constructor below
            gives it (the exact third derivative); it is needed only by the exact rates of the
            inverse kinematics' effort criterion, whose expected tool force follows the velocity.

    The arrays are copied to float64 on construction and made read-only. Invalid shapes,
    non-finite values or non-uniform times raise :class:`~vgtarm.errors.PathError`.
    """

    name: str
    t: FloatArray
    position: FloatArray
    velocity: FloatArray
    acceleration: FloatArray
    jerk: FloatArray | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str):
            raise PathError(f"name must be a str, got {type(self.name).__name__}")
        t = _frozen_array("t", self.t)
        if t.ndim != 1 or t.shape[0] < 2:
            raise PathError(f"t must have shape (N,) with N >= 2, got shape {t.shape}")
        checks.finite_array("t", t, error=PathError)
        n = t.shape[0]
        for field in ("position", "velocity", "acceleration", "jerk"):
            if field == "jerk" and self.jerk is None:
                continue
            values = _frozen_array(field, getattr(self, field))
            if values.shape != (n, 3):
                raise PathError(f"{field} must have shape ({n}, 3) to match t, got shape {values.shape}")
            checks.finite_array(field, values, error=PathError)
            object.__setattr__(self, field, values)
        step = (t[-1] - t[0]) / (n - 1)
        if not step > 0.0:
            raise PathError(f"t must be strictly increasing, got t[0]={float(t[0])!r}, t[-1]={float(t[-1])!r}")
        if not step >= MIN_DT:
            raise PathError(f"t must be spaced by at least {MIN_DT:g} s, got dt={float(step)!r}")
        deviation = np.abs(t - (t[0] + np.arange(n) * step))
        worst = int(np.argmax(deviation))
        if deviation[worst] > _uniform_tolerance(step, t):
            raise PathError(
                f"t must be uniformly spaced (t_k = t0 + k*dt, dt={float(step)!r}); "
                f"t[{worst}]={float(t[worst])!r} is off by {deviation[worst]:.3g} s"
            )
        object.__setattr__(self, "t", t)

    @property
    def dt(self) -> float:
        """Sampling period, s."""
        return float((self.t[-1] - self.t[0]) / (len(self) - 1))

    def __len__(self) -> int:
        """Number of samples ``N``."""
        return int(self.t.shape[0])


def case1(
    dt: float = 1e-3,
    *,
    x0: float = 0.0,
    y0: float = 0.0,
    z0: float = 0.66,
    ax: float = 0.06,
    ay: float = 0.06,
    az: float = 0.03,
    duration: float = 2 * math.pi,
) -> TipPath:
    """Closed curve of case study 1 (paper eq. 22).

    ``X = x0 + ax sin t``, ``Y = y0 + ay cos t``, ``Z = z0 + az sin(2t) cos(2t)``, sampled at
    ``t_k = k*dt`` for ``k = 0 .. floor(duration/dt)`` (6284 samples at the defaults).

    Args:
        dt: Sampling period, s, > 0.
        x0: Centre of the curve along x, m.
        y0: Centre of the curve along y, m.
        z0: Centre of the curve along z, m.
        ax: Amplitude along x, m.
        ay: Amplitude along y, m.
        az: Amplitude along z, m.
        duration: Length of the path, s, >= dt.

    Returns:
        A :class:`TipPath` named ``"case1"`` with analytic velocity and acceleration.
    """
    dt = checks.number("dt", dt, minimum=MIN_DT, unit="s", error=PathError)
    for field, value in (("x0", x0), ("y0", y0), ("z0", z0), ("ax", ax), ("ay", ay), ("az", az)):
        checks.number(field, value, unit="m", error=PathError)
    duration = checks.positive("duration", duration, "s", error=PathError)
    t = _sample_times(0.0, duration, dt, "duration")
    sin_t, cos_t = np.sin(t), np.cos(t)
    # Z uses sin(2t) cos(2t) = sin(4t) / 2.
    sin_4t, cos_4t = np.sin(4 * t), np.cos(4 * t)
    position = np.column_stack((x0 + ax * sin_t, y0 + ay * cos_t, z0 + 0.5 * az * sin_4t))
    velocity = np.column_stack((ax * cos_t, -ay * sin_t, 2 * az * cos_4t))
    acceleration = np.column_stack((-ax * sin_t, -ay * cos_t, -8 * az * sin_4t))
    jerk = np.column_stack((-ax * cos_t, ay * sin_t, -32 * az * cos_4t))
    return TipPath("case1", t, position, velocity, acceleration, jerk)


def case2(
    dt: float = 1e-3,
    *,
    corners: Sequence[Sequence[float]] | ArrayLike = (
        (0.03, -0.04, 0.64),
        (-0.04, 0.03, 0.68),
        (0.04, 0.05, 0.62),
    ),
    durations: Sequence[float] | ArrayLike = (2.0, 2.0),
) -> TipPath:
    """Straight lines through corners, case study 2 (paper eq. 23).

    Each line is a rest-to-rest cubic in time, ``x(tau) = Pa + (3 tau^2 - 2 tau^3)(Pb - Pa)``
    with ``tau = (t - t_a)/T``, so the velocity is zero at every corner. Samples are
    ``t_k = k*dt`` up to the total duration (4001 samples at the defaults).

    Args:
        dt: Sampling period, s, > 0.
        corners: Corner points in the base frame, shape ``(M, 3)`` with ``M >= 2``, m.
        durations: Time spent on each line, shape ``(M - 1,)``, s, each > 0.

    Returns:
        A :class:`TipPath` named ``"case2"``.
    """
    dt = checks.number("dt", dt, minimum=MIN_DT, unit="s", error=PathError)
    points = _as_points("corners", corners)
    spans = _as_float_array("durations", durations)
    if spans.shape != (points.shape[0] - 1,):
        raise PathError(
            f"durations must have one entry per line, shape ({points.shape[0] - 1},) for "
            f"{points.shape[0]} corners, got shape {spans.shape}"
        )
    for i, span in enumerate(spans):
        checks.positive(f"durations[{i}]", span, "s", error=PathError)
    times = np.concatenate(([0.0], np.cumsum(spans)))
    return waypoints(times, points, dt, blend="cubic", name="case2")


def waypoints(
    times: Sequence[float] | ArrayLike,
    points: Sequence[Sequence[float]] | ArrayLike,
    dt: float = 1e-3,
    *,
    blend: str = "cubic",
    name: str | None = None,
) -> TipPath:
    """Path through timed waypoints.

    Samples are ``t_k = times[0] + k*dt`` up to ``times[-1]`` (included within 1e-9 dt). A
    sample that falls on a waypoint time belongs to the later segment.

    Args:
        times: Waypoint times, shape ``(M,)``, s, strictly increasing, ``M >= 2``.
        points: Waypoint positions, shape ``(M, 3)``, m.
        dt: Sampling period, s, > 0.
        blend: How consecutive waypoints are joined:
            ``"cubic"`` -- rest-to-rest cubic ``3 tau^2 - 2 tau^3`` per segment (zero velocity
            at each waypoint, acceleration jumps there);
            ``"quintic"`` -- rest-to-rest quintic ``10 tau^3 - 15 tau^4 + 6 tau^5`` (zero
            velocity and acceleration at each waypoint);
            ``"spline"`` -- one C2 cubic spline through all waypoints with zero velocity at
            both ends (it does not stop at interior waypoints).
        name: Label of the path; defaults to ``"waypoints-<blend>"``.

    Returns:
        A :class:`TipPath` with the exact derivatives of the chosen blend.
    """
    sampler = _BLENDS[checks.choice("blend", blend, sorted(_BLENDS), error=PathError)]
    dt = checks.number("dt", dt, minimum=MIN_DT, unit="s", error=PathError)
    knots, pts = _check_samples(times, points, "times", "points", lambda i: f"index {i}")
    t = _sample_times(knots[0], knots[-1] - knots[0], dt, "times[-1] - times[0]")
    position, velocity, acceleration, jerk = sampler(knots, pts, t, dt)
    label = name if name is not None else f"waypoints-{blend}"
    return TipPath(label, t, position, velocity, acceleration, jerk)


def from_samples(
    t: Sequence[float] | ArrayLike,
    position: Sequence[Sequence[float]] | ArrayLike,
    dt: float | None = None,
    *,
    name: str = "samples",
) -> TipPath:
    """Path fitted through sampled positions and resampled at a fixed period.

    A C2 cubic spline (:class:`scipy.interpolate.CubicSpline`, ``bc_type="not-a-knot"``) is
    fitted through the samples; velocity and acceleration are its first and second derivatives.
    "not-a-knot" is used rather than "natural" because it imposes no zero-acceleration condition
    at the ends, which would bias a path that starts or ends while accelerating. With two
    samples the fit is the straight line between them, with three a parabola.

    Args:
        t: Sample times, shape ``(n,)``, s, strictly increasing, ``n >= 2``.
        position: Sampled tip positions, shape ``(n, 3)``, m.
        dt: Output sampling period, s, > 0. Defaults to the spacing of ``t`` if that is uniform
            to 1e-9 relative; otherwise it is required.
        name: Label of the path.

    Returns:
        A :class:`TipPath` sampled at ``t[0] + k*dt`` up to ``t[-1]``.
    """
    times, points = _check_samples(t, position, "t", "position", lambda i: f"index {i}")
    return _fit_spline(times, points, dt, name, "t", lambda i: f"index {i}")


def from_csv(
    file: str | os.PathLike[str], dt: float | None = None, *, name: str | None = None, quote: bool = True
) -> TipPath:
    """Path read from a CSV file of sampled positions, fitted as in :func:`from_samples`.

    The file has a header row ``t,x,y,z`` (case-insensitive, whitespace around the names
    allowed) and one row per sample: time in s, position in m. Blank lines are skipped.

    Args:
        file: Path of the CSV file.
        dt: Output sampling period, s, > 0; defaults to the rows' spacing if it is uniform.
        name: Label of the path; defaults to the file's stem.
        quote: Whether a message about a bad header, row or value quotes it. False for a file named
            by someone other than the user (a study file's ``path``): a file that is not a valid
            path file is then never shown, only its line and column.

    Returns:
        A :class:`TipPath` sampled at ``t[0] + k*dt`` up to the last row's time.

    Raises:
        PathError: The file cannot be read (missing, a folder, not UTF-8 text, larger than
            :data:`CSV_FILE_LIMIT` bytes), or a header, row or value is invalid; the message
            names the file and the line (1-based, the header being line 1).
    """
    label = os.fspath(file)
    times, points, where = _read_csv(file, quote, minimum=2)
    stem = os.path.splitext(os.path.basename(label))[0]
    try:
        return _fit_spline(times, points, dt, name if name is not None else stem, "t", where)
    except PathError as exc:
        raise PathError(f"path file {shown(label, 200)}: {exc}") from None


def csv_point(file: str | os.PathLike[str], *, quote: bool = True) -> tuple[float, FloatArray] | None:
    """The time (s) and the point ``(3,)`` (m) of a path file with a single data row; ``None`` if it has more.

    The file is read and checked as by :func:`from_csv` (same messages), which needs two rows or
    more; ``vgtarm ik`` answers a one-row file with the configuration of that point.
    """
    times, points, _ = _read_csv(file, quote, minimum=1)
    return (float(times[0]), points[0].copy()) if points.shape[0] == 1 else None


def _read_csv(
    file: str | os.PathLike[str], quote: bool, minimum: int
) -> tuple[FloatArray, FloatArray, Callable[[int], str]]:
    """The checked times ``(N,)`` and points ``(N, 3)`` of a path file with at least ``minimum`` rows,
    and the function naming the line of a row (for messages)."""
    label = os.fspath(file)
    shown_label = shown(label, 200)
    text = read_text_limited(file, CSV_FILE_LIMIT, "path file", error=PathError, encoding="utf-8-sig")
    try:
        rows = _numbered_rows(csv.reader(io.StringIO(text, newline="")))
    except csv.Error as exc:
        raise PathError(f"path file {shown_label} is not a readable CSV text file: {cut(str(exc), 120)}") from None
    if not rows:
        raise PathError(f"path file {shown_label} is empty; expected a header row t,x,y,z")
    header_line, header = rows[0]
    found = tuple(cell.strip().lower() for cell in header)
    if found != _CSV_COLUMNS:  # another kind of file (an ik output, a run's table, a TOML file): never quoted
        raise PathError(
            f"path file {shown_label}: line {header_line}: header must be the columns t,x,y,z (time in s, the tip"
            f" point in m); {found_columns(header, text=text, quote=quote)}"
        )
    if len(rows) < minimum + 1:
        raise PathError(
            f"path file {shown_label}: need at least {minimum} data row{'s' if minimum > 1 else ''} after the header,"
            f" got {len(rows) - 1}"
        )
    if len(rows) - 1 > MAX_SAMPLES:
        raise PathError(f"path file {shown_label}: {len(rows) - 1} data rows; at most {MAX_SAMPLES:,} are read")
    data = np.empty((len(rows) - 1, 4))
    lines = []

    def value(cell: str) -> str:
        return shown(cell.strip()) if quote else "the value"

    for k, (line, row) in enumerate(rows[1:]):
        if len(row) != len(_CSV_COLUMNS):
            raise PathError(
                f"path file {shown_label}: line {line}: expected 4 fields (t,x,y,z), found {len(row)}"
                + (f": {shown(row)}" if quote else "")
            )
        for j, (column, cell) in enumerate(zip(_CSV_COLUMNS, row, strict=True)):
            try:
                data[k, j] = float(cell)
            except ValueError:
                raise PathError(
                    f"path file {shown_label}: line {line}, column {column!r}: {value(cell)} is not a number"
                ) from None
            if not math.isfinite(data[k, j]):
                raise PathError(f"path file {shown_label}: line {line}, column {column!r}: {value(cell)} is not finite")
        lines.append(line)

    def where(i: int) -> str:
        return f"line {lines[i]}"

    if data.shape[0] == 1:
        return data[:, 0], data[:, 1:], where
    try:
        times, points = _check_samples(data[:, 0], data[:, 1:], "t", "x,y,z", where)
    except PathError as exc:
        raise PathError(f"path file {shown_label}: {exc}") from None
    return times, points, where


def _numbered_rows(reader: Any) -> list[tuple[int, list[str]]]:
    """Non-blank CSV rows with the (1-based) file line on which each one ends."""
    numbered = []
    for row in reader:
        if row and any(cell.strip() for cell in row):
            numbered.append((reader.line_num, row))
    return numbered


def _fit_spline(
    times: FloatArray,
    points: FloatArray,
    dt: float | None,
    name: str,
    field: str,
    where: Callable[[int], str],
) -> TipPath:
    """Fit a not-a-knot cubic spline through checked samples and resample it every ``dt``.

    ``field`` names the times and ``where(i)`` sample ``i`` in error messages.
    """
    n = times.shape[0]
    if dt is None:
        step = (times[-1] - times[0]) / (n - 1)
        spacing = np.diff(times)
        worst = int(np.argmax(np.abs(spacing - step)))
        if abs(spacing[worst] - step) > _UNIFORM_RTOL * step:
            raise PathError(
                f"{field} is not uniformly spaced: step {float(spacing[worst])!r} s from "
                f"{where(worst)} to {where(worst + 1)}, mean step {float(step)!r} s; "
                "pass dt to choose the output sampling period"
            )
        dt = float(step)
    dt = checks.number("dt", dt, minimum=MIN_DT, unit="s", error=PathError)
    t = _sample_times(times[0], times[-1] - times[0], dt, f"{field}[-1] - {field}[0]")
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is found below, as a non-finite value
        spline = CubicSpline(times, points, axis=0, bc_type="not-a-knot")
        samples = spline(t), spline(t, 1), spline(t, 2), spline(t, 3)
    return TipPath(name, t, *samples)


def _sample_cubic(
    knots: FloatArray, points: FloatArray, t: FloatArray, dt: float
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Rest-to-rest cubic ``s = 3 tau^2 - 2 tau^3`` per segment; returns (N, 3) x, v, a, jerk."""
    return _sample_segments(
        knots,
        points,
        t,
        dt,
        lambda u: (3 * u**2 - 2 * u**3, 6 * u - 6 * u**2, 6 - 12 * u, np.full_like(u, -12.0)),
    )


def _sample_quintic(
    knots: FloatArray, points: FloatArray, t: FloatArray, dt: float
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Rest-to-rest quintic ``s = 10 tau^3 - 15 tau^4 + 6 tau^5``; returns (N, 3) x, v, a, jerk."""
    return _sample_segments(
        knots,
        points,
        t,
        dt,
        lambda u: (
            10 * u**3 - 15 * u**4 + 6 * u**5,
            30 * u**2 - 60 * u**3 + 30 * u**4,
            60 * u - 180 * u**2 + 120 * u**3,
            60 - 360 * u + 360 * u**2,
        ),
    )


def _sample_spline(
    knots: FloatArray, points: FloatArray, t: FloatArray, dt: float
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """C2 cubic spline through all points, zero velocity at both ends; (N, 3) x, v, a, jerk."""
    spline = CubicSpline(knots, points, axis=0, bc_type="clamped")
    return spline(t), spline(t, 1), spline(t, 2), spline(t, 3)


def _sample_segments(
    knots: FloatArray,
    points: FloatArray,
    t: FloatArray,
    dt: float,
    profile: Callable[[FloatArray], tuple[FloatArray, FloatArray, FloatArray, FloatArray]],
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Evaluate a per-segment blend ``x = Pa + s(tau)(Pb - Pa)`` at times ``t``.

    ``profile(tau)`` returns ``s``, ``ds/dtau``, ``d2s/dtau2`` and ``d3s/dtau3``. A sample within a
    millionth of ``dt`` below a knot counts as on it and goes to the later segment.
    """
    segment = np.searchsorted(knots, t + 1e-6 * dt, side="right") - 1
    segment = np.clip(segment, 0, knots.shape[0] - 2)
    span = knots[segment + 1] - knots[segment]
    tau = np.clip((t - knots[segment]) / span, 0.0, 1.0)
    s, ds, dds, ddds = profile(tau)
    delta = points[segment + 1] - points[segment]
    position = points[segment] + s[:, None] * delta
    velocity = (ds / span)[:, None] * delta
    acceleration = (dds / span**2)[:, None] * delta
    jerk = (ddds / span**3)[:, None] * delta
    return position, velocity, acceleration, jerk


_BLENDS = MappingProxyType({"cubic": _sample_cubic, "quintic": _sample_quintic, "spline": _sample_spline})
"""Waypoint blends by name: ``sampler(knots, points, t, dt) -> (position, velocity, accel, jerk)``."""


def _check_samples(
    times: object,
    points: object,
    times_field: str,
    points_field: str,
    where: Callable[[int], str],
) -> tuple[FloatArray, FloatArray]:
    """Validate timed points; ``where(i)`` names sample ``i`` in messages.

    Returns times of shape ``(n,)`` and points of shape ``(n, 3)`` as float64 copies.
    """
    knots = _as_float_array(times_field, times)
    if knots.ndim != 1:
        raise PathError(f"{times_field} must be 1-dimensional, got shape {knots.shape}")
    pts = _as_points(points_field, points)
    if knots.shape[0] != pts.shape[0]:
        raise PathError(
            f"{times_field} and {points_field} must have the same length, got "
            f"{knots.shape[0]} times and {pts.shape[0]} points"
        )
    bad = np.flatnonzero(~np.isfinite(knots))
    if bad.size:
        i = int(bad[0])
        raise PathError(f"{where(i)}: {times_field} is {float(knots[i])!r}, must be finite")
    bad_rows, bad_cols = np.nonzero(~np.isfinite(pts))
    if bad_rows.size:
        i, j = int(bad_rows[0]), int(bad_cols[0])
        raise PathError(f"{where(i)}: {points_field} column {'xyz'[j]!r} is {float(pts[i, j])!r}, must be finite")
    bad = np.flatnonzero(np.abs(knots) > MAX_TIME)
    if bad.size:
        i = int(bad[0])
        raise PathError(f"{where(i)}: {times_field} is {float(knots[i])!r} s, expected a time within +-{MAX_TIME:g} s")
    bad_rows, bad_cols = np.nonzero(np.abs(pts) > MAX_COORDINATE)
    if bad_rows.size:
        i, j = int(bad_rows[0]), int(bad_cols[0])
        raise PathError(
            f"{where(i)}: {points_field} column {'xyz'[j]!r} is {float(pts[i, j])!r} m, expected a coordinate"
            f" within +-{MAX_COORDINATE:g} m (positions are in metres)"
        )
    steps = np.diff(knots)
    bad = np.flatnonzero(steps <= 0.0)
    if bad.size:
        i = int(bad[0]) + 1
        raise PathError(
            f"{where(i)}: {times_field} must be strictly increasing, got "
            f"{float(knots[i])!r} after {float(knots[i - 1])!r} ({where(i - 1)})"
        )
    bad = np.flatnonzero(steps < MIN_DT)
    if bad.size:
        i = int(bad[0]) + 1
        raise PathError(
            f"{where(i)}: {times_field} = {float(knots[i])!r} is only {float(steps[i - 1])!r} s after "
            f"{float(knots[i - 1])!r} ({where(i - 1)}); samples must be at least {MIN_DT:g} s apart"
        )
    return knots, pts


def _as_points(field: str, value: object) -> FloatArray:
    """``value`` as a float64 array of shape ``(n, 3)``, else PathError naming ``field``."""
    points = _as_float_array(field, value)
    if points.ndim != 2 or points.shape[1] != 3:
        raise PathError(f"{field} must have shape (n, 3), got shape {points.shape}")
    if points.shape[0] < 2:
        raise PathError(f"{field}: need at least 2 points, got {points.shape[0]}")
    return points


def _as_float_array(field: str, value: object) -> FloatArray:
    """``value`` as a new float64 array, else PathError naming ``field`` (also a masked array with
    masked entries: np.array would take the values under the mask)."""
    refuse_masked(value, field, PathError)
    try:
        return np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise PathError(f"{field} must be an array of numbers, got {shown(value)} ({cut(str(exc))})") from None


def _frozen_array(field: str, value: object) -> FloatArray:
    """A read-only float64 copy of ``value``."""
    array = _as_float_array(field, value)
    array.flags.writeable = False
    return array


def _sample_times(start: float, duration: float, dt: float, field: str) -> FloatArray:
    """Times ``start + k*dt`` for ``k = 0 .. floor(duration/dt + 1e-9)``, shape ``(N,)``, s.

    Refuses more than :data:`MAX_SAMPLES` samples before allocating them.
    """
    ratio = duration / dt + _COUNT_TOLERANCE
    if not ratio < MAX_SAMPLES:
        raise PathError(
            f"{field} = {float(duration)!r} s at dt = {dt!r} s makes {ratio:.3g} samples; at most"
            f" {MAX_SAMPLES:,}: give a larger dt or a shorter path"
        )
    count = math.floor(ratio) + 1
    if count < 2:
        raise PathError(f"{field} = {float(duration)!r} s is shorter than dt = {dt!r} s; need 2 samples")
    return float(start) + np.arange(count, dtype=np.float64) * float(dt)


def _uniform_tolerance(step: float, t: FloatArray) -> float:
    """Allowed deviation of sample times from ``t0 + k*dt``, s."""
    return _UNIFORM_RTOL * step + 8 * np.finfo(np.float64).eps * float(np.max(np.abs(t)))


def __getattr__(name: str) -> Any:
    """``vgtarm.paths.Path``, the old name of :class:`TipPath`, with a :class:`DeprecationWarning`:
    it shadowed :class:`pathlib.Path` in a module that imported both."""
    if name == "Path":
        import warnings

        warnings.warn(
            "vgtarm.paths.Path is now vgtarm.paths.TipPath (Path shadowed pathlib.Path)",
            DeprecationWarning,
            stacklevel=2,
        )
        return TipPath
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
