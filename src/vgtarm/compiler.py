"""Running a C compiler (or ``make``) for vgtarm: under a time limit, in a process group of its own
that dies with vgtarm, however vgtarm ends.

Every compiler vgtarm runs goes through :func:`run` (or :func:`compile_checked`): the model's
build (:mod:`vgtarm.model.compiled`, inside its build process), the recursive model's library
(:mod:`vgtarm.model.recursive.library`), the export's check compile and harnesses
(:mod:`vgtarm.export.controller`) and the test suite's ``make``.

- **Time limit** per command: ``$VGTARM_COMPILER_TIME_LIMIT`` seconds (a number > 0; another value
  is a :class:`~vgtarm.errors.ConfigError` naming the variable and the value), else the caller's
  default: :data:`CHECK_TIME_LIMIT` (2 min) for the export's check compile of small files and its
  harnesses, a generous multiple of the estimated compile for a model's build and for the export
  of a large stack (:func:`vgtarm.model.budget.compiler_limit`), 10 min for a whole ``make`` in the
  tests. A command that runs longer is killed, with its children, and ends in one line naming the
  program, the limit and the variable.
- **Its own process group, dying with vgtarm.** The command runs under a tiny supervisor, a
  Python process started in a session of its own (so a terminal's Ctrl-C reaches vgtarm alone),
  that starts the command in its process group and ends the whole group (``killpg`` with
  ``SIGKILL``: the compiler, ``cc1``, ``as``, ``ld`` and any background child of a compiler
  script) when the command exits, when its parent ends (the kernel's parent-death signal,
  ``PR_SET_PDEATHSIG``, where there is one, and the end of a pipe from the parent, which the
  supervisor reads: the pipe ends however the parent ends, ``SIGKILL`` included) or when it is
  sent ``SIGTERM``, ``SIGHUP`` or ``SIGINT``. vgtarm itself kills the group on the time limit, on
  Ctrl-C (``KeyboardInterrupt``) or any other exception while it waits, and re-raises; a compiler
  that ignores ``SIGINT`` and ``SIGTERM`` is killed all the same. Only a child that leaves the
  group on purpose (``setsid``) escapes.
- **Output through files**: the command's standard output and error go to two unnamed temporary
  files (not pipes), read when it has ended, so a background child that keeps them open cannot
  make the wait outlast the limit; its standard input is ``/dev/null``.
- A compiler that exits 0 but writes no output file, or an empty one, has failed
  (:func:`compile_checked`): one line saying so, never a success.
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import IO

from .errors import ConfigError, VgtarmError, cut, shown

#: The variable that sets the longest one compiler command may run (seconds).
TIME_LIMIT_VARIABLE = "VGTARM_COMPILER_TIME_LIMIT"
#: Default limit (s) of a command on small C files: the export's check compile and harnesses.
CHECK_TIME_LIMIT = 120.0
#: Most of a command's standard output or error read back (bytes); the rest is left unread.
_MAX_OUTPUT = 1 << 20
#: Longest wait (s) for the supervisor to go once its group was killed.
_REAP_WAIT = 5.0

#: The supervisor (run by ``python -I -S -c``; the standard library only, started in a session of
#: its own): ``PARENT_PID STDOUT_FD STDERR_FD COMMAND...``. It ends its whole process group when
#: its parent ends (parent-death signal, end of its standard input) or on SIGTERM, SIGHUP or
#: SIGINT; else it starts the command, waits for it, reports ``status N`` (or ``error TEXT`` when
#: it cannot start) on its standard output and ends its group, itself included.
_SUPERVISOR = r"""
import os, signal, sys, threading

def end(*_):
    os.killpg(0, signal.SIGKILL)

for number in (signal.SIGTERM, signal.SIGHUP, signal.SIGINT):
    signal.signal(number, end)
try:
    import ctypes
    ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
except (ImportError, OSError, AttributeError):
    pass  # no parent-death signal here: the end of the pipe below still says it
parent, out, err, command = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4:]
if os.getppid() != parent:  # the parent ended before the signal was asked for
    end()

def watch():
    try:
        while os.read(0, 4096):
            pass
    finally:
        end()

threading.Thread(target=watch, daemon=True).start()
try:
    actions = [
        (os.POSIX_SPAWN_OPEN, 0, os.devnull, os.O_RDONLY, 0),
        (os.POSIX_SPAWN_DUP2, out, 1),
        (os.POSIX_SPAWN_DUP2, err, 2),
        (os.POSIX_SPAWN_CLOSE, out),
        (os.POSIX_SPAWN_CLOSE, err),
    ]
    defaults = [signal.SIGPIPE, signal.SIGXFSZ, signal.SIGINT, signal.SIGTERM, signal.SIGHUP]
    pid = os.posix_spawnp(command[0], command, os.environ, file_actions=actions, setsigdef=defaults)
    report = f"status {os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1])}"
except OSError as exc:
    report = f"error {exc.strerror or exc}"
os.write(1, report.encode(errors="replace"))
end()
"""


class CompilerError(VgtarmError, RuntimeError):
    """A compiler (or ``make``) could not run, failed, ran past its limit or wrote nothing; the
    message is one line naming it."""


class CompilerTimeout(CompilerError):
    """The command ran longer than its time limit; it was killed with every child."""


def time_limit(default: float = CHECK_TIME_LIMIT) -> float:
    """The longest one compiler command may run (s): ``$VGTARM_COMPILER_TIME_LIMIT`` (empty counts
    as unset), else ``default``.

    Raises:
        ConfigError: the variable is set but not a finite number of seconds > 0.
    """
    return seconds_setting(TIME_LIMIT_VARIABLE, default)


def seconds_setting(variable: str, default: float) -> float:
    """The environment variable ``variable`` as a duration (s), ``default`` when it is unset or
    empty: the compiler's limit here and the model build's (:func:`vgtarm.model.budget.time_limit`).

    Raises:
        ConfigError: the variable is set but not a finite number of seconds > 0.
    """
    text = os.environ.get(variable, "")
    if not text.strip():
        return float(default)
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise ConfigError(f"{variable} = {shown(text)}: expected a number of seconds > 0")
    return value


def _read(stream: IO[bytes]) -> str:
    stream.seek(0)
    return stream.read(_MAX_OUTPUT).decode(errors="replace")


def _end(process: subprocess.Popen[bytes]) -> None:
    """Kill the supervisor's whole process group (the command and its children) and reap it."""
    if process.returncode is None:  # not reaped: its pid, the group's id, is still its own
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(process.pid, signal.SIGKILL)
    with contextlib.suppress(subprocess.TimeoutExpired):
        process.wait(timeout=_REAP_WAIT)


def _close(process: subprocess.Popen[bytes]) -> None:
    for stream in (process.stdin, process.stdout, process.stderr):
        if stream is not None:
            with contextlib.suppress(OSError):
                stream.close()


def run(
    command: Sequence[str],
    *,
    limit: float | None = None,
    cwd: str | os.PathLike[str] | None = None,
    program: str = "the C compiler",
    what: str = "",
) -> subprocess.CompletedProcess[str]:
    """Run ``command`` (a compiler or ``make``) under the time limit, in a process group of its own
    that dies with this process (module docstring); what it did: its exit status (negative: killed
    by that signal) and its standard output and error (the first MiB of each).

    ``limit`` is the default of :func:`time_limit` (None: :data:`CHECK_TIME_LIMIT`);
    ``program`` and ``what`` name the command and its input in messages
    (``"the C compiler 'cc' ... on what"``).

    Raises:
        CompilerTimeout: it ran past the limit (killed with every child).
        CompilerError: it could not be started.
        ConfigError: ``$VGTARM_COMPILER_TIME_LIMIT`` is not a number of seconds > 0.
        KeyboardInterrupt: (or any exception while it runs) after its whole group was killed.
    """
    seconds = time_limit(CHECK_TIME_LIMIT if limit is None else limit)
    command = [str(part) for part in command]
    name = f"{program} {shown(command[0], 80)}"
    on = f" on {what}" if what else ""
    if not sys.executable:
        raise CompilerError(f"cannot run {name}: no Python interpreter to supervise it (sys.executable is empty)")
    with contextlib.ExitStack() as stack:
        try:
            out = stack.enter_context(tempfile.TemporaryFile())
            err = stack.enter_context(tempfile.TemporaryFile())
            supervisor = [sys.executable, "-I", "-S", "-c", _SUPERVISOR, str(os.getpid()), str(out.fileno())]
            process = subprocess.Popen(
                [*supervisor, str(err.fileno()), *command],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                cwd=cwd,
                pass_fds=(out.fileno(), err.fileno()),
                start_new_session=True,
            )
        except OSError as exc:
            raise CompilerError(f"cannot run {name}: {exc.strerror or exc}") from None
        stack.callback(_close, process)  # after its end: the supervisor takes a closed pipe for the end of vgtarm
        try:
            process.wait(timeout=seconds)
        except subprocess.TimeoutExpired:
            _end(process)
            raise CompilerTimeout(
                f"{name} ran longer than the limit of {seconds:g} s{on} ({TIME_LIMIT_VARIABLE} sets it, in seconds)"
            ) from None
        except BaseException:  # Ctrl-C included: nothing of it is left running
            _end(process)
            raise
        assert process.stdout is not None and process.stderr is not None
        report = process.stdout.read(4096).decode(errors="replace")  # EOF: the supervisor has ended
        complaint = process.stderr.read(4096).decode(errors="replace")
        kind, _, detail = report.partition(" ")
        if kind == "error":
            raise CompilerError(f"cannot run {name}: {cut(detail, 160)}")
        if kind != "status" or not detail.lstrip("-").isdigit():
            lines = [line.strip() for line in complaint.splitlines() if line.strip()]
            why = f": {cut(lines[-1], 160)}" if lines else ""
            raise CompilerError(f"{name} was stopped{on}: its supervisor ended with status {process.returncode}{why}")
        return subprocess.CompletedProcess(command, int(detail), _read(out), _read(err))


def first_error(done: subprocess.CompletedProcess[str]) -> str:
    """The line of a failed command's standard error to show: the first that mentions an error,
    else the last, cut to one short line."""
    lines = [line.strip() for line in done.stderr.splitlines() if line.strip()]
    first = next((line for line in lines if "error" in line.lower()), lines[-1] if lines else "no message")
    return cut(first, 160)


def ending(status: int) -> str:
    """A command's exit status for a message: ``exit status 1``, ``killed by SIGSEGV``."""
    if status < 0:
        try:
            return f"killed by {signal.Signals(-status).name}"
        except ValueError:
            return f"killed by signal {-status}"
    return f"exit status {status}"


def output_of(command: Sequence[str]) -> Path | None:
    """The file a compiler command writes (its ``-o`` argument), or None."""
    parts = list(command)
    for i, part in enumerate(parts[:-1]):
        if part == "-o":
            return Path(parts[i + 1])
    return None


def product(command: Sequence[str]) -> str:
    """What a compiler command makes, for a message: an object file (``-c``), a library
    (``-shared``) or a program."""
    return "object file" if "-c" in command else "library" if "-shared" in command else "program"


def wrote_nothing(command: Sequence[str]) -> bool:
    """Whether a command that exited 0 left its output (``-o``) missing, empty or not a file."""
    output = output_of(command)
    if output is None:
        return False
    try:
        return not (output.is_file() and output.stat().st_size > 0)
    except OSError:
        return True


def compile_checked(
    command: Sequence[str],
    *,
    limit: float | None = None,
    cwd: str | os.PathLike[str] | None = None,
    program: str = "the C compiler",
    what: str = "",
) -> subprocess.CompletedProcess[str]:
    """:func:`run` a compiler command and hold it to its word: a non-zero exit is a
    :class:`CompilerError` with the first error line, and so is an exit 0 that left the output file
    (``-o``) missing or empty."""
    done = run(command, limit=limit, cwd=cwd, program=program, what=what)
    name = f"{program} {shown(str(command[0]), 80)}"
    on = f" on {what}" if what else ""
    if done.returncode != 0:
        raise CompilerError(f"{name} failed{on} ({ending(done.returncode)}): {first_error(done)}")
    if wrote_nothing(command):
        raise CompilerError(f"{name} exited 0 but wrote no {product(command)}{on}")
    return done
