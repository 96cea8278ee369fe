"""Property-based fuzzing of every file parser and of the command line (issue 14).

Robot files, path CSV files and study files are mutated from valid ones (keys deleted, values
replaced by wrong types, NaN, infinities, huge, negative or nested values, unknown keys, bytes
that are not text, truncation, control characters, very long strings, deep nesting); command
lines are drawn from the real subcommands and flags with valid, boundary and garbage values.

Every outcome must be either a success or a project error: a :class:`~vgtarm.errors.VgtarmError`
from the API, exit status 1 with exactly one line ``vgtarm: error: ...`` on standard error, or
exit status 2 (usage) ending in one ``error:`` line; never a traceback. Messages stay short and
hold no raw control characters, and a failed command leaves nothing behind in its folder.

Hypothesis runs derandomized (the project's rule: same seed, same numbers), so a failure found
here is found again on every run.
"""

from __future__ import annotations

import contextlib
import math
import tempfile
import tomllib
from collections.abc import Iterator
from importlib import resources
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vgtarm import paths
from vgtarm.app.cli.command import main
from vgtarm.errors import ConfigError, PathError, VgtarmError
from vgtarm.model.parameters import JOINT_NAMES, RobotParameters, load_parameters
from vgtarm.model.robot import load_robot

MESSAGE_LIMIT = 400
"""Longest acceptable error message (characters)."""


def fuzz(examples: int) -> Any:
    """Settings of every property here: reproducible, no per-example deadline."""
    return settings(
        max_examples=examples,
        deadline=None,
        derandomize=True,
        database=None,
        suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow, HealthCheck.data_too_large],
    )


REFERENCE_TEXT = resources.files("vgtarm.model.data").joinpath("reference_robot.toml").read_text("utf-8")
REFERENCE = tomllib.loads(REFERENCE_TEXT)

STUDY_TEXT = """
[study]
name = "fuzz"
case = 1
duration = 0.05
seeds = [0, 1]

[grid]
controller = ["cfc", "scm"]
external_force = true

[random]
draws = 2
seed = 3
model_mass = {uniform = [0.9, 1.1]}
"""
STUDY = tomllib.loads(STUDY_TEXT)

GOOD_CSV = "t,x,y,z\n0,0,0,0.66\n0.01,0.001,0,0.66\n0.02,0.002,0,0.66\n"


# --- checks -------------------------------------------------------------------------------------


def assert_clean_message(message: str) -> None:
    """One short line without raw control characters."""
    assert "\n" not in message and "\r" not in message, message[:MESSAGE_LIMIT]
    assert len(message) < MESSAGE_LIMIT, f"{len(message)} characters: {message[:MESSAGE_LIMIT]}"
    assert message.isprintable(), f"control characters in {message[:MESSAGE_LIMIT]!r}"


def assert_project_error(exc: BaseException, kind: type[VgtarmError]) -> None:
    assert isinstance(exc, kind), f"{type(exc).__name__}: {str(exc)[:MESSAGE_LIMIT]}"
    assert_clean_message(str(exc))


@contextlib.contextmanager
def scratch() -> Iterator[Path]:
    """A fresh empty folder made the current one (hypothesis examples cannot share tmp_path)."""
    with tempfile.TemporaryDirectory(prefix="vgtarm-fuzz-") as folder, contextlib.chdir(folder):
        yield Path(folder)


def listing(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


def run_cli(capsys: pytest.CaptureFixture[str], argv: list[str]) -> tuple[int, str, str]:
    """``vgtarm argv`` in this process; the status of a usage error (SystemExit) is returned too."""
    capsys.readouterr()
    try:
        status = main(argv)
    except SystemExit as exc:
        status = exc.code if isinstance(exc.code, int) else 1
    out, err = capsys.readouterr()
    return status, out, err


def assert_cli_outcome(status: int, out: str, err: str, argv: list[str]) -> None:
    """Success, one error line (status 1) or a usage error (status 2); never a traceback."""
    shown = repr(argv)[:300]
    assert "Traceback" not in err, f"{shown}: {err[-2000:]}"
    assert status in (0, 1, 2), f"{shown}: status {status}, stderr {err[-500:]!r}"
    if status == 1:
        assert err.endswith("\n") and err.count("\n") == 1, f"{shown}: {err[:1000]!r}"
        assert err.startswith("vgtarm: error: "), f"{shown}: {err[:500]!r}"
        assert_clean_message(err.rstrip("\n"))
    elif status == 2:
        last = err.rstrip("\n").splitlines()[-1]
        assert "error:" in last, f"{shown}: {err[-500:]!r}"
        assert_clean_message(last)
    for line in out.splitlines():
        assert line.isprintable(), f"{shown}: control characters in output line {line[:200]!r}"


# --- values and mutations of nested TOML data -----------------------------------------------------

SPECIAL_FLOATS = [math.nan, math.inf, -math.inf, 1e300, -1e300, 1e-300, 0.0, -0.0, -1.0, 5e-324, 1.7976931348623157e308]
SPECIAL_INTS = [0, -1, 1, 2, 3, 7, 2**31, 2**53 + 1, 2**63 - 1, -(2**63)]
NASTY_TEXT = ["", " ", "\x1b[31mred\x1b[0m", "\x00", "a\nb", "\u202eevil", "x" * 100_000, "é" * 300, "1e-3", "nan"]

leaf_values = st.one_of(
    st.sampled_from(SPECIAL_FLOATS),
    st.sampled_from(SPECIAL_INTS),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(2**63), max_value=2**63 - 1),
    st.booleans(),
    st.sampled_from(NASTY_TEXT),
    st.text(max_size=30),
)
values = st.recursive(
    leaf_values,
    lambda inner: st.one_of(
        st.lists(inner, max_size=8),
        st.dictionaries(st.text(min_size=1, max_size=12), inner, max_size=4),
    ),
    max_leaves=12,
)


def tree_paths(node: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every key path into nested dicts and lists (list entries by index)."""
    found = []
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else []
    for key, child in items:
        found.append((*prefix, key))
        found.extend(tree_paths(child, (*prefix, key)))
    return found


def locate(data: Any, path: tuple[Any, ...]) -> tuple[Any, Any] | None:
    """The container holding ``path``'s last key and that key, or None if the path is gone."""
    node = data
    for key in path[:-1]:
        try:
            node = node[key]
        except (KeyError, IndexError, TypeError):
            return None
    if isinstance(node, dict) and path[-1] in node:
        return node, path[-1]
    if isinstance(node, list) and isinstance(path[-1], int) and path[-1] < len(node):
        return node, path[-1]
    return None


@st.composite
def mutated(draw: st.DrawFn, base: dict[str, Any]) -> dict[str, Any]:
    """A deep copy of ``base`` with a few random mutations."""
    data = tomllib.loads(to_toml(base))  # a deep copy
    targets = tree_paths(base)
    for _ in range(draw(st.integers(1, 4))):
        action = draw(st.sampled_from(["delete", "replace", "replace", "add", "scale", "resize"]))
        path = draw(st.sampled_from(targets))
        where = locate(data, path)
        if where is None:
            continue
        node, key = where
        if action == "delete":
            del node[key]
        elif action == "replace":
            node[key] = draw(values)
        elif action == "add":
            table = node[key] if isinstance(node[key], dict) else node if isinstance(node, dict) else data
            table[draw(st.text(min_size=1, max_size=20))] = draw(values)
        elif action == "scale" and isinstance(node[key], int | float) and not isinstance(node[key], bool):
            node[key] = node[key] * draw(st.sampled_from([-1.0, 0.0, 1e300, 1e-300, 2.0, 0.5, math.nan]))
        elif action == "resize" and isinstance(node[key], list):
            node[key] = node[key][: draw(st.integers(0, len(node[key])))] + draw(st.lists(leaf_values, max_size=3))
    return data


def _toml_string(text: str) -> str:
    escaped = []
    for c in text:
        if c in '"\\':
            escaped.append("\\" + c)
        elif ord(c) < 0x20 or ord(c) == 0x7F:
            escaped.append(f"\\u{ord(c):04x}")
        elif 0xD800 <= ord(c) <= 0xDFFF:  # a lone surrogate cannot be written as UTF-8
            escaped.append("\\ufffd")
        else:
            escaped.append(c)
    return '"' + "".join(escaped) + '"'


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return _toml_string(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_toml_string(str(k))} = {_toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(type(value))


def to_toml(data: dict[str, Any]) -> str:
    """``data`` as TOML, one ``key = value`` line per top-level key (tables inline)."""
    return "".join(f"{_toml_string(str(k))} = {_toml_value(v)}\n" for k, v in data.items())


def test_toml_writer_round_trips_the_reference_files() -> None:
    assert tomllib.loads(to_toml(REFERENCE)) == REFERENCE
    assert tomllib.loads(to_toml(STUDY)) == STUDY
    assert load_parameters() == load_parameters_from_text(to_toml(REFERENCE))


def load_parameters_from_text(text: str) -> RobotParameters:
    with scratch() as folder:
        (folder / "robot.toml").write_text(text, encoding="utf-8")
        return load_parameters(folder / "robot.toml")


@st.composite
def damaged_text(draw: st.DrawFn, text: str) -> bytes:
    """``text`` damaged at the byte level: cut, with bytes or characters inserted, or replaced."""
    data = text.encode("utf-8")
    kind = draw(st.sampled_from(["truncate", "insert", "insert", "bytes", "nest", "long"]))
    if kind == "truncate":
        return data[: draw(st.integers(0, len(data)))]
    if kind == "insert":
        at = draw(st.integers(0, len(data)))
        piece = draw(
            st.one_of(
                st.binary(min_size=1, max_size=8),
                st.sampled_from([b"\x00", b"\x1b[2J", b"\xff\xfe", b"\r", b"\x7f", b"[", b"{", b'"', b"\xef\xbb\xbf"]),
                st.text(min_size=1, max_size=8).map(lambda s: s.encode("utf-8", "surrogatepass")),
            )
        )
        return data[:at] + piece + data[at:]
    if kind == "bytes":
        return draw(st.binary(max_size=200))
    if kind == "nest":
        depth = draw(st.sampled_from([100, 1_000, 100_000]))
        opener, closer = draw(st.sampled_from([("[", "]"), ("{a = ", "}")]))
        return data + f"\nnested = {opener * depth}1{closer * depth}\n".encode()
    return data + b'\nhuge = "' + b"y" * draw(st.sampled_from([10_000, 3_000_000])) + b'"\n'


# --- (a) robot files -------------------------------------------------------------------------------


def check_robot_file(file: Path) -> RobotParameters | None:
    try:
        parameters = load_parameters(file)
    except Exception as exc:  # noqa: BLE001  (any exception is judged here)
        assert_project_error(exc, ConfigError)
        assert str(file) in str(exc) or "..." in str(exc), str(exc)  # names the file (or a cut name)
        return None
    assert isinstance(parameters, RobotParameters)
    assert len(parameters.name) <= 200
    return parameters


@fuzz(150)
@given(data=mutated(REFERENCE))
def test_mutated_robot_files_load_or_fail_with_one_line(data: dict[str, Any]) -> None:
    with scratch() as folder:
        file = folder / "robot.toml"
        file.write_text(to_toml(data), encoding="utf-8")
        check_robot_file(file)


def numeric_paths(node: Any) -> list[tuple[Any, ...]]:
    """Key paths of the numbers in nested data."""
    return [p for p in tree_paths(node) if isinstance(locate(node, p)[0][p[-1]], int | float)]  # type: ignore[index]


@st.composite
def renumbered(draw: st.DrawFn, base: dict[str, Any]) -> dict[str, Any]:
    """A deep copy of ``base`` with a few numbers changed (the layout stays valid, so the values
    reach the physical checks: limits, triangle inequalities, inertia)."""
    data = tomllib.loads(to_toml(base))
    for path in draw(st.lists(st.sampled_from(numeric_paths(base)), min_size=1, max_size=3, unique=True)):
        node, key = locate(data, path)  # type: ignore[misc]
        number = draw(st.one_of(st.sampled_from(SPECIAL_FLOATS + SPECIAL_INTS), st.floats(-1e3, 1e3)))
        node[key] = draw(st.sampled_from([number, node[key] * number if isinstance(number, float) else number]))
    return data


@fuzz(120)
@given(data=renumbered(REFERENCE))
def test_robot_files_with_odd_numbers_load_or_fail_with_one_line(data: dict[str, Any]) -> None:
    with scratch() as folder:
        file = folder / "robot.toml"
        file.write_text(to_toml(data), encoding="utf-8")
        check_robot_file(file)


@fuzz(80)
@given(data=damaged_text(REFERENCE_TEXT))
def test_damaged_robot_files_fail_with_one_line(data: bytes) -> None:
    with scratch() as folder:
        file = folder / "robot.toml"
        file.write_bytes(data)
        check_robot_file(file)


@fuzz(30)
@given(data=st.one_of(renumbered(REFERENCE), mutated(REFERENCE)))
def test_describe_of_a_mutated_robot_prints_clean_lines(capsys: pytest.CaptureFixture[str], data: dict) -> None:
    with scratch() as folder:
        (folder / "robot.toml").write_text(to_toml(data), encoding="utf-8")
        argv = ["describe", "--config", "robot.toml"]
        status, out, err = run_cli(capsys, argv)
        assert_cli_outcome(status, out, err, argv)
        assert listing(folder) == {"robot.toml"}


@pytest.mark.parametrize(
    ("config", "expected"),
    [
        ("", "configuration file '': expected a file name"),
        (".", "is a folder, not a file"),
        ("/dev/zero", "is a character device; expected a regular file"),
        ("missing.toml", "missing.toml: not found"),
        ("a\x00b", r"a\\x00b: not a valid file name"),
    ],
)
def test_robot_file_names_that_are_not_files(config: str, expected: str) -> None:
    with pytest.raises(ConfigError, match=expected) as info:
        load_robot(config)
    assert_clean_message(str(info.value))


def test_deep_nesting_and_huge_values_are_one_short_line(tmp_path: Path) -> None:
    deep = tmp_path / "deep.toml"
    deep.write_text("a = " + "[" * 100_000 + "]" * 100_000)
    with pytest.raises(ConfigError, match="nested too deep"):
        load_parameters(deep)
    huge = tmp_path / "huge.toml"
    huge.write_text(REFERENCE_TEXT.replace("mass = 2.75", 'mass = "' + "x" * 900_000 + '"', 1))
    with pytest.raises(ConfigError, match=r"bodies\.platform1\.mass.*more characters.*a number") as info:
        load_parameters(huge)
    assert_clean_message(str(info.value))


def test_a_robot_name_with_terminal_escapes_is_printed_escaped(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    robot = tmp_path / "robot.toml"
    robot.write_text(REFERENCE_TEXT.replace('name = "reference', 'name = "\\u001b[2Jwiped', 1))
    assert load_parameters(robot).name.startswith("\x1b[2J")  # kept as given ...
    status, out, err = run_cli(capsys, ["describe", "--config", str(robot)])
    assert status == 0 and "\x1b" not in out  # ... and escaped on output
    assert "robot      \\x1b[2Jwiped" in out


# --- (b) path CSV files ------------------------------------------------------------------------------


def weighted(*choices: tuple[int, st.SearchStrategy[Any]]) -> st.SearchStrategy[Any]:
    """One of the strategies, each drawn with its weight."""
    return st.sampled_from([s for weight, s in choices for _ in range(weight)]).flatmap(lambda s: s)


csv_numbers = weighted(
    (6, st.floats(min_value=-0.2, max_value=0.8)),
    (1, st.sampled_from([*SPECIAL_FLOATS, 1e3, 1001.0, 0.66])),
    (1, st.floats(allow_nan=True, allow_infinity=True)),
)


@st.composite
def csv_files(draw: st.DrawFn) -> bytes:
    """A path CSV file: mostly valid structure with bad numbers, steps, cells and bytes."""
    good_header = st.sampled_from(["t,x,y,z", "T , X , Y , Z", "\ufefft,x,y,z"])
    bad_header = st.sampled_from(["t,x,y", "time,x,y,z", "t,x,y,z,w", "", "t;x;y;z"])
    header = draw(weighted((6, good_header), (1, bad_header)))
    rows = draw(weighted((5, st.integers(2, 6)), (1, st.integers(0, 1))))
    step = draw(weighted((6, st.just(0.01)), (1, st.sampled_from([1.0, 1e-7, 1e-300, 0.0, -0.01, 1e300, 1e11]))))
    lines = [header]
    t = draw(weighted((6, st.just(0.0)), (1, st.sampled_from([-5.0, 1.7e9, 1e13]))))
    for _ in range(rows):
        cells = [repr(t)] + [repr(draw(csv_numbers)) for _ in range(3)]
        if draw(st.integers(0, 15)) == 0:
            cells[draw(st.integers(0, 3))] = draw(st.sampled_from(NASTY_TEXT[:-3] + ['"', "1,5", "--1", "0x10"]))
        if draw(st.integers(0, 20)) == 0:
            cells = cells[: draw(st.integers(0, 4))] + ["0"] * draw(st.integers(0, 2))
        lines.append(",".join(cells))
        t += step * draw(weighted((8, st.just(1.0)), (1, st.sampled_from([2.0, 0.5]))))
    text = draw(st.sampled_from(["\n", "\r\n", "\n\n"])).join(lines) + "\n"
    data = text.encode("utf-8", "surrogatepass")
    if draw(st.integers(0, 6)) == 0:
        data = draw(damaged_text(text))
    return data


def check_path_file(file: Path, dt: Any) -> paths.TipPath | None:
    try:
        path = paths.from_csv(file, dt)
    except Exception as exc:  # noqa: BLE001  (any exception is judged here)
        assert_project_error(exc, PathError)
        return None
    assert 2 <= len(path) <= paths.MAX_SAMPLES
    return path


@fuzz(200)
@given(data=csv_files(), dt=st.sampled_from([None, None, 0.01, 0.005, 0.0, -1.0, math.nan, math.inf, 1e-300, "x"]))
def test_path_csv_files_load_or_fail_with_one_line(data: bytes, dt: Any) -> None:
    with scratch() as folder:
        file = folder / "path.csv"
        file.write_bytes(data)
        check_path_file(file, dt)


@pytest.mark.parametrize(
    ("rows", "expected"),
    [
        ("0,1e300,0,0\n1,0,0,0\n", r"line 2: x,y,z column 'x' is 1e\+300 m, expected a coordinate within"),
        ("0,0,0,0\n1e300,0,0,0\n", r"line 3: t is 1e\+300 s, expected a time within"),
        ("0,0,0,0\n1e-300,0,0,0\n", r"only 1e-300 s after 0\.0 \(line 2\); samples must be at least 1e-06 s apart"),
        ("0,0,0,0\n1e6,0,0,0\n", None),  # two samples a day apart: a valid, slow path
    ],
)
def test_path_values_that_overflowed_are_refused(tmp_path: Path, rows: str, expected: str | None) -> None:
    file = tmp_path / "p.csv"
    file.write_text("t,x,y,z\n" + rows)
    if expected is None:
        assert len(paths.from_csv(file)) == 2
        with pytest.raises(PathError, match=r"makes 1e\+09 samples; at most 10,000,000") as info:
            paths.from_csv(file, 1e-3)
    else:
        with pytest.raises(PathError, match=expected) as info:
            paths.from_csv(file)
    assert_clean_message(str(info.value))


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        ("1,0," + "9" * 100 + "q" * 100_000 + ",0", r"line 3, column 'y': '9+\.\.\. \(100042 more characters\)"),
        ("1," * 10_000_000, r"line 3: expected 4 fields \(t,x,y,z\), found 10000001: \['1', '1', .*more characters"),
        ("1,0," + "q" * 200_000 + ",0", r"not a readable CSV text file: field larger than field limit"),
    ],
    ids=["long cell", "20 MB line", "cell over the csv limit"],
)
def test_a_huge_bad_line_is_cut_in_the_message(tmp_path: Path, line: str, expected: str) -> None:
    file = tmp_path / "p.csv"
    file.write_text("t,x,y,z\n0,0,0,0\n" + line + "\n")
    with pytest.raises(PathError, match=expected) as info:
        paths.from_csv(file)
    assert_clean_message(str(info.value))


@st.composite
def reachable_csv_files(draw: st.DrawFn) -> bytes:
    """A valid path CSV near the reference robot's tip at home, (0, 0, 0.66) m, 10 ms apart, with
    at most one fault: a bad cell, a far or non-finite point, a repeated time."""
    rows = [[0.01 * k, draw(st.floats(-0.005, 0.005)), draw(st.floats(-0.005, 0.005)), 0.66] for k in range(5)]
    lines = ["t,x,y,z"] + [",".join(repr(v) for v in row) for row in rows]
    fault = draw(st.sampled_from(["none", "none", "none", "cell", "far", "time"]))
    k = draw(st.integers(1, len(rows)))
    if fault == "cell":
        cells = lines[k].split(",")
        cells[draw(st.integers(0, 3))] = draw(st.sampled_from(NASTY_TEXT + ["1e300", "nan", "0.7"]))
        lines[k] = ",".join(cells)
    elif fault == "far":
        lines[k] = f"{0.01 * (k - 1)!r},{draw(st.sampled_from(['0.5', '1e300', '-2', '1e3']))},0,0.66"
    elif fault == "time":
        lines[k] = lines[k - 1]
    return ("\n".join(lines) + "\n").encode("utf-8", "surrogatepass")


@fuzz(40)
@given(
    data=reachable_csv_files(),
    dt=weighted(
        (4, st.none()), (2, st.just("0.005")), (1, st.sampled_from(["0", "-1e-3", "nan", "1e-300", "1e-9", "\x1b[1m"]))
    ),
)
def test_ik_on_fuzzed_path_files(capsys: pytest.CaptureFixture[str], data: bytes, dt: str | None) -> None:
    with scratch() as folder:
        (folder / "path.csv").write_bytes(data)
        argv = ["ik", "--path", "path.csv", "-o", "out/q.csv"] + ([] if dt is None else ["--dt", dt])
        status, out, err = run_cli(capsys, argv)
        assert_cli_outcome(status, out, err, argv)
        if status != 0:
            assert listing(folder) == {"path.csv"}, argv


# --- (c) study files ---------------------------------------------------------------------------------

STUDY_FILES = ["path.csv", "robot.toml", "", ".", "/dev/zero", "missing.csv", "../x", "\x1b]0;title\x07"]


@st.composite
def study_data(draw: st.DrawFn) -> dict[str, Any]:
    data = draw(mutated(STUDY))
    if draw(st.integers(0, 3)) == 0 and isinstance(data.get("study"), dict):
        head = data["study"]
        head.pop("case", None)
        head[draw(st.sampled_from(["path", "robot"]))] = draw(st.sampled_from(STUDY_FILES))
    return data


def check_study_file(file: Path) -> None:
    from vgtarm.study.spec import MAX_POINTS, load_study

    try:
        study = load_study(file)
    except Exception as exc:  # noqa: BLE001  (any exception is judged here)
        assert_project_error(exc, ConfigError)
        return
    assert 1 <= len(study.points()) <= MAX_POINTS


@fuzz(120)
@given(data=study_data())
def test_mutated_study_files_load_or_fail_with_one_line(data: dict[str, Any]) -> None:
    with scratch() as folder:
        (folder / "path.csv").write_text(GOOD_CSV)
        (folder / "robot.toml").write_text(REFERENCE_TEXT)
        (folder / "study.toml").write_text(to_toml(data), encoding="utf-8")
        check_study_file(folder / "study.toml")


@fuzz(50)
@given(data=damaged_text(STUDY_TEXT))
def test_damaged_study_files_fail_with_one_line(data: bytes) -> None:
    with scratch() as folder:
        (folder / "study.toml").write_bytes(data)
        check_study_file(folder / "study.toml")


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("[study]\ncase = 1\nseeds = 9223372036854775807\n", r"runs .*; at most 100,000"),
        (
            "[study]\ncase = 1\n[grid]\nhorizon = [1, 2, 3, 4, 5, 6, 7, 8, 9, 10]\nsubsteps = "
            + str(list(range(1, 20001))),
            r"200,000 runs",
        ),
        ("[study]\ncase = 1\n[random]\ndraws = 9223372036854775807\nmodel_mass = {uniform = [0.9, 1.1]}\n", r"at most"),
        (
            "[study]\ncase = 1\n[random]\ndraws = 2\n"
            "horizon = {integers = [-9223372036854775808, 9223372036854775807]}\n",
            r"random\.horizon \(draw \d\) = -?\d+: expected a whole number from 1 to 10,000 \(control periods; SCM\)",
        ),
        ('[study]\npath = "/dev/zero"\n', r"study\.path: file /dev/zero: is a character device; expected a regular"),
        ('[study]\ncase = 1\nrobot = "' + "r" * 5000 + '"\n', r"more characters"),
    ],
)
def test_study_files_that_would_not_fit_are_refused(tmp_path: Path, text: str, expected: str) -> None:
    from vgtarm.study.spec import load_study

    file = tmp_path / "study.toml"
    file.write_text(text)
    with pytest.raises(ConfigError, match=expected) as info:
        load_study(file)
    assert_clean_message(str(info.value))


@pytest.mark.parametrize(
    ("files", "head", "expected"),
    [
        (
            {"p.csv": "t,x,y,z\n0,0,0,0.66\n0.01,0,0,abc\n"},
            'path = "p.csv"',
            r"study\.path = 'p\.csv': line 3, column 'z'",
        ),
        (
            {"r.toml": "a = " + "[" * 10_000 + "]" * 10_000},
            'case = 1\nrobot = "r.toml"',
            r"study\.robot.*nested too deep",
        ),
        ({"r.toml": REFERENCE_TEXT.replace("h1 = 0.10", "h1 = -1")}, 'case = 1\nrobot = "r.toml"', r"geometry\.h1"),
    ],
    ids=["bad path file", "deep robot file", "bad robot value"],
)
def test_a_study_refuses_bad_robot_and_path_files_when_loaded(
    tmp_path: Path, files: dict[str, str], head: str, expected: str
) -> None:
    from vgtarm.study.spec import load_study

    for name, text in files.items():
        (tmp_path / name).write_text(text)
    (tmp_path / "study.toml").write_text(f"[study]\n{head}\n")
    with pytest.raises(ConfigError, match=expected) as info:
        load_study(tmp_path / "study.toml")
    assert_clean_message(str(info.value))


# --- (d) command lines -------------------------------------------------------------------------------

NUMBERS = ["0", "1", "-1", "-1e-3", "1e-3", "0.28", "nan", "inf", "-inf", "1e300", "1e309", "", "abc", "0x10", "1_0"]
# (No NUL characters: a real command line cannot hold them; the API tests below try them.)
GARBAGE = ["", "-", "--", "\x1b[31m", "x" * 5000, "é", "--config", "-o", "$(rm)", "..", "/", "/dev/zero"]
FILES = ["robot.toml", "bad.toml", "path.csv", "missing.toml", "out", "out/new.xml", "", ".", "/dev/zero", "path.csv/x"]
OUT_FILES = ["out/result.csv", "out/robot.xml", "out/s.toml", "path.csv", "robot.toml", "out", ".", "", "/", "x.csv"]
SAFE_TIMES = ["0.002", "0.001", "0", "-1", "nan", "abc", "1e-300"]

# Each subcommand: fixed words, then flags with their value pools (None: a flag without value).
COMMANDS: dict[str, tuple[list[str], dict[str, list[str] | None]]] = {
    "describe": (["describe"], {"--config": FILES}),
    "fk": (["fk"], {"--config": FILES}),
    "ik": (
        ["ik"],
        {
            "--case": ["1", "2", "3", "0", "", "1.0"],
            "--path": FILES,
            "--dt": ["0.5", "1", "1e-300", "1e-9", "0", "-1", "nan", "x"],
            "--solver": ["fast", "reference", "bogus", ""],
            "--rates": ["exact", "finite_difference", "bogus"],
            "-o": OUT_FILES,
            "--pose": None,
            "--config": FILES,
        },
    ),
    "export": (["export", "mjcf"], {"--out": OUT_FILES, "--timestep": NUMBERS, "--config": FILES}),
    "study init": (["study", "init"], {"--force": None}),
    # Pictures and videos only where they fail fast (no run folder is valid here): their checks.
    "draw": (["draw"], {"--out": ["out/x.txt", "out/x", "/", "", "path.csv/x.png"], "--config": FILES}),
    "animate": (
        ["animate", "."],
        {"--out": ["out/v.gif", "out/v.mp4", "out/v.avi"], "--fps": NUMBERS, "--speed": NUMBERS, "--dpi": NUMBERS},
    ),
    "report": (["report", "path.csv"], {"--out": ["out", ".", "/", ""], "--title": GARBAGE, "--config": FILES}),
    "simulate": (
        ["simulate", "--case", "1", "-q", "--duration"],
        {
            "--controller": ["cfc", "scm", "pid"],
            "--model-mass": NUMBERS,
            "--substeps": ["1", "2", "0", "-1", "x"],
            "--seed": ["0", "-1", "x", "18446744073709551616"],
            "--integrator": ["euler", "rk4", "bogus"],
            "--horizon": ["1", "0", "x"],
            "--out": ["out/run", "path.csv", ".", "", "/"],
            "--config": FILES,
        },
    ),
}


@st.composite
def command_lines(draw: st.DrawFn) -> list[str]:
    name = draw(st.sampled_from(sorted(COMMANDS)))
    words, flags = COMMANDS[name]
    argv = list(words)
    if name == "simulate":  # only tiny runs: --duration is always given, a few control periods
        argv.append(draw(st.sampled_from(SAFE_TIMES)))
    if name == "fk":
        joint_values = st.sampled_from(NUMBERS[:6] + ["0.22", "0.36", "0.46", "3.2", "-3.2"])
        argv += [draw(joint_values) for _ in JOINT_NAMES]
    if name == "study init":
        argv.append(draw(st.sampled_from(OUT_FILES + GARBAGE[:4])))
    if name == "ik" and draw(st.booleans()):
        argv += ["--path", "path.csv"]
    for flag in draw(st.lists(st.sampled_from(sorted(flags)), max_size=4, unique=True)):
        pool = flags[flag]
        argv += [flag] if pool is None else [flag, draw(st.sampled_from(pool + GARBAGE))]
    for _ in range(draw(st.sampled_from([0, 0, 0, 1, 2]))):  # stray tokens anywhere
        token = draw(
            st.one_of(
                st.sampled_from(GARBAGE + NUMBERS), st.text(st.characters(exclude_characters="\x00"), max_size=10)
            )
        )
        argv.insert(draw(st.integers(1, len(argv))), token)
    if draw(st.integers(0, 9)) == 0 and len(argv) > 1:  # a dropped token
        del argv[draw(st.integers(1, len(argv) - 1))]
    return argv


@fuzz(250)
@given(argv=command_lines())
def test_random_command_lines_succeed_or_fail_with_one_line(
    capsys: pytest.CaptureFixture[str], argv: list[str]
) -> None:
    with scratch() as folder:
        (folder / "robot.toml").write_text(REFERENCE_TEXT)
        (folder / "bad.toml").write_text(REFERENCE_TEXT.replace("h1 = 0.10", "h1 = -1", 1))
        (folder / "path.csv").write_text(GOOD_CSV)
        inputs = {name: (folder / name).read_bytes() for name in listing(folder)}
        status, out, err = run_cli(capsys, argv)
        assert_cli_outcome(status, out, err, argv)
        if status != 0:  # nothing written, nothing left over, the inputs untouched
            assert listing(folder) == set(inputs), f"{argv!r} left {sorted(listing(folder) - set(inputs))}"
            assert all((folder / name).read_bytes() == data for name, data in inputs.items()), argv


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["describe", "--config", "/dev/zero"], "configuration file /dev/zero: is a character device; expected"),
        (["describe", "--config", ""], "configuration file .: is a folder, not a file"),  # argparse: Path("") is "."
        (["ik", "--path", "far.csv"], "line 2: x,y,z column 'x' is 1e+300 m, expected a coordinate within +-1000 m"),
        (["ik", "--path", "close.csv"], "only 1e-300 s after 0.0 (line 2); samples must be at least 1e-06 s apart"),
        (["ik", "--path", "path.csv", "--dt", "1e-9"], "dt = 1e-09: expected a finite number >= 1e-06 (s)"),
        (["ik", "--path", "path.csv", "--dt", "x" * 10_000], "got 'xxxxxxxx"),
        (["study", "init", ""], "FILE .: is a folder; give a file name"),
    ],
)
def test_commands_of_the_issue_end_in_one_line(
    capsys: pytest.CaptureFixture[str], argv: list[str], expected: str
) -> None:
    with scratch() as folder:
        (folder / "path.csv").write_text(GOOD_CSV)
        (folder / "far.csv").write_text("t,x,y,z\n0,1e300,0,0\n1,0,0,0\n")
        (folder / "close.csv").write_text("t,x,y,z\n0,0,0,0.66\n1e-300,0,0,0.66\n")
        before = listing(folder)
        status, out, err = run_cli(capsys, argv)
        assert_cli_outcome(status, out, err, argv)
        assert status == 1 and expected in err
        assert listing(folder) == before
