"""Data and error logs: round trip, the seed's text and CSV, sorting, and a killed writer."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from modules.common.logs import (
    DataLog,
    ErrorLog,
    LogError,
    convert_csv,
    convert_text,
    read_log,
    sort_log,
    summary,
)
from tokenring.cli import main as cli_main

CONFIG = {"sensors": {}}


def small_log(path: Path) -> None:
    with DataLog(path, "20040120-130535", CONFIG) as log:
        log.write(100, "O", "R", {"gen": 0, "n": 0, "v": {"steps_left": 10, "steps_right": 12}})
        log.write(90, "G", "R", {"gen": 0, "n": 1, "v": {"heading_cdeg": 9000, "state": 1}, "seq": 4})
        log.write(100, "O", "C", {"gen": 0, "dl": 10, "dr": 12, "count": 1, "stamp_ms": 100})
        log.write(100, "G", "C", {"gen": 0, "heading": 1.5707963, "count": 1, "stamp_ms": 90})
        log.write(
            100, "W", "C", {"gen": 0, "distances_mm": [500, None], "walls": [], "count": 1, "stamp_ms": 95}
        )
        log.write(100, "L", "P", {"x": 1000.0, "y": 1000.0, "psi": 0.0, "valid": [True, True, True]})
        log.write(100, "K", "P", {"x": 1003.2, "y": 998.1, "psi": 0.01, "valid": [True, False, True]})
        log.write(100, "S", "S", {"gen": 0, "period_ms": 100, "counts": {"odometry": 1, "compass": 1}})


def test_round_trip_and_the_seeds_text_format(tmp_path: Path) -> None:
    small_log(tmp_path / "a.trlog")
    log = read_log(tmp_path / "a.trlog", expect="data")
    assert log.header["start"] == "20040120-130535" and log.header["config"] == CONFIG
    assert len(log.records) == 8 and not log.truncated
    lines = convert_text(log).splitlines()
    assert lines[0].split() == ["S", "T", "0", "20040120-130535"]
    assert lines[1].split() == ["O", "R", "100", "10", "12"]
    assert lines[3].split() == ["O", "C", "100", "10", "12", "1"]
    assert lines[7].split() == ["K", "P", "100", "1003", "998", "0.01000", "1", "0", "1"]
    assert lines[-1].split()[:4] == ["S", "S", "100", "0"]


def test_csv_has_one_line_per_synchronisation(tmp_path: Path) -> None:
    small_log(tmp_path / "a.trlog")
    data, sonar = convert_csv(read_log(tmp_path / "a.trlog"))
    header, row = data.splitlines()
    columns = dict(zip(header.split(","), row.split(","), strict=True))
    assert columns["steps_left"] == "10" and columns["x"] == "1003.2" and columns["y_valid"] == "0"
    assert columns["truth_x"] == "1000.0"
    assert sonar.splitlines() == ["stamp_ms,sonar0_mm,sonar1_mm", "100,500,"]


def test_sort_orders_by_time_stamp_into_a_new_file(tmp_path: Path) -> None:
    small_log(tmp_path / "a.trlog")
    assert sort_log(tmp_path / "a.trlog", tmp_path / "b.trlog") == 8
    stamps = [r[0] for r in read_log(tmp_path / "b.trlog").records]
    assert stamps == sorted(stamps) and stamps[0] == 90
    with pytest.raises(LogError, match="new file"):
        sort_log(tmp_path / "a.trlog", tmp_path / "a.trlog")


def test_error_log_classes(tmp_path: Path) -> None:
    with ErrorLog(tmp_path / "e.trerr", "now", debug=False) as log:
        log.message("I", 479, "Configuration read succesfully")
        log.message("D", 480, "dropped: debug is off")
        log.message("E", 3647, "odometry: 2 samples missed")
        with pytest.raises(ValueError, match="error class"):
            log.message("X", 1, "no such class")
    text = convert_text(read_log(tmp_path / "e.trerr", expect="errors"))
    assert text.splitlines() == [
        "I      479 Configuration read succesfully",
        "E     3647 odometry: 2 samples missed",
    ]


WRITER = textwrap.dedent(
    """
    import sys, time
    from modules.common.logs import DataLog
    log = DataLog(sys.argv[1], "now", {})
    i = 0
    while True:
        log.write(i, "O", "R", {"gen": 0, "n": i, "v": {"steps_left": i, "steps_right": -i}})
        i += 1
        if i == 2000:
            print("written", flush=True)
        if i > 2000:
            time.sleep(0.0005)
    """
)


def test_log_survives_a_killed_writer(tmp_path: Path) -> None:
    path = tmp_path / "killed.trlog"
    writer = subprocess.Popen([sys.executable, "-c", WRITER, str(path)], stdout=subprocess.PIPE, text=True)
    try:
        assert writer.stdout.readline().strip() == "written"
        time.sleep(0.05)
    finally:
        os.kill(writer.pid, signal.SIGKILL)
        writer.wait(timeout=10)
    log = read_log(path)
    assert len(log.records) >= 2000
    assert [r[3]["n"] for r in log.records] == list(range(len(log.records)))
    # a torn last record (a kill in the middle of a write) is dropped and reported, not fatal
    data = path.read_bytes()
    path.write_bytes(data[:-3])
    torn = read_log(path)
    assert torn.truncated and len(torn.records) == len(log.records) - 1
    assert summary(torn)["truncated"]


def test_log_command_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    small_log(tmp_path / "a.trlog")
    assert cli_main(["log", "convert", str(tmp_path / "a.trlog")]) == 0
    assert "K P      100" in capsys.readouterr().out
    assert (
        cli_main(["log", "convert", str(tmp_path / "a.trlog"), "--to", "csv", "--out", str(tmp_path / "csv")])
        == 0
    )
    assert (tmp_path / "csv" / "data.csv").exists() and (tmp_path / "csv" / "sonar.csv").exists()
    assert cli_main(["log", "info", str(tmp_path / "a.trlog"), "--json"]) == 0
    assert '"O R": 1' in capsys.readouterr().out
    assert cli_main(["log", "sort", str(tmp_path / "a.trlog"), "--out", str(tmp_path / "s.trlog")]) == 0
    assert cli_main(["log", "convert", str(tmp_path / "a.trlog"), "--to", "csv"]) == 2
    assert "give the directory with --out" in capsys.readouterr().err
    (tmp_path / "text.txt").write_text("O R 100 1 2\n")
    assert cli_main(["log", "info", str(tmp_path / "text.txt")]) == 2
    assert "not a tokenring log" in capsys.readouterr().err
