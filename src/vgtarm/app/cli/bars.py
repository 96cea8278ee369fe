"""Progress bars of the command line for what :mod:`vgtarm.progress` reports (issue 27: progress on
anything longer than two seconds).

:func:`progress_bar` listens to the reports made inside its block and shows them as a tqdm bar on
standard error, in the style of the other bars and of a model build's progress lines (``vgtarm:``
first): only on a terminal, only once the computation has run for :data:`vgtarm.progress.DELAY`
seconds (a short one shows nothing), and never after ``-q``. The bar is removed when the block ends.
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterator
from typing import Any, TextIO

from ... import progress


def terminal(stream: Any) -> bool:
    """Whether ``stream`` is a terminal (a closed or descriptor-less stream is not)."""
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):
        return False


@contextlib.contextmanager
def progress_bar(what: str, unit: str, total: int | None = None, stream: TextIO | None = None) -> Iterator[None]:
    """Show the progress :func:`vgtarm.progress.report` gives inside the block as a bar
    ``vgtarm: <what>`` counting ``unit`` (``total`` when known now, else from the first report), on
    ``stream`` (default standard error) when it is a terminal and ``-q`` was not given."""
    out = sys.stderr if stream is None else stream
    if progress.quiet() or not terminal(out):
        with progress.listening(None):
            yield
        return
    from tqdm import tqdm

    bars: list[Any] = []

    def start(count: int) -> Any:
        bars.append(tqdm(total=count, desc=f"vgtarm: {what}", unit=unit, delay=progress.DELAY, file=out, leave=False))
        return bars[0]

    if total is not None:
        start(total)

    def listener(done: int, count: int) -> None:
        bar = bars[0] if bars else start(count)
        if bar.total != count:
            bar.total = count
        bar.update(done - bar.n)

    try:
        with progress.listening(listener):
            yield
    finally:
        for bar in bars:
            bar.close()
