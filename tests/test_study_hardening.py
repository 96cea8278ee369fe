"""Studies refuse what they cannot run well, up front and in one line, and write tables that are
safe to open: formula injection in results.csv, scheduler addresses, copied run files, the
period, path files that are not path files, huge seed counts, the MuJoCo plant and its gains.

Hypothesis runs derandomized (the project's rule: same seed, same examples).
"""

from __future__ import annotations

import csv
import http.server
import json
import math
import shutil
import socket
import socketserver
import threading
import time
from collections.abc import Iterator
from importlib import resources
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

pytest.importorskip("distributed")
pytest.importorskip("pyarrow")

from vgtarm.app.cli.command import main  # noqa: E402
from vgtarm.app.study_points import check_point, execute_point, simulate_command  # noqa: E402
from vgtarm.errors import ConfigError, InputError  # noqa: E402
from vgtarm.study import TIMING_COLUMNS, Store, load_study, runner  # noqa: E402
from vgtarm.study.runner import run_study, scheduler_address  # noqa: E402
from vgtarm.study.store import FORMULA_STARTS, _cell, spreadsheet_text  # noqa: E402

#: Longest wait for a scheduler in these tests (s): every server here is on this machine.
TIMEOUT = 2.0
ROBOT_FILE = "=cmd|' -C calc'!A0.toml"
ROBOT_NAME = "=cmd|' /C calc'!A0"


def fuzz(examples: int) -> Any:
    """Reproducible settings, no per-example deadline (as tests/test_fuzz.py)."""
    return settings(
        max_examples=examples,
        deadline=None,
        derandomize=True,
        database=None,
        suppress_health_check=[HealthCheck.function_scoped_fixture],
    )


def _one_line(text: str) -> str:
    lines = text.strip().splitlines()
    assert len(lines) == 1, text
    return lines[0]


# -- results.csv: formula injection -----------------------------------------------------------


@pytest.fixture(scope="module")
def hostile_run(tmp_path_factory: pytest.TempPathFactory) -> Any:
    """A cheap real study (two seeds, 20 ms of case 1) on a robot whose file and name are formulas."""
    folder = tmp_path_factory.mktemp("hostile")
    reference = resources.files("vgtarm.model.data").joinpath("reference_robot.toml").read_text("utf-8")
    lines = [
        f"name = {json.dumps(ROBOT_NAME)}" if line.startswith("name =") else line for line in reference.splitlines()
    ]
    (folder / ROBOT_FILE).write_text("\n".join(lines) + "\n")
    (folder / "study.toml").write_text(
        f'[study]\ncase = 1\nduration = 0.02\nseeds = [0, 1]\nrobot = "{ROBOT_FILE}"\n[grid]\ncontroller = "cfc"\n'
    )
    return run_study(load_study(folder / "study.toml"), folder / "out", execute_point, workers=1, progress=False)


def test_csv_cells_that_would_be_formulas_are_text_and_parquet_keeps_them(hostile_run: Any) -> None:
    import pyarrow.parquet as pq

    assert [row["success"] for row in hostile_run.rows] == [True, True]
    with open(hostile_run.folder / "results.csv", newline="", encoding="utf-8") as stream:
        table = list(csv.DictReader(stream))
    parquet = pq.read_table(hostile_run.folder / "results.parquet").to_pylist()
    assert len(table) == len(parquet) == 2
    for written, true in zip(table, parquet, strict=True):
        assert written["robot"] == "'" + ROBOT_FILE and true["robot"] == ROBOT_FILE
        assert written["plant"] == written["controller_model"] == "'" + ROBOT_NAME
        assert true["plant"] == true["controller_model"] == ROBOT_NAME
        for column, value in true.items():  # every number is written as the number it is
            if isinstance(value, float) and not isinstance(value, bool) and math.isfinite(value):
                assert float(written[column]) == value, column
            elif isinstance(value, int) and not isinstance(value, bool):
                assert int(written[column]) == value, column
        assert not any(cell.startswith(FORMULA_STARTS) for cell in written.values())


@fuzz(300)
@given(st.text(alphabet=st.sampled_from(["=", "+", "-", "@", "\t", "\r", "'", "a", "1", " ", ",", '"', "\n"])))
def test_spreadsheet_text_prefixes_exactly_the_formula_starts(text: str) -> None:
    safe = spreadsheet_text(text)
    if text.startswith(FORMULA_STARTS):
        assert safe == "'" + text
    else:
        assert safe == text
    assert not safe.startswith(FORMULA_STARTS)
    assert _cell(text) == safe


@fuzz(200)
@given(st.one_of(st.floats(allow_nan=False, allow_infinity=False), st.integers(-(2**63), 2**63 - 1)))
def test_numbers_are_written_as_numbers_even_when_negative(number: float | int) -> None:
    cell = _cell(number)
    assert cell == (repr(number) if isinstance(number, float) else number)
    assert float(cell) == float(number)


def test_a_negative_number_stays_a_number_and_the_same_text_is_made_text(tmp_path: Path) -> None:
    store = Store(tmp_path)
    store.prepare()
    store.write_tables([{"id": "a", "x": -1.5, "n": -3, "label": "-1.5", "note": "@SUM(A1)"}])
    with open(tmp_path / "results.csv", newline="", encoding="utf-8") as stream:
        (row,) = list(csv.DictReader(stream))
    assert row == {"id": "a", "x": "-1.5", "n": "-3", "label": "'-1.5", "note": "'@SUM(A1)"}


# -- run files: one row per stored id ----------------------------------------------------------


def test_each_stored_id_has_its_own_row_and_a_copied_run_file_is_refused(
    hostile_run: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    ids = [row["id"] for row in hostile_run.rows]
    with open(hostile_run.folder / "results.csv", newline="", encoding="utf-8") as stream:
        assert [row["id"] for row in csv.DictReader(stream)] == ids and len(set(ids)) == 2
    study = hostile_run.folder.parent / "study.toml"
    out = tmp_path / "out"
    shutil.copytree(hostile_run.folder, out)
    first, second = ids
    shutil.copyfile(out / f"{first}.json", out / f"{second}.json")  # same content, other id
    before = (out / "results.csv").read_bytes()
    assert main(["study", "run", str(study), "--out", str(out), "-q"]) == 1
    line = _one_line(capsys.readouterr().err)
    assert f"{second}.json" in line and repr(first) in line and "copy" in line
    assert (out / "results.csv").read_bytes() == before  # refused before any run or table
    with pytest.raises(InputError, match="not a run record"):
        (out / f"{second}.json").write_text("[1, 2]\n")
        Store(out).read(second)


# -- --scheduler ----------------------------------------------------------------------------


@pytest.fixture
def study_file(tmp_path: Path) -> Path:
    file = tmp_path / "study.toml"
    file.write_text("[study]\ncase = 1\nduration = 0.02\nseeds = [0]\n")
    return file


@pytest.fixture
def servers(monkeypatch: pytest.MonkeyPatch) -> Iterator[dict[str, str]]:
    """Addresses on 127.0.0.1 that are no Dask scheduler: an HTTP server (waits for a request
    line), a server that answers HTTP at once, and a closed port. No traffic leaves the machine."""
    monkeypatch.setattr(runner, "CONNECT_TIMEOUT", TIMEOUT)

    class Rude(socketserver.BaseRequestHandler):
        def handle(self) -> None:
            self.request.sendall(b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n" * 4)
            time.sleep(0.2)

    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, *args: Any) -> None:
            pass

    http_server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Quiet)
    rude = socketserver.ThreadingTCPServer(("127.0.0.1", 0), Rude)
    for server in (http_server, rude):
        threading.Thread(target=server.serve_forever, daemon=True).start()
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        closed = probe.getsockname()[1]  # free once closed: nothing listens there
    try:
        yield {
            "http": f"tcp://127.0.0.1:{http_server.server_address[1]}",
            "http-answers-at-once": f"tcp://127.0.0.1:{rude.server_address[1]}",
            "websocket-to-http": f"ws://127.0.0.1:{http_server.server_address[1]}",
            "closed-port": f"tcp://127.0.0.1:{closed}",
        }
    finally:
        for server in (http_server, rude):
            server.shutdown()
            server.server_close()


@pytest.mark.parametrize(
    "address", ["", "garbage!!://x y", "inproc://x", "tcp://127.0.0.1", "tcp://127.0.0.1:0", "udp://127.0.0.1:8786"]
)
def test_a_malformed_scheduler_address_is_refused_before_anything(
    study_file: Path, address: str, capsys: pytest.CaptureFixture[str]
) -> None:
    out = study_file.parent / "out"
    assert main(["study", "run", str(study_file), "--out", str(out), "--scheduler", address, "-q"]) == 1
    line = _one_line(capsys.readouterr().err)
    assert f"--scheduler {address!r}" in line and "SCHEME://HOST:PORT" in line
    assert not out.exists()


@pytest.mark.parametrize("kind", ["http", "http-answers-at-once", "websocket-to-http", "closed-port"])
def test_an_address_without_a_dask_scheduler_is_refused_in_bounded_time(
    study_file: Path, servers: dict[str, str], kind: str, capsys: pytest.CaptureFixture[str]
) -> None:
    out = study_file.parent / "out"
    assert main(["study", "run", str(study_file), "--out", str(out), "--scheduler", servers[kind], "-q"]) == 1
    line = _one_line(capsys.readouterr().err)
    assert f"--scheduler {servers[kind]!r}" in line and "Dask scheduler" in line and "EiB" not in line
    assert not out.exists()  # no empty runs/ folder


@fuzz(300)
@given(st.text(alphabet=st.sampled_from(list("tcpwsl:/[]0123456789.ab -_!\x1b")), max_size=30))
def test_scheduler_addresses_are_checked_in_one_line(text: str) -> None:
    try:
        address = scheduler_address(text)
    except InputError as exc:
        assert str(exc).startswith("--scheduler ") and "\n" not in str(exc) and "\x1b" not in str(exc)
    else:
        scheme, rest = address.split("://")
        host, port = rest.rsplit(":", 1)
        assert scheme in runner.SCHEDULER_SCHEMES and host and 1 <= int(port) <= 65535


# -- study files -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("head", "named"),
    [
        ("case = 1\ndt = 10", "study.dt = 10.0"),
        ("case = 2\ndt = 10.0", "study.dt = 10.0"),
        ("case = 1\ndt = 1e-12", "study.dt = 1e-12"),
        ("case = 1\nseeds = 100000000", "100,000,000 seeds (study.seeds = 100000000)"),
        (
            "case = 1\nseeds = {start = 7, count = 123456}",
            "123,456 seeds (study.seeds = {'start': 7, 'count': 123456})",
        ),
    ],
)
def test_a_study_that_cannot_run_well_is_refused_up_front(
    tmp_path: Path, head: str, named: str, capsys: pytest.CaptureFixture[str]
) -> None:
    study = tmp_path / "study.toml"
    study.write_text(f"[study]\n{head}\n")
    out = tmp_path / "out"
    assert main(["study", "run", str(study), "--out", str(out), "-q"]) == 1
    line = _one_line(capsys.readouterr().err)
    assert named in line and "reference t" not in line
    assert not out.exists()


SECRET = "root:$6$s3cr3t-hash:19000:0:99999:7:::"


@pytest.mark.parametrize(
    "text",
    [
        f"{SECRET}\ndaemon:*:19000:0:99999:7:::\n",  # not a path file at all (as /etc/shadow)
        f"t,x,y,z\n0,0,0,0\n1,{SECRET},0,0\n",  # a header, then a value that is no number
        f"t,x,y,z\n0,0,0,0\n{SECRET}\n",  # a row of the wrong width
        f"t,x,y,z\n0,0,0,0\n1,0,0,{SECRET.replace(':', '')}\n",
    ],
)
def test_a_file_that_is_not_a_path_file_is_never_quoted(
    tmp_path: Path, text: str, capsys: pytest.CaptureFixture[str]
) -> None:
    secret = tmp_path / "secret"
    secret.write_text(text)
    study = tmp_path / "study.toml"
    study.write_text(f"[study]\npath = {json.dumps(str(secret))}\n")  # an absolute path, as /etc/shadow
    with pytest.raises(ConfigError) as refused:
        load_study(study)
    assert "s3cr3t" not in str(refused.value) and "study.path" in str(refused.value)
    assert main(["study", "run", str(study), "--out", str(tmp_path / "out"), "-q"]) == 1
    line = _one_line(capsys.readouterr().err)
    assert "s3cr3t" not in line and "99999" not in line
    files = {"path": text}  # and where a worker reads it
    with pytest.raises(Exception) as again:  # noqa: PT011 - whatever the reader raises
        check_point({**load_study_inputs(), "path": "secret", "case": None}, files)
    assert "s3cr3t" not in str(again.value)


def load_study_inputs() -> dict[str, Any]:
    """The inputs of a minimal study's one point (every parameter at its default)."""
    from vgtarm.study import parse_study

    return dict(parse_study({"study": {"case": 1, "duration": 0.02}}).points()[0].inputs)


# -- the MuJoCo plant --------------------------------------------------------------------------


def test_a_study_runs_on_the_mujoco_plant_and_its_rows_name_the_plant(tmp_path: Path) -> None:
    pytest.importorskip("mujoco")
    study = tmp_path / "study.toml"
    study.write_text('[study]\ncase = 1\nduration = 0.02\nseeds = [0]\n[grid]\nplant_engine = ["model", "mujoco"]\n')
    run = run_study(load_study(study), tmp_path / "out", execute_point, check=check_point, workers=1, progress=False)
    assert [(row["plant_engine"], row["success"]) for row in run.rows] == [("model", True), ("mujoco", True)]
    model, mujoco = (row["max_tip_error_m"] for row in run.rows)
    assert mujoco == pytest.approx(model, rel=0.05)  # the same robot, another integrator's error
    record = Store(run.folder).read(run.rows[1]["id"])
    command = simulate_command(record["inputs"])
    assert command[command.index("--plant") + 1] == "mujoco"
    assert main([*command, "--out", str(tmp_path / "again"), "-q"]) == 0  # the row, re-run by hand
    again = json.loads((tmp_path / "again" / "summary.json").read_text())
    assert {k: v for k, v in again.items() if k not in TIMING_COLUMNS} == {
        k: v for k, v in record["summary"].items() if k not in TIMING_COLUMNS
    }


def test_a_study_refuses_negative_gains_on_the_mujoco_plant_as_on_the_model(tmp_path: Path) -> None:
    """(Through the Python API both plants take any gains, and unstable ones diverge alike:
    tests/test_mujoco.py.)"""
    study = tmp_path / "study.toml"
    study.write_text('[study]\ncase = 1\n[grid]\nplant_engine = "mujoco"\nkp = -5.0\n')
    with pytest.raises(ConfigError, match=r"grid\.kp = -5\.0: expected a gain > 0"):
        load_study(study)
