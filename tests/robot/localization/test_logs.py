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

from modules.localization.logs import (
    DataLog,
    ErrorLog,
    LogError,
    convert_csv,
    convert_text,
    read_log,
    sort_log,
    summary,
)
from tokenring.cli.main import main as cli_main

CONFIG = {"sensors": {}}


def small_log(path: Path) -> None:
    with DataLog(path, "20040120-130535", CONFIG) as log:
        log.write(100, "O", "R", {"gen": 0, "n": 0, "v": {"steps_left": 10, "steps_right": 12}})
        log.write(90, "M", "R", {"gen": 0, "n": 1, "v": {"heading_cdeg": 9000, "state": 1}, "seq": 4})
        log.write(100, "O", "C", {"gen": 0, "dl": 10, "dr": 12, "count": 1, "stamp_ms": 100})
        log.write(100, "M", "C", {"gen": 0, "heading": 1.5707963, "count": 1, "stamp_ms": 90})
        log.write(
            100, "W", "C", {"gen": 0, "distances_mm": [500, None], "walls": [], "count": 1, "stamp_ms": 95}
        )
        log.write(100, "T", "P", {"x": 1000.0, "y": 1000.0, "psi": 0.0, "valid": [True, True, True]})
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
    from modules.localization.logs import DataLog
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


def realistic_log(path: Path, records: int = 4441) -> None:
    """A data log with odometry, compass and position records, like the localisation's."""
    with DataLog(path, "20260101-000000", {"config": True}) as log:
        for i in range(records):
            if i % 3 == 0:
                log.write(i * 10, "O", "C", {"dl": i * 0.5, "dr": i * 0.5, "count": 2})
            elif i % 3 == 1:
                log.write(i * 10, "M", "R", {"gen": i, "n": 0, "v": {"heading_cdeg": i % 36000, "state": 1}})
            else:
                log.write(i * 10, "K", "P", {"x": float(i), "y": 2.0 * i, "psi": 0.1, "valid": [True] * 3})


def test_damage_in_the_middle_keeps_every_readable_record_and_says_where(tmp_path: Path) -> None:
    """50 flipped bytes kept 118 of 4441 records (read as a torn tail, exit 0) before; now every
    record around them is read, the damage is reported, and only --salvage reads on."""
    import random

    path = tmp_path / "run.trlog"
    realistic_log(path)
    data = bytearray(path.read_bytes())
    middle = len(data) // 2
    rng = random.Random(7)
    for offset in rng.sample(range(middle, middle + 2000), 50):
        data[offset] ^= 0xFF
    path.write_bytes(bytes(data))
    with pytest.raises(LogError, match=r"run.trlog: damaged inside: \d+ bytes unreadable in \d+ place\(s\)"):
        read_log(path)
    log = read_log(path, salvage=True)
    assert log.damaged and not log.truncated
    assert len(log.records) > 4441 - 200, len(log.records)  # the damage spans ~2 KB of ~60-byte records
    stamps = [r[0] for r in log.records]
    assert stamps[0] == 0 and stamps[-1] == 44400  # both ends read
    # the command line: damage is an error (exit 2, one line) unless --salvage
    result = subprocess.run(
        [sys.executable, "-m", "tokenring", "log", "info", str(path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1, result.stderr
    salvaged = subprocess.run(
        [sys.executable, "-m", "tokenring", "log", "info", str(path), "--salvage"],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert salvaged.returncode == 0 and "damaged bytes skipped" in salvaged.stderr, salvaged.stderr


def test_junk_in_the_middle_neither_crashes_convert_nor_analyze(tmp_path: Path) -> None:
    """3000 junk bytes mid-file crashed `log convert` and `analyze` with KeyError: 'dl'."""
    import random

    path = tmp_path / "junk.trlog"
    realistic_log(path, 900)
    data = path.read_bytes()
    middle = len(data) // 2
    junk = random.Random(3).randbytes(3000)
    path.write_bytes(data[:middle] + junk + data[middle:])
    for verb in (["log", "convert", str(path), "--salvage"], ["analyze", str(path), "--salvage"]):
        result = subprocess.run(
            [sys.executable, "-m", "tokenring", *verb], capture_output=True, text=True, timeout=120
        )
        assert result.returncode == 0, (verb, result.stderr[-600:])
        assert "Traceback" not in result.stderr
    log = read_log(path, salvage=True)
    assert len(log.records) >= 900 - 2 and log.damaged


def test_a_record_with_a_payload_no_reader_can_take_is_damage_not_a_crash(tmp_path: Path) -> None:
    """A record of the right shape with junk inside (odometry steps as text) crashed `log
    convert` with a TypeError; now it is damage like unreadable bytes, in the middle or at the end."""
    import msgpack

    for where in ("middle", "end"):
        path = tmp_path / f"{where}.trlog"
        realistic_log(path, 30)
        data = path.read_bytes()
        junk = msgpack.packb([5, "O", "C", {"dl": "ten", "dr": [1], "count": 2}])
        if where == "middle":
            cut = data.index(msgpack.packb([150, "O", "C", {"dl": 7.5, "dr": 7.5, "count": 2}]))
            data = data[:cut] + junk + data[cut:]
        else:
            data += junk
        path.write_bytes(data)
        with pytest.raises(LogError, match="damaged inside"):
            read_log(path)
        log = read_log(path, salvage=True)
        assert len(log.records) == 30 and not log.truncated and log.damaged
        convert = subprocess.run(
            [sys.executable, "-m", "tokenring", "log", "convert", str(path), "--salvage",
             "--out", str(tmp_path / f"{where}.txt")],
            capture_output=True, text=True, timeout=60,
        )  # fmt: skip
        assert convert.returncode == 0 and "Traceback" not in convert.stderr, convert.stderr


def test_a_version_1_log_reads_its_truth_under_l_as_t(tmp_path: Path) -> None:
    """Format 1 logged the world's truth under ``L`` (LOPS's letter while there was no LOPS);
    format 2 has it under ``T``. An old log, written here byte by byte with msgpack, reads back
    with its truth as ``T`` and converts to CSV truth columns as a new one does."""
    import msgpack

    header = {"tokenring_log": "data", "version": 1, "start": "20261201-120000", "config": {}}
    records = [
        [100, "L", "R", {"gen": 0, "n": 0, "v": {"x": 1000.0, "y": 900.0, "theta": 0.5}}],
        [100, "L", "P", {"x": 1000.0, "y": 900.0, "psi": 0.5, "valid": [True, True, True]}],
        [100, "S", "S", {"gen": 0, "period_ms": 100, "counts": {"truth": 1}}],
    ]
    path = tmp_path / "old.trlog"
    path.write_bytes(b"".join(msgpack.packb(entry) for entry in [header, *records]))
    log = read_log(path, expect="data")
    assert [(r[1], r[2]) for r in log.records] == [("T", "R"), ("T", "P"), ("S", "S")]
    data, _ = convert_csv(log)
    row = dict(zip(*[line.split(",") for line in data.splitlines()[:2]], strict=True))
    assert (row["truth_x"], row["truth_y"], row["truth_valid"]) == ("1000.0", "900.0", "1")
    # a new log keeps L for LOPS: nothing is renamed
    with DataLog(tmp_path / "new.trlog", "20261206-120000", {}) as new:
        new.write(5, "L", "P", {"x": 1.0, "y": 2.0, "psi": 0.0, "valid": [True, True, False]})
    assert [r[1] for r in read_log(tmp_path / "new.trlog").records] == ["L"]


@pytest.mark.parametrize("version", [1, 2])
def test_an_older_log_reads_its_compass_under_g_as_m(tmp_path: Path, version: int) -> None:
    """Formats 1 and 2 logged the compass under ``G`` (the gyroscope's letter while there was no
    gyroscope); format 3 has it under ``M`` and ``G`` is the gyroscope's. An old log, written here
    byte by byte with msgpack, reads back with its compass as ``M`` and its heading in the CSV's
    compass column; a new log keeps ``G`` for the gyroscope."""
    import msgpack

    header = {"tokenring_log": "data", "version": version, "start": "20261201-120000", "config": {}}
    records = [
        [90, "G", "R", {"gen": 0, "n": 0, "v": {"heading_cdeg": 9000, "state": 1}}],
        [100, "G", "C", {"gen": 0, "heading": 0.25, "count": 1}],
        [100, "G", "P", {"x": 0.0, "y": 0.0, "psi": 0.25, "valid": [False, False, True]}],
        [100, "S", "S", {"gen": 0, "period_ms": 100, "counts": {"compass": 1}}],
    ]
    path = tmp_path / "old.trlog"
    path.write_bytes(b"".join(msgpack.packb(entry) for entry in [header, *records]))
    log = read_log(path, expect="data")
    assert [(r[1], r[2]) for r in log.records] == [("M", "R"), ("M", "C"), ("M", "P"), ("S", "S")]
    data, _ = convert_csv(log)
    row = dict(zip(*[line.split(",") for line in data.splitlines()[:2]], strict=True))
    assert (row["compass_rad"], row["gyro_rad_s"]) == ("0.25", "")
    with DataLog(tmp_path / "new.trlog", "20261207-120000", {}) as new:
        new.write(5, "G", "C", {"gen": 0, "rate": 0.5, "turn": 0.05, "count": 5})
    again = read_log(tmp_path / "new.trlog")
    assert [r[1] for r in again.records] == ["G"]
    assert convert_csv(again)[0].splitlines()[0].split(",")[5] == "gyro_rad_s"
