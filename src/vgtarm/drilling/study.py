"""Drilling studies (issue 38): many closed-loop drilling runs over seeded bones, feeds, set points,
modes and feedbacks, one row of measures per run, their spread and how many runs meet the targets
(``docs/drilling_study.md``).

A :class:`DrillingStudy` names the nominal bones, the seeds (each seed perturbs every layer's
thickness and density by up to ``spread``, :func:`~.loop.perturbed_bone`), the feed limit (a
uniform draw per seed in :data:`FEED_RANGE`, or fixed values), the set points, the modes and the
feedbacks, and the settings every run shares. Its points are every combination; a point's drawn
feed comes from the generator of ``[FEED_STREAM, seed]``, a stream of its own (the bone's
perturbation uses the generator of ``seed`` itself: with the same stream the feed would be the
first layer's thickness factor, rescaled). The same study gives the same points and the same rows.

:func:`run_drilling_study` drills each point's perturbed bone with :func:`~.loop.drilling_run`, the
detector told only the nominal bone (``nominal=``), in this process or in worker processes, and
returns a :class:`DrillingStudyResult`: its ``rows``, :meth:`~DrillingStudyResult.table` (CSV),
:meth:`~DrillingStudyResult.spread`, :meth:`~DrillingStudyResult.within_targets` and
:meth:`~DrillingStudyResult.figure`. Study files: :func:`load_drilling_study` (a ``[drilling_study]``
table, ``examples/studies/drilling_bones.toml``).
"""

from __future__ import annotations

import csv
import dataclasses
import io
import itertools
import math
import multiprocessing
import os
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, TypeVar

import numpy as np

from .. import checks
from ..errors import ConfigError, InputError, cut
from ..fileio import parse_toml, read_text_limited
from ..markup import csv_cell, mpl_text
from ..model.robot import Robot, definition_of
from .bone import Bone, load_bone
from .control import FEEDBACKS, MODES, DrillingSettings, check_settings
from .loop import TARGETS, drilling_run, perturbed_bone

T = TypeVar("T")

#: The keys of a study file's ``[drilling_study]`` table.
STUDY_KEYS = (
    "name",
    "bones",
    "seeds",
    "spread",
    "feed_range",
    "feed_limit",
    "set_point",
    "mode",
    "feedback",
    "settings",
)
#: The settings a study sets per point (its axes); ``[drilling_study.settings]`` holds the others.
AXES = ("set_point", "feed_limit", "mode", "feedback")
#: The issue's feed range (m/s): a point's feed limit is drawn uniformly in it by default.
FEED_RANGE = (0.5e-3, 2.0e-3)
#: First entropy word of a point's feed generator, ``default_rng([FEED_STREAM, seed])`` (the issue's
#: number): a stream apart from the bone's ``default_rng(seed)``.
FEED_STREAM = 38
#: Largest study file read (bytes), most runs a study may expand to, longest name (characters).
STUDY_FILE_LIMIT = 2**20
MAX_POINTS = 100_000
NAME_LENGTH = 200
#: The measures of a row besides the per-layer ones, in the table's order.
MEASURES = (
    "thrust_error_rms_max",
    "protrusion",
    "detection_delay",
    "detection_delay_after_drop",
    "lateral_deviation_max",
    "axis_error_max",
    "transitions_missed",
    "transition_delay_max",
    "false_detections",
)
#: Per layer ``i`` of a run, the columns ``<name>_<i>`` (the summary's ``layers`` entries).
LAYER_MEASURES = ("thrust_error_rms", "thrust_mean", "at_feed_limit")
#: Each target of :data:`~.loop.TARGETS` and the row's column measured against it.
TARGET_COLUMNS = {
    "thrust_error_rms": "thrust_error_rms_max",
    "protrusion": "protrusion",
    "detection_delay": "detection_delay",
    "lateral_deviation": "lateral_deviation_max",
    "axis_error": "axis_error_max",
}


@dataclass(frozen=True)
class DrillingPoint:
    """One run of a study: its ``index`` in :meth:`DrillingStudy.points`, the nominal bone's index
    and ``label``, the ``seed`` of its perturbation and feed, and its feed limit (m/s), set point
    (N), mode and feedback."""

    index: int
    bone: int
    label: str
    seed: int
    feed_limit: float
    set_point: float
    mode: str
    feedback: str


@dataclass(frozen=True)
class DrillingStudy:
    """A drilling study: nominal ``bones`` (a :class:`~.bone.Bone` or a tuple of them; ``labels``
    name them in the rows, default their names), ``seeds`` (a count ``n`` for 0..n-1 or a sequence
    of distinct seeds), the perturbation's ``spread`` (0 to < 1), the feed limit (m/s) as a uniform
    draw per seed in ``feed_range`` (default :data:`FEED_RANGE`) or as the fixed values
    ``feed_limit`` (not both), the ``set_point`` values (N), the ``mode`` and ``feedback`` values
    (one value or a tuple each), and the ``settings`` every run shares (their set point, feed
    limit, mode and feedback are the point's). Refused in one :class:`~vgtarm.errors.InputError`
    line naming the field; :func:`load_drilling_study` reads one from a file (then a
    :class:`~vgtarm.errors.ConfigError`)."""

    bones: tuple[Bone, ...]
    seeds: tuple[int, ...] = (0,)
    spread: float = 0.3
    feed_range: tuple[float, float] | None = None
    feed_limit: tuple[float, ...] = ()
    set_point: tuple[float, ...] = (20.0,)
    mode: tuple[str, ...] = ("admittance",)
    feedback: tuple[str, ...] = ("observer",)
    settings: DrillingSettings = field(default_factory=DrillingSettings)
    labels: tuple[str, ...] = ()
    name: str = "drilling study"
    files: tuple[Path, ...] = ()  # the bone files read (a command's inputs), if from files

    def __post_init__(self) -> None:
        values = _validated({f.name: getattr(self, f.name) for f in dataclasses.fields(self)}, InputError, "")
        for key, value in values.items():
            object.__setattr__(self, key, value)

    def points(self) -> list[DrillingPoint]:
        """Every run: bones x seeds x feed limits (one drawn per seed, or each fixed value) x set
        points x modes x feedbacks, in that order."""
        points: list[DrillingPoint] = []
        for (b, label), seed in itertools.product(enumerate(self.labels), self.seeds):
            feeds = self.feed_limit or (point_feed(seed, self.feed_range or FEED_RANGE),)
            for feed, set_point, mode, feedback in itertools.product(feeds, self.set_point, self.mode, self.feedback):
                points.append(DrillingPoint(len(points), b, label, seed, feed, set_point, mode, feedback))
        return points

    def point_settings(self, point: DrillingPoint) -> DrillingSettings:
        """The settings of ``point``: :attr:`settings` with the point's set point, feed limit, mode
        and feedback."""
        return dataclasses.replace(
            self.settings,
            set_point=point.set_point,
            feed_limit=point.feed_limit,
            mode=point.mode,
            feedback=point.feedback,
        )


def point_feed(seed: int, feed_range: tuple[float, float] = FEED_RANGE) -> float:
    """The feed limit (m/s) drawn for ``seed``: uniform in ``feed_range``, with the generator of
    ``[FEED_STREAM, seed]`` (independent of the bone's perturbation, which uses ``seed``)."""
    seed = checks.seed("seed", seed)
    return float(np.random.default_rng([FEED_STREAM, seed]).uniform(*feed_range))


# -- validation -----------------------------------------------------------------------------------


def _validated(values: dict[str, Any], error: type[Exception], prefix: str) -> dict[str, Any]:
    """The fields of a study (``values``, by field name) checked and normalised (a value to a
    tuple of one, a seed count to its seeds, the default feed range); ``error`` names the field
    as ``prefix + name``."""
    out = dict(values)
    name = values["name"]
    if not isinstance(name, str) or not name.strip() or len(name) > NAME_LENGTH:
        checks.refuse(prefix + "name", name, f"a text of 1 to {NAME_LENGTH} characters", error)
    out["bones"] = bones = _bones(values["bones"], error, prefix)
    labels = values["labels"] or tuple(b.name for b in bones)
    if not isinstance(labels, tuple | list) or len(labels) != len(bones) or not all(isinstance(x, str) for x in labels):
        checks.refuse(prefix + "labels", values["labels"], f"{len(bones)} texts, one per bone", error)
    out["labels"] = tuple(labels)
    out["files"] = tuple(Path(f) for f in values["files"])
    out["seeds"] = _seeds(prefix + "seeds", values["seeds"], error)
    out["spread"] = checks.number(prefix + "spread", values["spread"], minimum=0.0, below=1.0, error=error)
    out["feed_range"], out["feed_limit"] = _feeds(values["feed_range"], values["feed_limit"], error, prefix)
    out["set_point"] = _values(prefix + "set_point", values["set_point"], error, _positive("N"))
    out["mode"] = _values(prefix + "mode", values["mode"], error, _choice(MODES))
    out["feedback"] = _values(prefix + "feedback", values["feedback"], error, _choice(FEEDBACKS))
    if not isinstance(values["settings"], DrillingSettings):
        checks.refuse(prefix + "settings", values["settings"], "a DrillingSettings", error)
    total = math.prod(len(out[k]) for k in ("bones", "seeds", "set_point", "mode", "feedback")) * max(
        1, len(out["feed_limit"])
    )
    if total > MAX_POINTS:
        checks.refuse(
            prefix + "seeds", values["seeds"], f"a study of at most {MAX_POINTS:,} runs (got {total:,})", error
        )
    return out


def _bones(value: object, error: type[Exception], prefix: str) -> tuple[Bone, ...]:
    bones = (value,) if isinstance(value, Bone) else value
    if not (isinstance(bones, tuple | list) and bones and all(isinstance(b, Bone) for b in bones)):
        checks.refuse(prefix + "bones", value, "a Bone or a non-empty tuple of them", error)
    return tuple(bones)


def _seeds(name: str, value: object, error: type[Exception]) -> tuple[int, ...]:
    """A count ``n`` (0..n-1), a sequence of distinct seeds, or ``{start = s, count = n}``."""
    expected = f"a count >= 1, a list of distinct seeds or {{start = S, count = N}} (seeds: {checks.SEED_RANGE})"
    if isinstance(value, Mapping):
        if set(value) != {"start", "count"}:
            checks.refuse(name, value, expected, error)
        start = checks.seed(f"{name}.start", value["start"], error=error)
        count = checks.whole(f"{name}.count", value["count"], 1, MAX_POINTS, error=error)
        if start + count - 1 > checks.MAX_SEED:
            checks.refuse(name, value, f"a last seed at most {checks.MAX_SEED}", error)
        return tuple(range(start, start + count))
    if checks.is_number(value) and not isinstance(value, tuple | list):
        return tuple(range(checks.whole(name, value, 1, MAX_POINTS, expected=expected, error=error)))
    if not isinstance(value, tuple | list | range) or not value:
        checks.refuse(name, value, expected, error)
    seeds = tuple(checks.seed(f"{name}[{i}]", s, error=error) for i, s in enumerate(value))
    if len(set(seeds)) != len(seeds):
        checks.refuse(name, value, "distinct seeds", error)
    return seeds


def _positive(unit: str) -> Callable[[str, object, type[Exception]], Any]:
    return lambda name, v, error: checks.positive(name, v, unit, error=error)


def _choice(choices: Sequence[str]) -> Callable[[str, object, type[Exception]], Any]:
    return lambda name, v, error: checks.choice(name, v, choices, error=error)


def _values(name: str, value: object, error: type[Exception], check: Callable[..., Any]) -> tuple[Any, ...]:
    """One value or a non-empty list of distinct values, each checked by ``check``."""
    if not isinstance(value, tuple | list):
        return (check(name, value, error),)
    if not value:
        checks.refuse(name, value, "a value or a non-empty list of values", error)
    out = tuple(check(f"{name}[{i}]", v, error) for i, v in enumerate(value))
    if len(set(out)) != len(out):
        checks.refuse(name, value, "distinct values", error)
    return out


def _feeds(
    feed_range: object, feed_limit: object, error: type[Exception], prefix: str
) -> tuple[tuple[float, float] | None, tuple[float, ...]]:
    """The feed range (drawn per seed) or the fixed feed limits (m/s): one of them."""
    limits = () if isinstance(feed_limit, tuple | list) and not feed_limit else feed_limit
    if limits != ():
        if feed_range is not None:
            checks.refuse(prefix + "feed_range", feed_range, "no range with fixed feed_limit values (give one)", error)
        return None, _values(prefix + "feed_limit", limits, error, _feed)
    if feed_range is None:
        return FEED_RANGE, ()
    low, high = checks.interval(prefix + "feed_range", feed_range, above=0.0, maximum=0.1, unit="m/s", error=error)
    return (low, high), ()


def _feed(name: str, value: object, error: type[Exception]) -> float:
    return checks.positive(name, value, "m/s", maximum=0.1, error=error)


# -- study files ----------------------------------------------------------------------------------


def load_drilling_study(file: str | os.PathLike[str]) -> DrillingStudy:
    """The study of the TOML file ``file`` (its ``[drilling_study]`` table; bone files relative to
    the study file's folder). Raises :class:`~vgtarm.errors.ConfigError`: one line naming the file
    and the field (an unknown key, a bad value, a bad bone file)."""
    text = read_text_limited(file, STUDY_FILE_LIMIT, "drilling study file", error=ConfigError)
    where = Path(file)
    data = parse_toml(text, f"drilling study file {cut(str(where), 200)}", error=ConfigError)
    return parse_drilling_study(data, source=str(where), folder=where.parent)


def parse_drilling_study(
    data: Mapping[str, Any], *, source: str = "<drilling study>", folder: Path | None = None
) -> DrillingStudy:
    """The study of a parsed study file ``data`` (bone files relative to ``folder``); one
    :class:`~vgtarm.errors.ConfigError` line ``source: drilling_study.<field> = value: expected ...``."""
    source = cut(str(source), 200)
    if not isinstance(data, Mapping) or set(data) != {"drilling_study"}:
        other = sorted(set(data) - {"drilling_study"}, key=str) if isinstance(data, Mapping) else []
        what = f"unknown table [{cut(str(other[0]))}]" if other else "no [drilling_study] table"
        raise ConfigError(f"{source}: {what}: expected a file of one [drilling_study] table")
    head = data["drilling_study"]
    prefix = f"{source}: drilling_study."
    if not isinstance(head, Mapping):
        checks.refuse(prefix[:-1], head, "a table [drilling_study]", ConfigError)
    for key in head:
        if key not in STUDY_KEYS:
            raise ConfigError(f"{prefix}{cut(str(key))}: unknown key; expected one of {list(STUDY_KEYS)}")
    names = head.get("bones")
    names = [names] if isinstance(names, str) else names
    if not (isinstance(names, list) and names and all(isinstance(n, str) and n for n in names)):
        checks.refuse(prefix + "bones", head.get("bones"), "a bone file name or a non-empty list of them", ConfigError)
    files = tuple(Path(n) if folder is None else folder / n for n in names)
    values: dict[str, Any] = {f.name: f.default for f in dataclasses.fields(DrillingStudy) if f.name != "settings"}
    values.update({k: v for k, v in head.items() if k not in ("bones", "settings")})
    values.update(bones=tuple(load_bone(f) for f in files), labels=tuple(names), files=files)
    values["settings"] = _settings(head.get("settings", {}), prefix + "settings")
    values = _validated(values, ConfigError, prefix)
    return DrillingStudy(**values)


def _settings(table: object, where: str) -> DrillingSettings:
    """``[drilling_study.settings]``: fields of :class:`~.control.DrillingSettings` but the study's
    axes, each of its default's type (their ranges are checked against the robot before the runs,
    :func:`check_drilling_study`)."""
    if not isinstance(table, Mapping):
        checks.refuse(where, table, "a table of DrillingSettings fields", ConfigError)
    defaults = DrillingSettings()
    known = [f.name for f in dataclasses.fields(DrillingSettings) if f.name not in AXES]
    values: dict[str, Any] = {}
    for key, value in table.items():
        name = f"{where}.{cut(str(key))}"
        if key in AXES:
            raise ConfigError(f"{name}: a study axis; set drilling_study.{key} instead")
        if key not in known:
            raise ConfigError(f"{name}: unknown setting; expected one of {known}")
        default = getattr(defaults, key)
        if isinstance(default, bool):
            values[key] = checks.flag(name, value, error=ConfigError)
        elif isinstance(default, int):
            values[key] = checks.whole(name, value, error=ConfigError)
        else:
            values[key] = checks.number(name, value, error=ConfigError)
    return dataclasses.replace(defaults, **values)


def check_drilling_study(robot: Robot, study: DrillingStudy) -> None:
    """Every point's settings checked against ``robot`` (:func:`~.control.check_settings`), before
    any run: one :class:`~vgtarm.errors.InputError` line naming the field and the point."""
    seen: set[DrillingSettings] = set()
    for point in study.points():
        settings = study.point_settings(point)
        if settings in seen:
            continue
        seen.add(settings)
        try:
            check_settings(robot, settings)
        except InputError as exc:
            raise InputError(f"{study.name}, point {point.index} (seed {point.seed}): {exc}") from None


# -- running --------------------------------------------------------------------------------------


class Pool(Protocol):
    """What runs a study's points: ``submit(fn, *args)`` calls ``fn(robot, *args)`` with a robot of
    the study's and returns its future (:class:`vgtarm.app.pool.Workers` is one)."""

    def submit(self, fn: Callable[..., T], /, *args: Any) -> Future[T]: ...


def run_drilling_study(
    robot: Robot,
    study: DrillingStudy,
    *,
    workers: int = 1,
    progress: Callable[[int, int], None] | None = None,
    pool: Pool | None = None,
) -> DrillingStudyResult:
    """Drill every point of ``study`` with ``robot``: the point's perturbed bone, the detector told
    the nominal one, the point's settings; one row of measures per point, in the points' order.

    ``workers`` > 1 runs the points in that many fresh worker processes (``spawn``: a script must
    start its work under ``if __name__ == "__main__":``), each with its own robot of
    ``robot.parameters``; ``pool`` (already entered; it overrides ``workers``) runs them instead:
    the command line passes :class:`vgtarm.app.pool.Workers`, which also ends its workers with a
    Ctrl-C or with this process. A run depends only on its inputs, so the rows are the same either
    way. ``progress(done, total)`` is called as the runs end. The settings are checked first
    (:func:`check_drilling_study`)."""
    workers = checks.whole("workers", workers, 1, unit="processes")
    check_drilling_study(robot, study)
    points = study.points()
    tasks = [(study.bones[p.bone], p.seed, study.spread, study.point_settings(p)) for p in points]
    start = time.perf_counter()
    if pool is not None:
        summaries = _run_all(pool, tasks, progress)
    elif workers == 1 or len(points) == 1:
        summaries = []
        for i, task in enumerate(tasks):
            summaries.append(run_point(robot, *task))
            if progress is not None:
                progress(i + 1, len(tasks))
    else:
        with _Spawned(min(workers, len(points)), robot) as spawned:
            summaries = _run_all(spawned, tasks, progress)
    wall = time.perf_counter() - start
    n_layers = max(len(b.layers) for b in study.bones)
    rows = [
        study_row(p, perturbed_bone(study.bones[p.bone], p.seed, study.spread), s, n_layers)
        for p, s in zip(points, summaries, strict=True)
    ]
    return DrillingStudyResult(study, tuple(points), rows, wall)


def run_point(robot: Robot, nominal: Bone, seed: int, spread: float, settings: DrillingSettings) -> dict[str, Any]:
    """The summary of one point's run: ``nominal`` perturbed by ``seed`` and ``spread``, drilled
    with ``settings``, the detector told ``nominal`` (a module-level function: it runs in workers)."""
    bone = perturbed_bone(nominal, seed, spread)
    return drilling_run(robot, bone, settings, nominal=nominal).summary()


def _run_all(pool: Pool, tasks: list[tuple[Any, ...]], progress: Callable[[int, int], None] | None) -> list[Any]:
    """Each task through ``pool`` (all submitted at once), the results in the tasks' order."""
    futures = {pool.submit(run_point, *task): i for i, task in enumerate(tasks)}
    results: list[Any] = [None] * len(tasks)
    pending = set(futures)
    while pending:
        done, pending = wait(pending, return_when=FIRST_COMPLETED)
        for future in done:
            results[futures[future]] = future.result()  # a worker's error goes up here
        if progress is not None:
            progress(len(tasks) - len(pending), len(tasks))
    return results


#: The robot of a worker process of :class:`_Spawned`.
_WORKER_ROBOT: list[Robot] = []


def _start_worker(parameters: Any, backend: str) -> None:
    """A worker's start: one GA thread (the processes fill the cores) and its own robot."""
    from ..model.compiled import get_backend

    os.environ["VGTARM_THREADS"] = "1"
    _WORKER_ROBOT.append(Robot(parameters, backend=get_backend(backend, definition_of(parameters))))


def _call(fn: Callable[..., T], *args: Any) -> T:
    return fn(_WORKER_ROBOT[0], *args)


class _Spawned:
    """``count`` spawned worker processes, each with a robot of ``robot``'s parameters and backend
    kind (the library's plain pool; the command line's :class:`vgtarm.app.pool.Workers` adds the
    Ctrl-C and orphan handling)."""

    def __init__(self, count: int, robot: Robot) -> None:
        self._executor = ProcessPoolExecutor(
            count,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_start_worker,
            initargs=(robot.parameters, robot.backend.kind),
        )

    def __enter__(self) -> _Spawned:
        return self

    def __exit__(self, kind: type[BaseException] | None, *exc: object) -> None:
        self._executor.shutdown(wait=True, cancel_futures=kind is not None)

    def submit(self, fn: Callable[..., T], /, *args: Any) -> Future[T]:
        return self._executor.submit(_call, fn, *args)


# -- rows -----------------------------------------------------------------------------------------


def study_row(point: DrillingPoint, bone: Bone, summary: Mapping[str, Any], n_layers: int) -> dict[str, Any]:
    """The row of ``point``: its inputs, the perturbed ``bone``'s total and per-layer thickness (m)
    and density (kg/m^3), ``success`` and ``reason``, the per-layer measures of ``summary`` (NaN
    beyond the bone's layers, up to ``n_layers``), the measures :data:`MEASURES` and
    ``within_targets``."""
    row: dict[str, Any] = {
        "point": point.index,
        "bone": point.label,
        "seed": point.seed,
        "mode": point.mode,
        "feedback": point.feedback,
        "set_point": point.set_point,
        "feed_limit": point.feed_limit,
        "thickness": bone.thickness,
    }
    for key in ("thickness", "density"):
        for i in range(n_layers):
            row[f"{key}_{i}"] = getattr(bone.layers[i], key) if i < len(bone.layers) else math.nan
    row["success"] = bool(summary["success"])
    row["reason"] = str(summary["reason"])
    layers = summary["layers"]
    for key in LAYER_MEASURES:
        for i in range(n_layers):
            row[f"{key}_{i}"] = float(layers[i][key]) if i < len(layers) else math.nan
    for key in MEASURES:
        if key == "transitions_missed":
            row[key] = sum(not math.isfinite(t["detected_time"]) for t in summary["transitions"])
        elif key == "transition_delay_max":  # the summary matches detections by layer count, not by time
            delays = [t["detected_time"] - t["true_time"] for t in summary["transitions"]]
            finite = [d for d in delays if math.isfinite(d)]
            row[key] = max(finite) if finite else math.nan
        elif key == "false_detections":
            row[key] = int(summary[key])
        else:
            row[key] = float(summary[key])
    row["within_targets"] = all(meets_targets(row).values())
    return row


def meets_targets(row: Mapping[str, Any]) -> dict[str, bool]:
    """Per target of :data:`~.loop.TARGETS`, whether ``row`` meets it (a finite value at most the
    target; the thrust error's is the largest layer RMS), and ``false_detections`` (none),
    ``transitions`` (every interface detected) and ``success`` (the breakthrough detected)."""
    met = {name: math.isfinite(row[column]) and row[column] <= TARGETS[name] for name, column in TARGET_COLUMNS.items()}
    met["false_detections"] = row["false_detections"] == 0
    met["transitions"] = row["transitions_missed"] == 0
    met["success"] = bool(row["success"])
    return met


@dataclass(frozen=True)
class DrillingStudyResult:
    """A study's runs: the ``study``, its ``points``, one row of measures per point (``rows``: dicts
    of the same keys, SI units, see :func:`study_row`) and the study's wall time (s)."""

    study: DrillingStudy
    points: tuple[DrillingPoint, ...]
    rows: list[dict[str, Any]]
    wall_time_s: float

    def columns(self) -> list[str]:
        """The rows' keys, in their order."""
        return list(self.rows[0]) if self.rows else []

    def table(self) -> str:
        """The rows as CSV text: a header of :meth:`columns`, then a line per row (:func:`csv_cell`)."""
        stream = io.StringIO()
        writer = csv.writer(stream, lineterminator="\n")
        writer.writerow(self.columns())
        for row in self.rows:
            writer.writerow([csv_cell(row[c]) for c in self.columns()])
        return stream.getvalue()

    def spread(self) -> dict[str, dict[str, float]]:
        """Per numeric column (inputs and measures; not ``point`` and ``seed``): the ``min``,
        ``median`` and ``max`` of its finite values and their ``count`` (NaN when there are none)."""
        out: dict[str, dict[str, float]] = {}
        for column in self.columns():
            values = [r[column] for r in self.rows]
            if column in ("point", "seed") or not all(checks.is_number(v) for v in values):
                continue
            finite = np.array([v for v in values if math.isfinite(v)], dtype=np.float64)
            stats = (finite.min(), np.median(finite), finite.max()) if finite.size else (math.nan,) * 3
            out[column] = {
                "min": float(stats[0]),
                "median": float(stats[1]),
                "max": float(stats[2]),
                "count": float(finite.size),
            }
        return out

    def within_targets(self) -> dict[str, int]:
        """``runs``; ``within_targets``, the runs meeting every target (:func:`meets_targets`);
        ``false_detections``, their total over the runs, and ``runs_with_false_detections``; and
        per target (``met_<target>``) the runs meeting it."""
        met = [meets_targets(r) for r in self.rows]
        out = {
            "runs": len(self.rows),
            "within_targets": sum(all(m.values()) for m in met),
            "false_detections": sum(int(r["false_detections"]) for r in self.rows),
            "runs_with_false_detections": sum(int(r["false_detections"]) > 0 for r in self.rows),
        }
        for name in met[0] if met else ():
            out[f"met_{name}"] = sum(m[name] for m in met)
        return out

    def summary(self) -> dict[str, Any]:
        """The study in one record (``summary.json``): its name, runs, :meth:`within_targets`, the
        targets and :meth:`spread`."""
        return {
            "study": self.study.name,
            "bones": list(self.study.labels),
            "runs": len(self.rows),
            "within_targets": self.within_targets(),
            "targets": dict(TARGETS),
            "spread": self.spread(),
            "wall_time_s": self.wall_time_s,
        }

    def figure(self, fig: Any = None) -> Any:
        """:func:`drilling_study_figure` of this result."""
        return drilling_study_figure(self, fig)


def drilling_study_figure(result: DrillingStudyResult, fig: Any = None) -> Any:
    """The protrusion (mm), the detection delay (ms, log scale; symmetric if one is < 0) and each layer's thrust
    error RMS (N, log scale) of every run against its feed limit (mm/s), a colour per mode, each
    target a dashed line, the runs that miss one hollow; a new :class:`matplotlib.figure.Figure`
    (no pyplot) unless ``fig`` is given."""
    from matplotlib.figure import Figure

    fig = fig if fig is not None else Figure(figsize=(8.0, 9.0))
    axes = fig.subplots(3, 1, sharex=True)
    rows = result.rows
    modes = list(dict.fromkeys(r["mode"] for r in rows))
    n_layers = sum(1 for c in result.columns() if c.startswith("thrust_error_rms_") and c[-1].isdigit())
    panels = (
        (axes[0], [("protrusion", 1e3)], "protrusion (mm)", 1e3 * TARGETS["protrusion"]),
        (axes[1], [("detection_delay", 1e3)], "detection delay (ms)", 1e3 * TARGETS["detection_delay"]),
        (
            axes[2],
            [(f"thrust_error_rms_{i}", 1.0) for i in range(n_layers)],
            "thrust error RMS (N)",
            TARGETS["thrust_error_rms"],
        ),
    )
    markers = "os^vD<>"
    for ax, columns, label, target in panels:
        for m, mode in enumerate(modes):
            chosen = [r for r in rows if r["mode"] == mode]
            feed = np.array([1e3 * r["feed_limit"] for r in chosen])
            ok = np.array([r["within_targets"] for r in chosen], dtype=bool)
            for i, (column, scale) in enumerate(columns):
                y = np.array([scale * r[column] for r in chosen], dtype=np.float64)
                style = {"color": f"C{m}", "marker": markers[i % len(markers)], "ls": "none", "ms": 5}
                name = mode if len(columns) == 1 else f"{mode}, layer {i}"
                ax.plot(feed[ok], y[ok], label=name if ok.any() else None, **style)
                ax.plot(feed[~ok], y[~ok], mfc="none", label=None if ok.any() else name, **style)
        ax.axhline(target, color="k", ls="--", lw=1.0, label="target")
        ax.set_ylabel(label)
    delays = np.array([r["detection_delay"] for r in rows], dtype=np.float64)
    if (delays[np.isfinite(delays)] > 0).all():  # a log scale keeps the rest legible beside an outlier
        axes[1].set_yscale("log")
    else:  # an early (false) breakthrough: negative delays
        axes[1].set_yscale("symlog", linthresh=1e3 * TARGETS["detection_delay"])
    axes[2].set_yscale("log")
    axes[2].set_xlabel("feed limit (mm/s)")
    axes[2].legend(loc="best", fontsize="x-small", ncol=2)
    axes[0].legend(loc="best", fontsize="small")
    counts = result.within_targets()
    fig.suptitle(
        f"{mpl_text(result.study.name)}\n{counts['within_targets']} of {counts['runs']} runs within every target "
        f"(hollow: a target missed); {counts['false_detections']} false detections"
    )
    return fig


__all__ = [
    "AXES",
    "FEED_RANGE",
    "FEED_STREAM",
    "MEASURES",
    "DrillingPoint",
    "DrillingStudy",
    "DrillingStudyResult",
    "Pool",
    "check_drilling_study",
    "drilling_study_figure",
    "load_drilling_study",
    "meets_targets",
    "parse_drilling_study",
    "point_feed",
    "run_drilling_study",
    "run_point",
    "study_row",
]
