"""A closed-loop run animated: the mechanism moving along the run's ``q(t)``, rendered to MP4 or GIF.

Each frame shows, on the left, the robot in an isometric view (drawn by
:func:`vgtarm.app.pictures.drawing.draw_mechanism` from the run's measured ``q`` at that instant) with the
desired and actual tip paths behind it; on the right, the tip path seen from above magnified around
the path, and the tip error against time with a cursor. A line of text gives the time, the current
tip error and, for runs of the switching method, whether the GA's gains are in use.

Frames and samples (:func:`frame_plan`): a run of duration ``D`` (first to last completed sample)
played at ``speed`` simulated seconds per second of video and ``fps`` frames per second has
``round(D * fps / speed)`` frames (at least one; halves round up). Frame ``i`` shows simulated
time ``t0 + i * speed / fps``, taken at the sample nearest to it (halves round up), so every frame
shows a recorded sample exactly and the video lasts ``frames / fps`` seconds.

MP4 is written by the ffmpeg binary of the ``imageio-ffmpeg`` package (no system ffmpeg), fed
raw frames through a pipe; its messages are kept, so that a failure (a full disk, a broken
binary) ends in one line naming the output and ffmpeg's reason, and leaves no file. GIF, with
Pillow alone, is the fallback when that package is missing.
"""

from __future__ import annotations

import os
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from numpy.typing import ArrayLike, NDArray

from ... import checks
from ...errors import InputError, cut, escape
from ...fileio import atomic_path
from ...markup import mpl_text
from ...memory import check_memory
from ...model.robot import Robot
from ...simulation.result import MODE_GA, SimulationResult
from .drawing import MM, draw_mechanism, label_axes, set_equal_extent
from .geometry import MechanismGeometry, mechanism_geometries

Array = NDArray[np.float64]

#: Video formats by file suffix.
FORMATS = (".mp4", ".gif")
#: Figure size (inches); at 100 dpi the frame is 1280 x 640 pixels, multiples of 16 as H.264 likes.
FIGURE_SIZE = (12.8, 6.4)
#: Largest resolution: 12,800 x 6,400 pixels a frame.
MAX_DPI = 1000.0
#: Most frames of one animation (more than an hour of video at 25 frames per second).
MAX_FRAMES = 100_000
#: Largest distance (m) between a run's recorded tip and the robot's tip at its first sample for
#: the run to count as made with that robot.
SAME_ROBOT_TOLERANCE = 1e-9


@dataclass(frozen=True)
class FramePlan:
    """Which sample of a run each frame shows (see the module's docstring).

    Attributes: ``samples`` (frames,) indices into the run; ``times`` (frames,) their times (s);
    ``fps``; ``speed``; ``duration_s`` the run's duration ``D``.
    """

    samples: NDArray[np.int64]
    times: Array
    fps: float
    speed: float
    duration_s: float

    def __len__(self) -> int:
        return len(self.samples)


@dataclass(frozen=True)
class Animation:
    """What :func:`render_animation` wrote: the file, its frame plan, and the tip drawn in each
    frame (frames, 3) in F0 (m), read back from the tool's Line3D after the frame was drawn."""

    path: Path
    plan: FramePlan
    drawn_tip: Array


def _round_half_up(x: ArrayLike) -> NDArray[np.int64]:
    return np.floor(np.asarray(x, dtype=float) + 0.5).astype(np.int64)


def frame_plan(result: SimulationResult, *, fps: float = 25.0, speed: float = 1.0) -> FramePlan:
    """The frames of an animation of ``result`` at ``fps`` frames per second and ``speed``."""
    checks.positive("fps", fps, "frames per second of video")
    checks.positive("speed", speed, "simulated seconds per second of video")
    n = result.completed
    if n < 1:
        raise InputError("the run has no completed sample to animate")
    t = result.t
    duration = float(t[n - 1] - t[0])
    frames = duration * fps / speed
    if not frames <= MAX_FRAMES:  # before any array of them is made
        raise InputError(
            f"fps = {fps!r} at speed = {speed!r} makes {frames:.3g} frames of the {duration:g} s run;"
            f" at most {MAX_FRAMES:,}: give fewer frames per second or a higher speed"
        )
    count = max(1, int(_round_half_up(frames)))
    wanted = np.arange(count) * (speed / fps)
    samples = np.clip(_round_half_up(wanted / result.dt), 0, n - 1)
    return FramePlan(samples=samples, times=t[samples], fps=float(fps), speed=float(speed), duration_s=duration)


def check_same_robot(robot: Robot, result: SimulationResult) -> None:
    """Raise :class:`~vgtarm.errors.InputError` unless ``result`` was made with ``robot``'s geometry
    (it has the robot's joints, and its recorded tip at the first sample is the robot's tip of the
    recorded ``q``)."""
    names = result.joint_names
    if names != robot.joint_names or result.q.shape[-1] != robot.n_joints:
        raise InputError(
            f"the run has {len(names)} joints ({_names(names)}) and robot {robot.parameters.name!r}"
            f" has {robot.n_joints} ({_names(robot.joint_names)}): it was made with another robot;"
            " pass that robot's file with --config"
        )
    if result.completed < 1:
        raise InputError("the run has no completed sample")
    gap = float(np.linalg.norm(robot.tip_position(result.q[0]) - result.tip[0]))
    if not gap <= SAME_ROBOT_TOLERANCE:
        raise InputError(
            f"the run's recorded tip is {gap * 1e3:.4g} mm from robot {robot.parameters.name!r}'s tip of its q: "
            "it was made with another robot; pass that robot's file with --config"
        )


def _names(names: tuple[str, ...]) -> str:
    """Joint names for a message: all of them, or the first and last few of many."""
    return " ".join(names) if len(names) <= 8 else " ".join((*names[:3], "...", *names[-3:]))


def _entry_point(result: SimulationResult) -> Array | None:
    """The entry point (m) of a run whose reference passes the tool's axis through one, else None."""
    value = result.metadata.get("entry_point_m")
    if not isinstance(value, list | tuple) or len(value) != 3:
        return None
    point = np.array(value, dtype=float)
    return point if np.isfinite(point).all() else None


def _uses_switching(result: SimulationResult) -> bool:
    return str(result.metadata.get("controller", "")).lower() == "scm" or bool(np.any(result.mode == MODE_GA))


class _Scene:
    """The figure of one animation and the artists each frame moves."""

    def __init__(self, result: SimulationResult, geometries: list[MechanismGeometry], title: str, dpi: float) -> None:
        n = result.completed
        self.result = result
        self.switching = _uses_switching(result)
        self.fig = Figure(figsize=FIGURE_SIZE, dpi=dpi)
        self.canvas = FigureCanvasAgg(self.fig)
        grid = self.fig.add_gridspec(
            2, 2, width_ratios=(1.25, 1.0), left=0.02, right=0.97, top=0.87, bottom=0.09, hspace=0.35
        )
        ax3d = self.fig.add_subplot(grid[:, 0], projection="3d")
        ax3d.set_proj_type("ortho")
        self.artists = draw_mechanism(geometries[0], ax3d, leg_labels=False)
        desired, actual = result.tip_desired[:n] * MM, result.tip[:n] * MM
        ax3d.plot(*desired.T, color="tab:blue", linewidth=1.0, linestyle="--", label="desired tip path")
        ax3d.plot(*actual.T, color="tab:orange", linewidth=1.0, label="actual tip path")
        entry = _entry_point(result)
        if entry is not None:  # a tool task through an entry point: the point the axis passes through
            ax3d.plot(*([v] for v in entry * MM), "x", color="tab:green", markersize=8, label="entry point")
        ax3d.view_init(elev=22.0, azim=-52.0)
        label_axes(ax3d)
        every = np.concatenate(
            [g.points() for g in geometries] + [desired / MM, actual / MM] + ([] if entry is None else [entry[None]])
        )
        set_equal_extent(ax3d, every * MM)
        ax3d.legend(loc="upper left", fontsize=8)

        self.ax_path = self.fig.add_subplot(grid[0, 1])
        self.ax_path.plot(desired[:, 0], desired[:, 1], "--", color="tab:blue", linewidth=1.2, label="desired")
        self.ax_path.plot(actual[:, 0], actual[:, 1], color="tab:orange", linewidth=1.2, label="actual")
        (self.tip_desired_dot,) = self.ax_path.plot([], [], "o", color="tab:blue", markersize=6)
        (self.tip_dot,) = self.ax_path.plot([], [], "o", color="tab:orange", markersize=5)
        self.ax_path.set_aspect("equal", adjustable="datalim")
        self.ax_path.set_xlabel("x (mm)", fontsize=8)
        self.ax_path.set_ylabel("y (mm)", fontsize=8)
        self.ax_path.set_title("tip path seen from above", fontsize=9)
        self.ax_path.legend(fontsize=7, loc="upper right")
        self.ax_path.tick_params(labelsize=7)

        self.ax_err = self.fig.add_subplot(grid[1, 1])
        t, err = result.t[:n], result.tip_error[:n] * MM
        self.ax_err.plot(t, err, color="tab:red", linewidth=1.0)
        if self.switching:
            ga = result.mode[:n] == MODE_GA
            self.ax_err.fill_between(
                t, 0, 1, where=ga, transform=self.ax_err.get_xaxis_transform(), color="tab:orange", alpha=0.2, lw=0
            )
        self.cursor = self.ax_err.axvline(t[0], color="0.2", linewidth=1.0)
        self.ax_err.set_xlabel("time (s)", fontsize=8)
        self.ax_err.set_ylabel("tip error (mm)", fontsize=8)
        self.ax_err.set_xlim(t[0], t[-1] if n > 1 else t[0] + result.dt)
        self.ax_err.tick_params(labelsize=7)
        self.ax_err.grid(alpha=0.3)
        self.fig.text(0.02, 0.965, title, fontsize=11, weight="bold")
        self.status = self.fig.text(0.02, 0.925, "", fontsize=10, family="monospace")

    def show(self, geometry: MechanismGeometry, k: int) -> tuple[NDArray[np.uint8], Array]:
        """Draw sample ``k``; return the frame's RGB pixels and the tip as drawn (m)."""
        r = self.result
        self.artists.update(geometry)
        self.tip_desired_dot.set_data([r.tip_desired[k, 0] * MM], [r.tip_desired[k, 1] * MM])
        self.tip_dot.set_data([r.tip[k, 0] * MM], [r.tip[k, 1] * MM])
        self.cursor.set_xdata([r.t[k], r.t[k]])
        text = f"t = {r.t[k]:7.3f} s    tip error = {r.tip_error[k] * 1e3:8.4f} mm"
        if self.switching:
            text += "    gains: " + ("GA (switched)" if r.mode[k] == MODE_GA else "fixed")
        self.status.set_text(text)
        self.canvas.draw()
        pixels = np.asarray(self.canvas.buffer_rgba())[:, :, :3].copy()
        xs, ys, zs = self.artists.lines["tool"].get_data_3d()
        return pixels, np.array([xs[-1], ys[-1], zs[-1]], dtype=float) / MM


def _writer(path: Path, fps: float, shown: Path) -> Any:
    """A writer of ``path`` (``append_data``, ``close``, ``abort``); ``shown`` is the user's name for it."""
    if path.suffix.lower() == ".mp4":
        try:
            import imageio_ffmpeg  # noqa: F401
        except ImportError:
            raise InputError(
                f"{shown}: MP4 needs the imageio-ffmpeg package (pip install 'vgtarm[viz]'); or write a .gif"
            ) from None
        return _FfmpegWriter(path, fps, shown)
    return _GifWriter(path, fps)


#: H.264 wants frame sides in multiples of this; other frames are scaled up to the next multiple.
MACRO_BLOCK = 16


class _FfmpegWriter:
    """H.264 MP4 by the ffmpeg of ``imageio-ffmpeg``, raw RGB frames on its standard input.

    ffmpeg runs in its own session (the terminal's Ctrl-C reaches vgtarm alone, which stops it) and
    its messages go to a temporary file, not the terminal: a failure, while writing or at the end
    (ffmpeg's exit status is checked), raises one ``OSError`` line naming the user's file and the
    last thing ffmpeg said."""

    def __init__(self, path: Path, fps: float, shown: Path) -> None:
        self.path, self.fps, self.shown = path, fps, shown
        self.process: subprocess.Popen[bytes] | None = None
        self.log = tempfile.TemporaryFile()

    def _start(self, height: int, width: int) -> subprocess.Popen[bytes]:
        import imageio_ffmpeg

        command = [imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-f", "rawvideo", "-vcodec", "rawvideo"]
        command += ["-s", f"{width}x{height}", "-pix_fmt", "rgb24", "-r", f"{self.fps:.12g}", "-i", "-", "-an"]
        command += ["-vcodec", "libx264", "-pix_fmt", "yuv420p", "-crf", "15"]
        padded = [-(-side // MACRO_BLOCK) * MACRO_BLOCK for side in (width, height)]
        if padded != [width, height]:
            command += ["-vf", f"scale={padded[0]}:{padded[1]}"]
        command += ["-v", "error", os.fspath(self.path)]
        try:
            return subprocess.Popen(
                command, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=self.log, start_new_session=True
            )
        except OSError as exc:
            raise OSError(f"{self.shown}: cannot start ffmpeg {cut(command[0], 120)!r} ({exc.strerror})") from None

    def append_data(self, pixels: NDArray[np.uint8]) -> None:
        if self.process is None:
            self.process = self._start(*pixels.shape[:2])
        assert self.process.stdin is not None
        try:
            self.process.stdin.write(np.ascontiguousarray(pixels, dtype=np.uint8).tobytes())
        except OSError:  # ffmpeg has gone (its reason is in its messages)
            self._failed()

    def close(self) -> None:
        if self.process is None:
            raise InputError(f"{self.shown}: no frame to write")
        assert self.process.stdin is not None
        try:
            self.process.stdin.close()
        except OSError:
            self._failed()
        if self.process.wait() != 0:
            self._failed()
        self.log.close()

    def abort(self) -> None:
        """Stop ffmpeg at once (an error or Ctrl-C while the frames are drawn)."""
        if self.process is not None and self.process.poll() is None:
            self.process.kill()
            self.process.wait()
        self.log.close()

    def _failed(self) -> None:
        assert self.process is not None
        try:  # a last frame stuck in the pipe: close it, ffmpeg has ended or ends now
            self.process.stdin.close()  # type: ignore[union-attr]
        except OSError:
            pass
        try:
            status = self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            status = self.process.wait()
        self.log.seek(0)
        said = [line.strip() for line in self.log.read().decode(errors="replace").splitlines() if line.strip()]
        self.log.close()
        reason = said[-1].replace(os.fspath(self.path), os.fspath(self.shown)) if said else "no message"
        ended = f"ended with status {status}" if status >= 0 else f"was killed by signal {-status}"
        raise OSError(f"{self.shown}: ffmpeg {ended}: {cut(reason, 160)}")


class _GifWriter:
    """Collects palette frames and writes one looping GIF with Pillow (no encoder package needed)."""

    def __init__(self, path: Path, fps: float) -> None:
        self.path, self.fps = path, fps
        self.frames: list[object] = []

    def append_data(self, pixels: NDArray[np.uint8]) -> None:
        from PIL import Image

        self.frames.append(Image.fromarray(pixels).quantize(colors=128, method=Image.Quantize.MEDIANCUT))

    def abort(self) -> None:
        self.frames.clear()

    def close(self) -> None:
        first, *rest = self.frames
        first.save(  # type: ignore[attr-defined]
            self.path, save_all=True, append_images=rest, duration=round(1000 / self.fps), loop=0, optimize=False
        )


def _title(robot: Robot, result: SimulationResult, speed: float) -> str:
    meta = result.metadata
    return (
        f"{mpl_text(robot.parameters.name)}: "
        + (
            f"case {mpl_text(meta['case'])}"
            if meta.get("case")
            else mpl_text(meta.get("path", meta.get("reference", "?")))
        )
        + ","
        f" {mpl_text(str(meta.get('controller', 'run')).upper())}"
        + (" + tool force" if meta.get("external_force") else "")
        + (f", {speed:g}x speed" if speed != 1 else "")
    )


def animation_frame(
    robot: Robot, result: SimulationResult, time_s: float, *, dpi: float = 100.0, title: str | None = None
) -> tuple[NDArray[np.uint8], int]:
    """One frame of the animation of ``result``: the RGB pixels (height, width, 3) at the recorded
    sample nearest to ``time_s``, and that sample's index."""
    check_same_robot(robot, result)
    n = result.completed
    k = int(np.clip(_round_half_up((time_s - result.t[0]) / result.dt), 0, n - 1))
    geometries = mechanism_geometries(robot, result.q[[0, k, n - 1]])
    scene = _Scene(result, geometries, title or _title(robot, result, 1.0), dpi)
    pixels, _ = scene.show(geometries[1], k)
    return pixels, k


def render_animation(
    robot: Robot,
    result: SimulationResult,
    out: str | Path,
    *,
    fps: float = 25.0,
    speed: float = 1.0,
    dpi: float = 100.0,
    title: str | None = None,
    progress: bool = True,
) -> Animation:
    """Write the animation of ``result`` (made with ``robot``) to ``out`` (``.mp4`` or ``.gif``).

    ``fps`` frames per second of video, ``speed`` simulated seconds per second of video; ``dpi``
    scales the frame (100: 1280 x 640 pixels). Shows a progress bar unless ``progress`` is False.
    The file appears only when complete.
    """
    from tqdm import tqdm

    path = Path(out)
    if path.suffix.lower() not in FORMATS:
        raise InputError(f"out = {str(path)!r}: expected a file name ending in one of {list(FORMATS)}")
    checks.positive("dpi", dpi, maximum=MAX_DPI)
    check_same_robot(robot, result)
    plan = frame_plan(result, fps=fps, speed=speed)
    area = (FIGURE_SIZE[0] * dpi) * (FIGURE_SIZE[1] * dpi)  # pixels a frame
    kept = len(plan) if path.suffix.lower() == ".gif" else 1  # a GIF is written from all its frames
    check_memory(
        area * (16 + kept),  # the canvas and its copies (RGBA), then the palette frames
        f"{len(plan):,} frames of {FIGURE_SIZE[0] * dpi:.0f} x {FIGURE_SIZE[1] * dpi:.0f} pixels (dpi = {dpi:g})",
        "give a lower dpi, fewer frames per second or a higher speed (or write .mp4)",
    )
    geometries = mechanism_geometries(robot, result.q[plan.samples])
    scene = _Scene(result, geometries, title or _title(robot, result, plan.speed), dpi)
    drawn = np.empty((len(plan), 3))
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as temporary:
        writer = _writer(temporary, plan.fps, path)
        try:
            for i in tqdm(range(len(plan)), desc=f"rendering {escape(path.name)}", unit="frame", disable=not progress):
                pixels, drawn[i] = scene.show(geometries[i], int(plan.samples[i]))
                writer.append_data(pixels)
        except BaseException:  # an error or Ctrl-C: the encoder stops, the temporary file goes
            writer.abort()
            raise
        writer.close()  # a failure of the encoder at the end is an error too
    return Animation(path=path, plan=plan, drawn_tip=drawn)
