"""The ``vgtarm`` program's entry point (the console script and ``python -m vgtarm``).

It imports nothing but the standard library's ``os``, ``signal`` and ``sys`` (and
:mod:`vgtarm.errors`, which imports nothing) and installs the Ctrl-C handling first, before the
command line (:mod:`vgtarm.app.cli.command`) pulls in NumPy, CasADi and matplotlib, which takes
the best part of a second. A Ctrl-C at any moment from here on prints the
one line ``vgtarm: interrupted`` on standard error and ends with status 130, without a traceback:

- during the imports, the import is abandoned (its ``finally`` clauses run; nothing of the
  command has been written yet) and the program ends;
- while the command runs, :func:`vgtarm.app.cli.command.main` handles it, undoing what the command had
  begun (temporary files and folders, worker processes);
- after the command has finished, during the interpreter's clean-up, the program ends at once.

SIGTERM (``kill``, a service manager, a batch system's time limit) is handled the same way, with
the line ``vgtarm: terminated`` and status 143 (128 + SIGTERM): while the command runs it raises
:class:`~vgtarm.errors.Terminated`, a ``KeyboardInterrupt``, so that everything that undoes a
Ctrl-C (temporary files and folders, worker processes, compiler runs) undoes it too; a second
SIGTERM while that clean-up runs changes nothing. Should a library swallow the exception (CasADi
does, raised inside one of its calls), the flag :attr:`~vgtarm.errors.Terminated.arrived` stays:
no writer of :mod:`vgtarm.fileio` puts a result in place after it, and the command still ends with
status 143. A SIGTERM ignored when vgtarm starts stays ignored.

What remains is the interpreter's own start-up before this module runs (loading Python, ``site``
and the console script's ``import re``; about 10-20 ms): a Ctrl-C there is handled by Python
itself (killed by SIGINT, which a shell reports as status 130 too, or a ``KeyboardInterrupt``
traceback while ``site`` and ``re`` are imported).
"""

from __future__ import annotations

import os
import signal
import sys
from types import FrameType
from typing import NoReturn

from .errors import Terminated

#: Exit status of an interrupted command (Ctrl-C): 128 + SIGINT, as a shell reports it.
INTERRUPTED = 130
#: The one line an interrupted command prints on standard error.
MESSAGE = "vgtarm: interrupted"
#: Exit status of a command ended by SIGTERM: 128 + SIGTERM, as a shell reports it.
TERMINATED = 143
#: The one line a command ended by SIGTERM prints on standard error.
TERMINATED_MESSAGE = "vgtarm: terminated"


class _State:
    """Whether a Ctrl-C arrived during start-up (set by the handler; a library may swallow the
    ``KeyboardInterrupt`` it raises, the flag stays; a SIGTERM's flag is ``Terminated.arrived``)."""

    interrupted = False


def _on_terminate(signum: int, frame: FrameType | None) -> None:
    """SIGTERM: unwind the start-up or the command once; another one while it unwinds changes nothing."""
    if Terminated.arrived:
        return
    Terminated.arrived = True
    raise Terminated


def _on_start_up_interrupt(signum: int, frame: FrameType | None) -> None:
    """SIGINT during the imports: unwind them once; a second Ctrl-C while they unwind is the same."""
    if _State.interrupted:
        return
    _State.interrupted = True
    raise KeyboardInterrupt


def _end_interrupted() -> NoReturn:
    """Print the one line and end at once with status 130, or 143 after a SIGTERM (no module teardown)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the line is printed once, whatever comes next
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe or stream: nothing more can be shown anyway
            pass
    try:
        os.write(2, f"{TERMINATED_MESSAGE if Terminated.arrived else MESSAGE}\n".encode())
    except OSError:  # standard error closed: the status still says it
        pass
    os._exit(TERMINATED if Terminated.arrived else INTERRUPTED)


def _on_late_interrupt(signum: int, frame: FrameType | None) -> None:
    """SIGINT or SIGTERM after the command returned (the interpreter's clean-up can take a second)."""
    if signum == signal.SIGTERM:
        Terminated.arrived = True
    _end_interrupted()


#: Thread counts of NumPy's BLAS, set to one unless the user set them (see single_threaded_blas).
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def single_threaded_blas() -> None:
    """Ask NumPy's BLAS for one thread, unless the environment already says otherwise; only
    effective before NumPy is imported.

    vgtarm's matrices are small, so BLAS threads never pay; but once a NumPy call has woken them,
    OpenBLAS's threads spin for a while, and on a small machine they take the cores the compiled
    loop and the GA's threads need (case 2 with the tool force under switching control: 1.92 s with
    spinning BLAS threads, 1.49 s without, in the same benchmark). :func:`vgtarm.simulate` also limits
    BLAS to one thread while it runs (threadpoolctl), but that cannot stop threads already spinning.
    """
    for name in BLAS_THREAD_VARIABLES:
        os.environ.setdefault(name, "1")


def main() -> int:
    """Run the ``vgtarm`` command line with Ctrl-C handled from the first moment; its exit status."""
    single_threaded_blas()
    ours = signal.getsignal(signal.SIGINT) is signal.default_int_handler  # not when started ignoring it
    if signal.getsignal(signal.SIGTERM) == signal.SIG_DFL:  # not when started ignoring it either
        signal.signal(signal.SIGTERM, _on_terminate)  # the same handler from start-up to the end
    if ours:
        signal.signal(signal.SIGINT, _on_start_up_interrupt)
    try:
        from .app import cli
    except BaseException:  # a KeyboardInterrupt, or whatever a library turned it into
        if _State.interrupted or Terminated.arrived:
            _end_interrupted()
        raise
    if _State.interrupted or Terminated.arrived:  # a library swallowed the KeyboardInterrupt: still stop
        _end_interrupted()
    try:
        if ours:
            signal.signal(signal.SIGINT, signal.default_int_handler)  # cli.main handles KeyboardInterrupt
        try:
            return cli.main()
        finally:  # a status, or SystemExit from --help or a usage error
            if ours:
                signal.signal(signal.SIGINT, _on_late_interrupt)
            if signal.getsignal(signal.SIGTERM) is _on_terminate:
                signal.signal(signal.SIGTERM, _on_late_interrupt)
    except KeyboardInterrupt:  # between the hand-over and cli.main's own handling, either side
        _end_interrupted()
