"""Regenerate the README's pictures: ``python -m vgtarm.app.pictures.readme_images [--out docs/images]``.

- ``robot_home.png``: the reference robot at its home pose (:func:`vgtarm.app.pictures.drawing.pose_figure`);
- ``animation_frame.png``: one frame of the animation of case 1 under the switching method
  (:func:`vgtarm.app.pictures.animation.animation_frame`), from a seeded run of the whole path.

Both are reduced to a palette of :data:`COLOURS` colours so that they stay a few tens of kB.
"""

from __future__ import annotations

import argparse
import io
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from numpy.typing import NDArray

from ...experiment.cases import run_case
from ...fileio import atomic_path
from ...model.robot import Robot, load_robot
from .animation import animation_frame
from .drawing import pose_figure

#: Palette size of the written PNGs.
COLOURS = 96
#: Time of case 1 shown in the animation frame (s).
FRAME_TIME_S = 2.2


def _pixels(fig: Figure) -> NDArray[np.uint8]:
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[:, :, :3].copy()


def write_png(pixels: NDArray[np.uint8], path: str | Path, colours: int = COLOURS) -> Path:
    """Write RGB ``pixels`` as a palette PNG of ``colours`` colours, atomically."""
    from PIL import Image

    image = Image.fromarray(pixels).quantize(colors=colours, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
    buffer = io.BytesIO()
    image.save(buffer, format="PNG", optimize=True)
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(target) as temporary:
        temporary.write_bytes(buffer.getvalue())
    return target


def make_images(robot: Robot, out: str | Path) -> list[Path]:
    """Write both pictures into ``out``; returns their paths."""
    folder = Path(out)
    home = write_png(_pixels(pose_figure(robot, robot.parameters.home, dpi=80)), folder / "robot_home.png")
    run = run_case(robot, 1, controller="scm", seed=0, scm_variant="paper")  # the paper's case 1 run
    pixels, _ = animation_frame(robot, run, FRAME_TIME_S, dpi=70)
    frame = write_png(pixels, folder / "animation_frame.png")
    return [home, frame]


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m vgtarm.app.pictures.readme_images``."""
    parser = argparse.ArgumentParser(
        prog="python -m vgtarm.app.pictures.readme_images", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--out", type=Path, default=Path("docs/images"), help="folder (default: docs/images)")
    parser.add_argument("--config", type=Path, default=None, help="robot TOML file (default: the reference robot)")
    args = parser.parse_args(argv)
    for path in make_images(load_robot(args.config), args.out):
        print(f"{path} ({path.stat().st_size / 1024:.0f} kB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
