"""Study files: a TOML grid and/or random draws over run inputs, validated, expanded into points.

A study file has three tables (see :mod:`vgtarm.study.example` for a commented one):

- ``[study]``: what every run shares: ``name``, ``case`` (1 or 2) or ``path`` (a CSV file of
  ``t,x,y,z`` rows, relative to the study file), ``duration`` (s, keep only the start of the
  reference; default the whole path), ``dt`` (s), ``rates``, ``robot`` (a robot TOML file,
  default the reference robot) and ``seeds`` (a count ``n`` for 0..n-1, a list, or
  ``{start = s, count = n}``);
- ``[grid]``: parameters with one value or a list of values; every combination is run;
- ``[random]``: ``draws`` (how many), ``seed`` (of the draws) and parameters with a distribution
  ``{uniform = [a, b]}``, ``{log_uniform = [a, b]}``, ``{normal = [mean, sd]}``,
  ``{integers = [a, b]}`` (both ends included) or ``{choice = [v1, v2, ...]}``.

Points are the grid's combinations times the draws times the seeds. Every point's inputs hold
every parameter (defaults filled in) and its id is a hash of its inputs, so the same study gives
the same ids on any machine and a changed input gives a new id.

Parameters: :data:`PARAMETERS` (controller, gains, GA, tool force, controller-model errors,
integrator), :data:`IK_PARAMETERS` (the reference's redundancy criterion and its joint-limit
weight; a point of eq. 12 has the weight's default, so a grid of both criteria runs eq. 12 once)
and every scalar option of the simulation's :class:`~vgtarm.simulation.Scenario` not listed
there, passed to it unchanged: each declared once, where it is a field
(:func:`vgtarm.experiment.options.study_options` lists them all).
"""

from __future__ import annotations

import difflib
import hashlib
import itertools
import json
import math
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError, VgtarmError, cut, shown
from ..experiment.options import IK_OPTIONS, scenario_names, study_options
from ..fileio import parse_toml, read_text_limited
from ..ga import MAX_SEED, check_seed
from ..kinds import other_toml
from ..model.parameters import ROBOT_FILE_LIMIT
from ..model.robot import robot_parameters_from_dict
from ..option import ID_ALWAYS, Option, Value
from ..paths import CSV_FILE_LIMIT, MIN_DT, from_csv

#: One run input of a study: an option of the experiment, declared once (:mod:`vgtarm.option`).
Parameter = Option

#: The study's own parameters (the experiment's options and the integrator: the controller, gains, GA,
#: tool force, controller-model errors); those of the first studies always count in a point's id.
PARAMETERS: dict[str, Parameter] = {
    name: o
    for name, o in study_options().items()
    if name not in scenario_names() and o not in IK_OPTIONS or o.in_id == ID_ALWAYS
}

#: The reference's redundancy criterion (issue 22): eq. 12 (``"joint_limits"``, the paper's) or the static
#: actuator efforts (``"effort"``, with the expected cutting force when the point has the tool force), and
#: the joint-limit weight of the effort criterion. Like the simulator's options they count in a point's id
#: only when set or away from their default, so the ids of studies written before stay as they were.
IK_PARAMETERS: dict[str, Parameter] = {o.name: o for o in IK_OPTIONS}


def _positive(v: float) -> bool:
    return math.isfinite(v) and v > 0


def simulate_options() -> dict[str, Parameter]:
    """The options of the simulation's :class:`~vgtarm.simulation.Scenario` a study passes through
    (every declared one but the integrator, its substeps and the seed, which the study sets itself)."""
    return {name: o for name, o in study_options().items() if name in scenario_names() and name not in PARAMETERS}


def all_parameters() -> dict[str, Parameter]:
    """Every parameter a study may set, in the order of a point's inputs
    (:func:`vgtarm.experiment.options.study_options`)."""
    return study_options()


def optional_defaults() -> dict[str, Value]:
    """The parameters that count in a point's id only when set or away from these defaults."""
    return {k: p.default for k, p in study_options().items() if p.in_id != ID_ALWAYS}


_STUDY_KEYS = ("name", "case", "path", "duration", "dt", "rates", "robot", "seeds")
_RATES = ("exact", "finite_difference")
_DISTRIBUTIONS = ("uniform", "log_uniform", "normal", "integers", "choice")
#: Largest study file read (bytes).
STUDY_FILE_LIMIT = 2**20
#: Most runs a study may expand to (grid combinations x draws x seeds), checked before expanding.
MAX_POINTS = 100_000
#: Longest study name (characters).
NAME_LENGTH = 200
_FILE_LIMITS = {"path": CSV_FILE_LIMIT, "robot": ROBOT_FILE_LIMIT}
_INT64 = (-(2**63), 2**63 - 1)


@dataclass(frozen=True)
class Point:
    """One run of a study: its id (16 hex digits) and its inputs (name -> value)."""

    id: str
    inputs: dict[str, Value]


@dataclass(frozen=True)
class Study:
    """A validated study. ``files`` maps ``"path"``/``"robot"`` to the files' text (shipped to
    workers, so they need not share the file system)."""

    name: str
    shared: dict[str, Value]
    grid: dict[str, list[Value]]
    random: dict[str, tuple[str, list[Value]]]
    draws: int
    random_seed: int
    seeds: tuple[int, ...]
    files: dict[str, str]
    source: str = "<study>"

    def points(self) -> list[Point]:
        """Every run: grid combinations x draws x seeds, in that order, duplicates removed."""
        params = all_parameters()
        rng = np.random.default_rng(self.random_seed)
        drawn = [
            {key: _draw(rng, dist, args) for key, (dist, args) in sorted(self.random.items())}
            for _ in range(self.draws)
        ] or [{}]
        for i, values in enumerate(drawn):
            for key, value in values.items():
                where = f"{self.source}: random.{key} (draw {i})"
                values[key] = _check_value(where, value, params[key])
        grid_keys = list(self.grid)
        points: dict[str, Point] = {}
        for combo in itertools.product(*(self.grid[k] for k in grid_keys)):
            chosen = dict(zip(grid_keys, combo, strict=True))
            for values in drawn:
                for seed in self.seeds:
                    inputs: dict[str, Value] = dict(self.shared)
                    for name, p in params.items():
                        inputs[name] = values.get(name, chosen.get(name, p.default))
                    inputs["seed"] = seed
                    if inputs["criterion"] == "joint_limits":  # the weight is the effort criterion's only
                        inputs["joint_limit_weight"] = IK_PARAMETERS["joint_limit_weight"].default
                    point_id = point_id_of(inputs, self.files, explicit=set(chosen) | set(values))
                    points.setdefault(point_id, Point(point_id, inputs))
        return list(points.values())


def point_id_of(inputs: Mapping[str, Value], files: Mapping[str, str], *, explicit: set[str] | None = None) -> str:
    """A stable id of a run: SHA-256 of its inputs (canonical JSON) and of its files' text.

    Options passed through to the simulator count only when set explicitly or away from their
    default, so an option added to the simulator later does not change existing ids.
    """
    own = {k for k, p in PARAMETERS.items() if p.in_id == ID_ALWAYS} | set(_STUDY_KEYS) | {"seed"}
    defaults = optional_defaults()
    keyed = {
        k: v
        for k, v in inputs.items()
        if k in own or (explicit is not None and k in explicit) or defaults.get(k, object()) != v
    }
    digest = hashlib.sha256(json.dumps(keyed, sort_keys=True, separators=(",", ":")).encode())
    for name in sorted(files):
        digest.update(f"\0{name}\0{files[name]}".encode())
    return digest.hexdigest()[:16]


def load_study(file: str | Path) -> Study:
    """Read and validate a study file; raises :class:`ConfigError` (one line naming the key).

    Files larger than :data:`STUDY_FILE_LIMIT` bytes, not UTF-8 text or nested too deep to parse
    are refused like a TOML syntax error.
    """
    text = read_text_limited(file, STUDY_FILE_LIMIT, "study file", error=ConfigError)
    where = Path(file)
    data = parse_toml(text, f"study file {cut(str(where), 200)}", error=ConfigError)
    return parse_study(data, source=str(where), folder=where.parent)


def parse_study(data: Mapping[str, Any], *, source: str = "<study>", folder: Path | None = None) -> Study:
    """Validate a study given as a dict (a parsed TOML file); files are relative to ``folder``."""
    source = cut(str(source), 200)
    head, grid_in, random_in = _tables(source, data)
    params = all_parameters()
    name = head.get("name", "study")
    if not isinstance(name, str) or not name or len(name) > NAME_LENGTH:
        raise ConfigError(
            f"{source}: study.name = {shown(name)}: expected a non-empty string of at most {NAME_LENGTH} characters"
        )
    files: dict[str, str] = {}
    shared = _shared(source, head, folder, files)
    seeds = _seeds(source, head.get("seeds", 1))
    grid = _grid(source, grid_in, params)
    draws, random_seed, random = _random(source, random_in, grid, params)
    _check_criterion(source, grid, random)
    _check_size(source, head, grid, draws, seeds)
    study = Study(name, shared, grid, random, draws, random_seed, tuple(seeds), files, source)
    study.points()  # draws are checked here, before any run
    return study


def _tables(source: str, data: Mapping[str, Any]) -> tuple[Mapping[str, Any], Mapping[str, Any], dict[str, Any]]:
    """The tables ``[study]``, ``[grid]`` and ``[random]`` (a copy) of a study file's ``data``, each
    refused in one line when ``data`` is not a study file's, a table is unknown or ``[study]`` has a
    key it does not know."""
    if not isinstance(data, Mapping):
        raise ConfigError(f"{source}: {shown(data)}: expected a table of [study], [grid] and [random]")
    other = other_toml(data, "a study file")  # a robot file given as a study: said in those words
    if other is not None:
        raise ConfigError(f"{source}: {other}")
    unknown = sorted(set(data) - {"study", "grid", "random"}, key=str)
    if unknown:
        raise ConfigError(f"{source}: unknown table [{cut(str(unknown[0]))}]: expected [study], [grid] and [random]")
    head = _table(source, data, "study")
    grid_in = _table(source, data, "grid")
    random_in = dict(_table(source, data, "random"))
    for key in head:
        if key not in _STUDY_KEYS:
            raise ConfigError(f"{source}: study.{cut(str(key))}: unknown key; expected one of {list(_STUDY_KEYS)}")
    return head, grid_in, random_in


def _shared(source: str, head: Mapping[str, Any], folder: Path | None, files: dict[str, str]) -> dict[str, Value]:
    """What every run of the study shares, from ``[study]``: the case or the path file, the
    duration, the period, the rates and the robot file; the files' text is read into ``files``
    and parsed, so a bad one is refused before any run."""
    shared: dict[str, Value] = {}
    if ("case" in head) == ("path" in head):
        raise ConfigError(f'{source}: [study]: give exactly one of case = 1|2 and path = "FILE.csv"')
    if "case" in head:
        case = head["case"]
        if isinstance(case, bool) or case not in (1, 2):
            raise ConfigError(f"{source}: study.case = {shown(case)}: expected 1 or 2 (the paper's case studies)")
        shared["case"] = int(case)
        shared["path"] = None
    else:
        shared["case"] = None
        shared["path"] = _file(source, folder, "path", head["path"], files)
    duration = head.get("duration")
    if duration is not None and not (_is_number(duration) and _positive(float(duration))):
        raise ConfigError(f"{source}: study.duration = {shown(duration)}: expected a time > 0 (s)")
    shared["duration"] = None if duration is None else float(duration)
    dt = head.get("dt", 1e-3)
    if not (_is_number(dt) and _positive(float(dt))):
        raise ConfigError(f"{source}: study.dt = {shown(dt)}: expected a period > 0 (s)")
    if float(dt) < MIN_DT:
        raise ConfigError(
            f"{source}: study.dt = {shown(dt)}: expected a period >= {MIN_DT:g} s (closer samples turn rounding"
            " into huge rates)"
        )
    shared["dt"] = float(dt)
    rates = head.get("rates", "exact")
    if rates not in _RATES:
        raise ConfigError(f"{source}: study.rates = {shown(rates)}: expected one of {list(_RATES)}")
    shared["rates"] = rates
    shared["robot"] = None if head.get("robot") is None else _file(source, folder, "robot", head["robot"], files)
    _check_files(source, head, files, float(dt))
    return shared


def _grid(source: str, grid_in: Mapping[str, Any], params: Mapping[str, Parameter]) -> dict[str, list[Value]]:
    """The ``[grid]`` table: each parameter's values (one value: a list of one), each checked."""
    grid: dict[str, list[Value]] = {}
    for key, value in grid_in.items():
        if key not in params:
            raise ConfigError(f"{source}: grid.{cut(str(key))}: unknown parameter; expected {_names(key, params)}")
        values = value if isinstance(value, list) else [value]
        if not values:
            raise ConfigError(f"{source}: grid.{key} = []: expected a value or a non-empty list of values")
        grid[key] = [_check_value(f"{source}: grid.{key}", v, params[key]) for v in values]
    return grid


def _random(
    source: str, random_in: dict[str, Any], grid: Mapping[str, list[Value]], params: Mapping[str, Parameter]
) -> tuple[int, int, dict[str, tuple[str, list[Value]]]]:
    """The ``[random]`` table (``random_in``, whose ``draws`` and ``seed`` are taken out of it): the
    number of draws, their seed and each drawn parameter's distribution, none of them in ``grid``."""
    draws = random_in.pop("draws", 0)
    random_seed = random_in.pop("seed", 0)
    if isinstance(draws, bool) or not isinstance(draws, int) or draws < 0:
        raise ConfigError(f"{source}: random.draws = {shown(draws)}: expected a whole number >= 0")
    random_seed = check_seed(random_seed, f"{source}: random.seed", ConfigError)
    random: dict[str, tuple[str, list[Value]]] = {}
    for key, value in random_in.items():
        if key not in params:
            raise ConfigError(f"{source}: random.{cut(str(key))}: unknown parameter; expected {_names(key, params)}")
        if key in grid:
            raise ConfigError(f"{source}: random.{key}: already in [grid]; a parameter is either swept or drawn")
        random[key] = _distribution(f"{source}: random.{key}", value, params[key])
    if random and draws == 0:
        raise ConfigError(f"{source}: random.draws = 0: expected a whole number >= 1 with random parameters")
    return draws, random_seed, random


def _check_size(
    source: str, head: Mapping[str, Any], grid: Mapping[str, list[Value]], draws: int, seeds: Sequence[int]
) -> None:
    """Refuse a study of more than :data:`MAX_POINTS` runs (grid combinations x draws x seeds)."""
    combinations = math.prod(len(values) for values in grid.values())
    n_seeds = seeds.stop - seeds.start if isinstance(seeds, range) else len(seeds)  # len() of a vast range fails
    total = combinations * max(draws, 1) * n_seeds
    if total > MAX_POINTS:
        raise ConfigError(
            f"{source}: {total:,} runs = {combinations:,} grid combinations x {max(draws, 1):,} random.draws x"
            f" {n_seeds:,} seeds (study.seeds = {shown(head.get('seeds', 1))}); at most {MAX_POINTS:,}"
        )


def _check_criterion(
    source: str, grid: Mapping[str, list[Value]], random: Mapping[str, tuple[str, list[Value]]]
) -> None:
    """Refuse a joint-limit weight in a study none of whose points uses the effort criterion."""
    weight = "grid" if "joint_limit_weight" in grid else "random" if "joint_limit_weight" in random else None
    if weight is None:
        return
    criteria = grid.get("criterion") or (random["criterion"][1] if "criterion" in random else ["joint_limits"])
    if "effort" not in criteria:
        raise ConfigError(
            f"{source}: {weight}.joint_limit_weight: applies to criterion = 'effort' only; expected criterion ="
            f" 'effort' among the [grid] or [random] values (got {sorted(set(map(str, criteria)))})"
        )


def _names(key: object, params: Mapping[str, Parameter]) -> str:
    """The valid parameter names for a message about ``key``: all if few, else the closest ones."""
    names = sorted(params)
    if len(names) <= 8:
        return str(names)
    close = difflib.get_close_matches(str(key), names, n=3, cutoff=0.5)
    hint = f"closest: {close}; " if close else ""
    return f"one of the {len(names)} study parameters ({hint}see the example of `vgtarm study init`)"


def _table(source: str, data: Mapping[str, Any], name: str) -> Mapping[str, Any]:
    value = data.get(name, {})
    if not isinstance(value, Mapping):
        raise ConfigError(f"{source}: {name} = {shown(value)}: expected a table [{name}]")
    return value


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _file(source: str, folder: Path | None, key: str, value: object, files: dict[str, str]) -> str:
    if not isinstance(value, str) or not value:
        raise ConfigError(f"{source}: study.{key} = {shown(value)}: expected a file name")
    file = Path(value) if folder is None else folder / value
    files[key] = read_text_limited(file, _FILE_LIMITS[key], f"{source}: study.{key}: file", error=ConfigError)
    return value


def _check_files(source: str, head: Mapping[str, Any], files: Mapping[str, str], dt: float) -> None:
    """Parse the study's robot and path files now, so a bad one is refused before any run."""
    if "robot" in files:
        where = f"{source}: study.robot = {shown(head['robot'])}"
        robot_parameters_from_dict(parse_toml(files["robot"], where, error=ConfigError), source=where)
    if "path" in files:
        with tempfile.TemporaryDirectory(prefix="vgtarm-study-") as folder:  # the text read, not the file again
            copy = Path(folder) / "path.csv"
            copy.write_text(files["path"], encoding="utf-8")
            try:
                from_csv(copy, dt, quote=False)  # a file named by the study's author: never shown
            except VgtarmError as exc:
                label = f"path file {shown(str(copy), 200)}"
                message = str(exc).replace(f"{label}: ", "").replace(label, "the file")
                raise ConfigError(f"{source}: study.path = {shown(head['path'])}: {message}") from None


def _seeds(source: str, value: object) -> Sequence[int]:
    """The seeds of ``study.seeds``: a range (not expanded, however long) or a list; every seed from 0
    to :data:`~vgtarm.ga.MAX_SEED` (a run's seed is stored as a 64-bit integer)."""
    where = f"{source}: study.seeds = {shown(value)}"
    seeds = f"seeds from 0 to 2**63 - 1 = {MAX_SEED}"

    def whole(v: object) -> bool:
        return isinstance(v, int) and not isinstance(v, bool) and v >= 0

    if whole(value) and value:
        if value > MAX_SEED + 1:  # type: ignore[operator]
            raise ConfigError(f"{where}: expected a count of at most 2**63 ({seeds})")
        return range(int(value))  # type: ignore[call-overload]
    if isinstance(value, list) and value and all(whole(v) for v in value):
        if len(set(value)) != len(value):
            raise ConfigError(f"{where}: expected distinct seeds")
        if max(value) > MAX_SEED:
            raise ConfigError(f"{where}: seed {shown(max(value))}: expected {seeds}")
        return [int(v) for v in value]
    if isinstance(value, Mapping) and set(value) == {"start", "count"} and whole(value["start"]):
        if whole(value["count"]) and value["count"] >= 1:
            start, count = int(value["start"]), int(value["count"])
            if start + count - 1 > MAX_SEED:
                raise ConfigError(f"{where}: the last seed is {start + count - 1}; expected {seeds}")
            return range(start, start + count)
    raise ConfigError(
        f"{where}: expected a count >= 1, a list of distinct whole numbers >= 0 or {{start = S, count = N}} ({seeds})"
    )


def _check_value(where: str, value: object, p: Parameter) -> Value:
    """The value converted to the parameter's type, or ConfigError naming it."""
    bad = ConfigError(f"{where} = {shown(value)}: expected {p.expected}")
    if p.kind is bool:
        if not isinstance(value, bool | np.bool_):
            raise bad
        return bool(value)
    if p.kind is int:
        if isinstance(value, bool) or not isinstance(value, int | np.integer):
            raise bad
        converted: Value = int(value)
    elif p.kind is float:
        if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
            raise bad
        converted = float(value)
        if not math.isfinite(converted):
            raise bad
    else:
        if not isinstance(value, str):
            raise bad
        converted = value
    if p.choices and converted not in p.choices:
        raise bad
    if not p.accepts(converted):
        raise bad
    return converted


def _distribution(where: str, value: object, p: Parameter) -> tuple[str, list[Value]]:
    if not (isinstance(value, Mapping) and len(value) == 1 and next(iter(value)) in _DISTRIBUTIONS):
        raise ConfigError(f"{where} = {shown(value)}: expected one of {{{' | '.join(_DISTRIBUTIONS)} = [...]}}")
    dist, args = next(iter(value.items()))
    if dist == "choice":
        if not (isinstance(args, list) and args):
            raise ConfigError(f"{where}.choice = {shown(args)}: expected a non-empty list of values")
        return dist, [_check_value(f"{where}.choice", v, p) for v in args]
    if not (isinstance(args, list) and len(args) == 2 and all(_is_number(a) for a in args)):
        raise ConfigError(f"{where}.{dist} = {shown(args)}: expected two numbers [a, b]")
    if p.kind not in (int, float) or (dist == "integers") != (p.kind is int):
        kind = "whole-number" if p.kind is int else ("numeric" if p.kind is float else p.kind.__name__)
        raise ConfigError(f"{where}.{dist}: not a distribution for a {kind} parameter ({p.expected})")
    a, b = args
    if dist == "normal" and not b > 0:
        raise ConfigError(f"{where}.normal = {shown(args)}: expected [mean, standard deviation > 0]")
    if dist != "normal" and not a <= b:
        raise ConfigError(f"{where}.{dist} = {shown(args)}: expected [a, b] with a <= b")
    if dist == "integers" and not all(isinstance(x, int) and _INT64[0] <= x <= _INT64[1] for x in args):
        raise ConfigError(f"{where}.integers = {shown(args)}: expected two whole numbers (64-bit)")
    if dist == "log_uniform" and not a > 0:
        raise ConfigError(f"{where}.log_uniform = {shown(args)}: expected 0 < a <= b")
    return dist, list(args)


def _draw(rng: np.random.Generator, dist: str, args: list[Value]) -> Value:
    if dist == "choice":
        return args[int(rng.integers(len(args)))]
    if dist == "integers":
        return int(rng.integers(int(args[0]), int(args[1]), endpoint=True))  # type: ignore[arg-type]
    a, b = float(args[0]), float(args[1])  # type: ignore[arg-type]
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is a non-finite draw, refused by the check
        if dist == "uniform":
            return float(rng.uniform(a, b))
        if dist == "log_uniform":
            return float(np.exp(rng.uniform(np.log(a), np.log(b))))
        return float(rng.normal(a, b))
