"""The record of one closed-loop run: time series, GA activations and a summary."""

from __future__ import annotations

import io
import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError, cut
from ..fileio import atomic_folder, atomic_write_text, check_input_folder, json_value, open_input, read_text_limited
from ..kinds import found_columns
from ..markup import html_table
from ..model.parameters import JOINT_NAMES

if TYPE_CHECKING:
    from ..model.robot import Robot
    from .reference import JointReference

Array = NDArray[np.float64]

#: The files :meth:`SimulationResult.save` writes (and the figure ``vgtarm simulate`` adds): an
#: existing folder of only these, written before folders listed their files, may be replaced.
RUN_FILES = ("summary.json", "timeseries.csv", "ga_activations.csv", "figure.png", "robot.toml")
#: The copy of the robot file a run was made with (``vgtarm simulate --config``, ``vgtarm reproduce
#: --config``), by which ``vgtarm animate`` and ``vgtarm report`` find the run's robot.
ROBOT_COPY = "robot.toml"

#: Controller mode per sample.
MODE_FIXED, MODE_GA, MODE_NOT_RUN = 0, 1, -1


@dataclass(frozen=True)
class GAActivation:
    """One call of the genetic algorithm by the switching method."""

    sample: int
    time_s: float
    generations: int
    evaluations: int
    best_fitness: float
    fixed_gains_fitness: float
    error_before_m: float
    error_after_m: float
    wall_time_s: float


@dataclass(frozen=True, eq=False)
class SimulationResult:
    """Time series of a run (N samples at period ``dt``) and what happened.

    Arrays: ``t`` (N,); ``tip_desired``, ``tip`` (N, 3) m; ``tip_error`` (N,) m (``|P(q_d) -
    P(q)|``); ``q_desired``, ``qd_desired``, ``q``, ``qd`` (N, 7); ``effort`` (N, 7) N and N m;
    ``f_ext`` (N, 3) N, the force on the tool; ``mode`` (N,) 0 fixed gains, 1 GA gains, -1 not
    reached. Samples after a failure are NaN (``mode == -1``).

    How it ended: ``success`` (every sample reached), ``status`` (``"completed"``, or what stopped
    it: ``"not_finite"``, ``"not_assemblable"``, ``"outside_limits"``, ``"function_failed"``,
    ``"no_memory"``), ``message`` (one line), ``wall_time_s``; :func:`~vgtarm.simulation.simulate`
    with ``check=False`` returns a failed run with its arrays up to the failure.

    With a disturbance observer or a force sensor, ``effort_estimate`` (N, 7) N and N m holds the
    estimated external joint efforts the controller subtracted; with realistic sensing,
    ``tip_error_measured`` (N,) m is the tip error the controller saw, ``|P(q_d) - P(q_meas)|``
    (``tip_error`` is always the true one). Both are None otherwise.

    Where it came from: ``robot``, the simulated :class:`~vgtarm.Robot` (the plant), and
    ``reference``, the :class:`~vgtarm.simulation.reference.JointReference` it followed (an IK
    result given as the reference, wrapped); None for a run read back by :meth:`load`. The robot
    is not pickled (it holds its compiled library): a run sent to another process keeps its
    names in :attr:`metadata` (``plant``, ``reference``).
    """

    t: Array
    tip_desired: Array
    tip: Array
    tip_error: Array
    q_desired: Array
    qd_desired: Array
    q: Array
    qd: Array
    effort: Array
    f_ext: Array
    mode: NDArray[np.int8]
    activations: tuple[GAActivation, ...]
    success: bool
    message: str
    wall_time_s: float
    ga_time_s: float
    metadata: Mapping[str, Any] = field(default_factory=dict)
    effort_estimate: Array | None = None
    tip_error_measured: Array | None = None
    status: str = "completed"
    robot: Robot | None = None
    reference: JointReference | None = None

    def __getstate__(self) -> dict[str, Any]:
        """The pickled state: everything but :attr:`robot` (its compiled library does not pickle)."""
        return {**self.__dict__, "robot": None}

    @property
    def dt(self) -> float:
        """Control period (s): the run's recorded ``dt_s``, else the first step of ``t`` (NaN for a
        run of one sample that records none)."""
        if "dt_s" in self.metadata:
            return float(self.metadata["dt_s"])
        return float(self.t[1] - self.t[0]) if len(self.t) >= 2 else float("nan")

    @property
    def completed(self) -> int:
        """Number of samples reached."""
        return int(np.count_nonzero(self.mode != MODE_NOT_RUN))

    def summary(self) -> dict[str, Any]:
        """Figures of the run, as written to ``summary.json``."""
        n = self.completed
        err = self.tip_error[:n]
        transient = float(self.metadata.get("transient_s", 0.2))
        after = err[self.t[:n] >= self.t[0] + transient]
        twist = np.array([name.startswith("psi") for name in self.joint_names])  # N m; the legs' efforts: N
        forces = self.effort[:n, :6] if self.joint_names == JOINT_NAMES else self.effort[:n, ~twist]
        torque = self.effort[:n, 6] if self.joint_names == JOINT_NAMES else self.effort[:n, twist]
        summary: dict[str, Any] = {key: self.metadata[key] for key in self.metadata}
        summary.update(
            success=self.success,
            status=self.status,
            message=self.message,
            samples=len(self.t),
            samples_completed=n,
            simulated_time_s=float(self.t[n - 1] - self.t[0]) if n else 0.0,
            wall_time_s=self.wall_time_s,
            real_time_factor=(float(self.t[n - 1] - self.t[0]) / self.wall_time_s)
            if n and self.wall_time_s > 0
            else None,
            max_tip_error_m=_max(err),
            rms_tip_error_m=_rms(err),
            max_tip_error_after_transient_m=_max(after),
            rms_tip_error_after_transient_m=_rms(after),
            time_of_max_tip_error_s=float(self.t[int(np.nanargmax(err))]) if (~np.isnan(err)).any() else None,
            peak_force_n=_max(np.abs(forces)),
            rms_force_n=_rms(forces),
            peak_twist_torque_nm=_max(np.abs(torque)),
            **force_figures(forces, torque, self.effort[:n], self.qd[:n], self.dt),
            peak_external_force_n=_max(np.linalg.norm(self.f_ext[:n], axis=1)),
            ga_activations=len(self.activations),
            ga_time_s=self.ga_time_s,
            ga_time_per_activation_s=self.ga_time_s / len(self.activations) if self.activations else None,
            ga_activation_time_median_s=_percentile(self.activations, 50.0),
            ga_activation_time_p99_s=_percentile(self.activations, 99.0),
            time_in_ga_mode_s=float(np.count_nonzero(self.mode == MODE_GA) * self.dt),
            **self.tool_figures(),
        )
        return summary

    def tool_figures(self) -> dict[str, Any]:
        """A tool task's figures (:mod:`vgtarm.ik.axis`; the pose task too): the largest and RMS angle
        of the tool's axis from its desired axis (that of the desired joints, as the tip error is
        ``|P(q_d) - P(q)|``), after the transient too, and with an entry point the largest distance of
        the axis from it; none for a run whose reference is the tip alone or whose robot is unknown (a
        run sent back from another process: keep them in its ``metadata`` there, for its summary)."""
        reference, robot, n = self.reference, self.robot, self.completed
        if reference is None or reference.task in ("position", "") or robot is None or n == 0:
            return {}
        from ..ik.axis import axis_error, entry_distance

        tip, rotation = robot.tool_frame(self.q[:n])
        axes = rotation[:, :, 2]
        error = axis_error(axes, robot.tool_axis(self.q_desired[:n]))
        transient = float(self.metadata.get("transient_s", 0.2))
        after = error[self.t[:n] >= self.t[0] + transient]
        figures: dict[str, Any] = {
            "max_axis_error_rad": _max(error),
            "rms_axis_error_rad": _rms(error),
            "max_axis_error_after_transient_rad": _max(after),
        }
        if reference.entry_point is not None:
            figures["max_entry_distance_m"] = _max(entry_distance(tip, axes, np.asarray(reference.entry_point)))
        return figures

    def _repr_html_(self) -> str:
        """The run in a notebook: its main figures as a table and a small plot of the tip error
        (an inline PNG), every value escaped."""
        s = self.summary()
        keys = (
            "controller",
            "reference",
            "case",
            "success",
            "message",
            "simulated_time_s",
            "real_time_factor",
            "max_tip_error_m",
            "rms_tip_error_m",
            "max_tip_error_after_transient_m",
            "peak_force_n",
            "rms_force_n",
            "ga_activations",
        )
        rows: list[list[object]] = [[k, f"{s[k]:.6g}" if isinstance(s[k], float) else s[k]] for k in keys if k in s]
        return html_table(("figure", "value"), rows, caption="simulation run") + self._error_png()

    def _error_png(self) -> str:
        """A small inline plot of the tip error (mm) over time, as an ``<img>`` with a data URL."""
        import base64
        import io

        from matplotlib.figure import Figure

        figure = Figure(figsize=(5.0, 2.0), dpi=80)
        ax = figure.add_subplot()
        ax.plot(self.t, self.tip_error * 1e3, linewidth=0.8)
        ax.set_xlabel("t (s)")
        ax.set_ylabel("tip error (mm)")
        figure.tight_layout()
        buffer = io.BytesIO()
        figure.savefig(buffer, format="png")
        data = base64.b64encode(buffer.getvalue()).decode("ascii")
        return f'<img alt="tip error over time" src="data:image/png;base64,{data}"/>'

    def to_dataframe(self) -> Any:
        """The time series as a :class:`pandas.DataFrame`, one row per sample and the columns of
        ``timeseries.csv`` (``t``, the tip, the joints, the efforts, ...; SI units). Needs pandas
        (``pip install "vgtarm[dataframe]"``)."""
        pandas = _pandas()
        columns, table = self._table()
        frame = pandas.DataFrame(table, columns=columns)
        frame["mode"] = self.mode
        return frame

    def plot(self, ax: Any = None) -> Any:
        """The tip error (mm) against time, into ``ax`` (a new figure's axes when None); returns the
        axes. Samples not reached (a failed run) are left out. The comparison of several runs is
        :func:`vgtarm.comparison_figure`."""
        if ax is None:
            from matplotlib.figure import Figure

            ax = Figure(figsize=(6.0, 3.0), layout="constrained").add_subplot()
        label = str(self.metadata.get("controller", "run"))
        ax.plot(self.t, self.tip_error * 1e3, linewidth=0.9, label=label)
        ax.set_xlabel("t (s)")
        ax.set_ylabel("tip error (mm)")
        if not self.success:
            ax.set_title(f"stopped: {self.status}")
        return ax

    def save(self, folder: str | Path) -> Path:
        """Write ``timeseries.csv``, ``ga_activations.csv`` and ``summary.json`` into ``folder``.

        The folder is written as one unit (:func:`vgtarm.fileio.atomic_folder`): into a temporary
        sibling that replaces ``folder`` whole when complete, so it never mixes files of two runs
        and an error leaves the old folder as it was. An existing ``folder`` that holds files
        vgtarm did not write is refused (:class:`~vgtarm.errors.InputError`), never deleted.
        """
        columns, table = self._table()
        act_columns = list(GAActivation.__dataclass_fields__)
        act_rows = np.array([[getattr(a, c) for c in act_columns] for a in self.activations], dtype=float)
        summary = json.dumps(json_value(self.summary()), indent=2) + "\n"
        with atomic_folder(folder, "folder", owned=RUN_FILES) as out:
            atomic_write_text(out / "timeseries.csv", _csv(columns, table))
            atomic_write_text(out / "ga_activations.csv", _csv(act_columns, act_rows.reshape(-1, len(act_columns))))
            atomic_write_text(out / "summary.json", summary)
        return Path(folder)

    @classmethod
    def load(cls, folder: str | Path) -> SimulationResult:
        """Read back a run written by :meth:`save` (``timeseries.csv``, ``ga_activations.csv``,
        ``summary.json``); ``load(save(r))`` holds the same arrays, activations and summary as ``r``.

        Raises :class:`~vgtarm.errors.InputError` naming the file when the folder does not hold a
        complete, readable run: a file missing, not a regular file (a named pipe, a device: refused
        before it is opened), or not of its kind (a header that is not a run's, in one line saying
        what it looks like).
        """
        where = Path(folder)
        check_input_folder(where, "run folder")
        summary_file, table_file = where / "summary.json", where / "timeseries.csv"
        for file in (summary_file, table_file):
            if not os.path.lexists(file):
                raise InputError(
                    f"run folder {cut(str(where), 200)}: missing {file.name} (expected a folder written by save())"
                )
        summary = _read_summary(summary_file)
        joints = [str(n) for n in summary.get("joint_names", JOINT_NAMES)]  # a stack's run records its joints
        layouts = [cls._columns(estimate, measured, joints) for estimate in (False, True) for measured in (False, True)]
        header, table = _read_table(table_file, layouts, "a run's time series (timeseries.csv)")
        _check_summary(summary_file, summary)
        columns = header
        index = {name: i for i, name in enumerate(columns)}

        def block(names: list[str]) -> Array:
            return np.ascontiguousarray(table[:, [index[n] for n in names]])

        activations: list[GAActivation] = []
        act_file = where / "ga_activations.csv"
        if os.path.lexists(act_file):
            fields = GAActivation.__dataclass_fields__
            _, rows = _read_table(act_file, [list(fields)], "a run's GA activations (ga_activations.csv)")
            whole = [name for name in fields if fields[name].type in (int, "int")]
            if not np.isfinite(rows[:, [list(fields).index(n) for n in whole]]).all():
                raise InputError(
                    f"run file {cut(str(act_file), 200)}: {', '.join(whole)}: expected whole numbers in every row"
                )
            for row in rows:
                values: dict[str, Any] = {
                    name: int(v) if fields[name].type in (int, "int") else float(v)
                    for name, v in zip(fields, row, strict=True)
                }
                activations.append(GAActivation(**values))
        mode = np.nan_to_num(table[:, index["mode"]], nan=MODE_NOT_RUN).astype(np.int8)
        loaded = cls(
            t=block(["t"])[:, 0],
            tip_desired=block(["x_d", "y_d", "z_d"]),
            tip=block(["x", "y", "z"]),
            tip_error=block(["tip_error"])[:, 0],
            q_desired=block([f"{n}_d" for n in joints]),
            qd_desired=block([f"d{n}_d" for n in joints]),
            q=block(joints),
            qd=block([f"d{n}" for n in joints]),
            effort=block([f"F_{n}" for n in joints]),
            f_ext=block(["fx", "fy", "fz"]),
            mode=mode,
            activations=tuple(activations),
            success=bool(summary["success"]),
            status=str(summary.get("status", "completed" if summary["success"] else "failed")),
            message=str(summary["message"]),
            wall_time_s=float(summary["wall_time_s"]),
            ga_time_s=float(summary["ga_time_s"]),
            effort_estimate=block([f"tau_hat_{n}" for n in joints]) if "tau_hat_" + joints[0] in index else None,
            tip_error_measured=block(["tip_error_measured"])[:, 0] if "tip_error_measured" in index else None,
            # a stack's joints, for the figures computed below (a planar module has fewer than the paper's 7)
            metadata={"joint_names": joints} if "joint_names" in summary else {},
        )
        # the summary is the metadata updated with figures computed from the arrays: keep the rest
        computed = set(loaded.summary()) - set(loaded.metadata)
        return replace(loaded, metadata={k: v for k, v in summary.items() if k not in computed})

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The robot's joint names (a stack's run records them in its metadata; else the paper's)."""
        names = self.metadata.get("joint_names")
        return tuple(str(n) for n in names) if names else JOINT_NAMES

    @staticmethod
    def _columns(estimate: bool = False, measured: bool = False, joints: Sequence[str] = JOINT_NAMES) -> list[str]:
        columns = ["t", "x_d", "y_d", "z_d", "x", "y", "z", "tip_error"]
        columns += [f"{n}_d" for n in joints] + list(joints)
        columns += [f"d{n}_d" for n in joints] + [f"d{n}" for n in joints]
        columns += [f"F_{n}" for n in joints] + ["fx", "fy", "fz", "mode"]
        columns += [f"tau_hat_{n}" for n in joints] if estimate else []
        columns += ["tip_error_measured"] if measured else []
        return columns

    def _table(self) -> tuple[list[str], Array]:
        estimate, measured = self.effort_estimate is not None, self.tip_error_measured is not None
        columns = self._columns(estimate, measured, self.joint_names)
        extra = [a for a in (self.effort_estimate, self.tip_error_measured) if a is not None]
        table = np.column_stack(
            [
                self.t,
                self.tip_desired,
                self.tip,
                self.tip_error,
                self.q_desired,
                self.q,
                self.qd_desired,
                self.qd,
                self.effort,
                self.f_ext,
                self.mode.astype(float),
                *extra,
            ]
        )
        return columns, table


#: Largest ``summary.json`` of a run read (bytes): a few kilobytes.
SUMMARY_LIMIT = 2**20
#: What a run's ``summary.json`` holds at least.
SUMMARY_KEYS = ("success", "message", "wall_time_s", "ga_time_s")


def _read_summary(file: Path) -> dict[str, Any]:
    """The parsed ``summary.json`` of a run: a JSON table, or one line naming the file."""
    text = read_text_limited(file, SUMMARY_LIMIT, "run file")
    shown_file = cut(str(file), 200)
    try:
        summary = json.loads(text)
    except (ValueError, RecursionError):
        raise InputError(f"run file {shown_file}: not JSON; expected a run's summary.json (from save())") from None
    if not isinstance(summary, dict):
        raise InputError(f"run file {shown_file}: not a table of figures; expected a run's summary.json")
    return summary


def _check_summary(file: Path, summary: Mapping[str, Any]) -> None:
    """Refuse, in one line naming the file, a summary without the figures a run records."""
    missing = [key for key in SUMMARY_KEYS if key not in summary]
    if missing:
        raise InputError(
            f"run file {cut(str(file), 200)}: no {missing[0]!r}; expected a run's summary.json (with"
            f" {', '.join(SUMMARY_KEYS)}, from save())"
        )


def _read_table(file: Path, layouts: Sequence[list[str]], kind: str) -> tuple[list[str], Array]:
    """The header (one of ``layouts``) and the rows ``(n, columns)`` of the CSV table ``file``,
    which must be a regular file (:func:`~vgtarm.fileio.open_input`); else one line naming the
    file, what was expected and what was found (never quoting it)."""
    shown_file = cut(str(file), 200)
    with open_input(file, "run file") as raw:
        stream = io.TextIOWrapper(raw, encoding="utf-8", newline="")
        try:
            first = stream.readline(1 << 20)
        except UnicodeDecodeError as exc:
            raise InputError(f"run file {shown_file}: not utf-8 text (byte {exc.start} cannot be decoded)") from None
        header = [cell.strip() for cell in first.rstrip("\r\n").split(",")]
        if header not in layouts:
            expected = layouts[0]
            raise InputError(
                f"run file {shown_file}: columns do not match {kind}: expected the {len(expected)} columns"
                f" {', '.join(expected[:4])}, ...; {found_columns(header, text=first, expected=kind.split(' (')[0])}"
            )
        try:
            rows = stream.read()
            table = (
                np.genfromtxt(io.StringIO(rows), delimiter=",", dtype=float, ndmin=2)
                if rows.strip()
                else np.empty((0, len(header)))
            )
        except UnicodeDecodeError as exc:
            raise InputError(f"run file {shown_file}: not utf-8 text (byte {exc.start} cannot be decoded)") from None
        except ValueError:  # rows of other lengths than the header
            raise InputError(
                f"run file {shown_file}: a row of another length than its header of {len(header)} columns"
            ) from None
        except OSError as exc:
            raise InputError(f"run file {shown_file}: cannot read it: {cut(exc.strerror or str(exc), 120)}") from None
    if table.shape[1:] != (len(header),):
        raise InputError(
            f"run file {shown_file}: rows of {table.shape[1]} values under a header of {len(header)} columns"
        )
    return header, table


def _pandas() -> Any:
    """pandas, or :class:`ImportError` saying which extra brings it."""
    try:
        import pandas
    except ImportError:
        raise ImportError('to_dataframe() needs pandas: pip install "vgtarm[dataframe]"') from None
    return pandas


def force_figures(forces: Array, torque: Array, effort: Array, qd: Array, dt: float) -> dict[str, Any]:
    """Figures of the actuator efforts of a run (issue 22), from the arrays.

    ``forces`` ``(N, legs)`` leg forces (N), ``torque`` ``(N,)`` or ``(N, twists)`` twist torques (N m),
    ``effort`` and ``qd`` ``(N, n)`` every joint's effort and rate, ``dt`` the control period (s).

    - ``rms_force_per_leg_n``, ``peak_force_per_leg_n``: per leg, over the run;
    - ``rms_twist_torque_nm``;
    - ``chatter_n``: RMS of the change of the leg forces from one period to the next (over every
      leg and period), the "vibration on the actuators" the paper warns of;
    - ``actuator_energy_j``: ``dt sum_k sum_i |F_i qd_i|``, the rectangle rule of the integral of the
      absolute actuator power (legs and twist; energy spent, none recovered).
    """
    per_leg_rms = [_rms(forces[:, j]) for j in range(forces.shape[1])]
    per_leg_peak = [_max(np.abs(forces[:, j])) for j in range(forces.shape[1])]
    change = np.diff(forces, axis=0)
    power = np.abs(effort * qd).sum(axis=1)
    known = power[~np.isnan(power)]
    return {
        "rms_force_per_leg_n": per_leg_rms,
        "peak_force_per_leg_n": per_leg_peak,
        "rms_twist_torque_nm": _rms(torque),
        "chatter_n": _rms(change) if change.size else None,
        "actuator_energy_j": float(known.sum() * dt) if known.size else None,
    }


def _percentile(activations: tuple[GAActivation, ...], q: float) -> float | None:
    """Percentile ``q`` of the activations' wall times (s), or None without activations."""
    if not activations:
        return None
    return float(np.percentile([a.wall_time_s for a in activations], q))


def _max(values: Array) -> float | None:
    """Largest value that is not NaN, or None if there is none (a run failed at its first sample)."""
    known = values[~np.isnan(values)]
    return float(np.max(known)) if known.size else None


def _rms(values: Array) -> float | None:
    """Root mean square of the values that are not NaN, or None if there is none."""
    known = values[~np.isnan(values)]
    with np.errstate(over="ignore"):  # a diverged run's huge values give inf, as they should
        return float(np.sqrt(np.mean(np.square(known)))) if known.size else None


def _csv(columns: list[str], table: Array) -> str:
    """CSV text: 17 significant digits (exact round trip), empty fields for NaN.

    One ``%`` format per row (most of ``vgtarm reproduce``'s time went into formatting numbers
    one by one); only the rows that hold a NaN are formatted field by field, to leave those empty.
    """
    values = np.asarray(table, dtype=float).reshape(len(table), len(columns))
    rows = values.tolist()
    row_format = ",".join(["%.17g"] * len(columns))
    lines = [row_format % tuple(row) for row in rows]
    for i in np.flatnonzero(np.isnan(values).any(axis=1)).tolist():
        lines[i] = ",".join("" if v != v else f"{v:.17g}" for v in rows[i])
    return ",".join(columns) + "\n" + ("\n".join(lines) + "\n" if lines else "")
