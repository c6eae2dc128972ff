"""The seed's logfileconverter output (seed 000, appendix B.3, table B.8): ``tokenring log convert
--to dat`` writes ``data.dat`` and ``sonar.dat``, one line per synchronisation in each.

The expected fields are typed out by hand from the records the test writes, and the columns are
checked against the widths table B.8 gives (each field right-aligned in its width, one blank
between fields), not against the converter's own helpers.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from modules.localization.logs import DataLog, ErrorLog, convert_seed_dat, convert_seed_text, read_log
from tests.robot.localization.test_seed_logs import one_error_line
from tokenring.cli.main import main as cli_main

#: table B.8, data.dat: Zeitpunkt, Takt, Enkoder links/rechts, Gyroskop, Entfernung 1..3,
#: LOPS-X, LOPS-Y, LOPS-Valid, X-Position, Y-Position, Drehung, X-/Y-/Drehung-Valid
DATA_WIDTHS = [8, 4, 8, 8, 15, 8, 8, 8, 8, 8, 1, 8, 8, 8, 1, 1, 1]
#: table B.8, sonar.dat: X and Y of each sonar's obstacle
SONAR_WIDTH = 6
#: three sonars: ahead 150 mm in front, to the left 120 mm out, behind 150 mm back
CONFIG = {"robot": {"sonars": [[150, 0, 0], [0, 120, 90], [-150, 0, 180]]}}


def fixed_fields(line: str, widths: list[int]) -> list[str]:
    """The fields of a fixed-width line: each right-aligned in its width, one blank between;
    fails when a field does not sit in its columns."""
    assert len(line) == sum(widths) + len(widths) - 1, (len(line), line)
    fields, start = [], 0
    for width in widths:
        column = line[start : start + width]
        assert column == column.strip().rjust(width) and column.strip(), (width, column, line)
        assert start == 0 or line[start - 1] == " ", line
        fields.append(column.strip())
        start += width + 1
    assert fields == line.split()  # the blanks separate the fields too
    return fields


def position(x: float, y: float, psi: float, valid: list[bool]) -> dict:
    return {"x": x, "y": y, "psi": psi, "valid": valid, "walls": []}


def darmstadt_log(path: Path) -> None:
    """Three synchronisations with odometry, gyroscope, LOPS, the filter and the sonar (the
    second with LOPS unable to place the robot, y unknown to the filter; the third with
    odometry alone), records table B.8 has no column for, and a synchronisation the log ends
    inside."""
    with DataLog(path, "20040120-130535", CONFIG) as log:
        log.write(990, "O", "R", {"gen": 0, "n": 0, "v": {"steps_left": 120, "steps_right": 118}})
        log.write(1000, "O", "C", {"gen": 0, "dl": 120, "dr": 118, "count": 1})
        log.write(1000, "G", "C", {"gen": 0, "rate": 0.0123456789, "turn": 0.001234567891, "count": 5})
        lops = {"d1": 1500.4, "d2": 2300.6, "d3": None, "x": 1234.4, "y": 2345.6, "counter": 7}
        log.write(1000, "L", "C", {"gen": 0, **lops, "count": 1})
        log.write(1000, "M", "C", {"gen": 0, "heading": 1.2, "count": 1})
        log.write(1000, "W", "C", {"gen": 0, "distances_mm": [500, None, 730], "walls": [], "count": 2})
        log.write(1000, "T", "P", position(1000.0, 2000.0, 0.0, [True, True, True]))
        log.write(1000, "O", "P", position(1001.0, 2001.0, 0.01, [True, True, True]))
        log.write(1000, "K", "P", position(1001.6, 2000.2, 0.0123, [True, True, True]))
        log.write(1000, "S", "S", {"gen": 0, "period_ms": 0, "counts": {"odometry": 1}})
        log.write(1100, "O", "C", {"gen": 1, "dl": -5, "dr": 7, "count": 1})
        log.write(1100, "G", "C", {"gen": 1, "rate": -0.005, "turn": -0.0005, "count": 5})
        lost = {"d1": 1499, "d2": None, "d3": None, "x": None, "y": None, "counter": 8}
        log.write(1100, "L", "C", {"gen": 1, **lost, "count": 1})
        log.write(1100, "W", "C", {"gen": 1, "distances_mm": [None, 250, None], "walls": [], "count": 2})
        log.write(1100, "K", "P", position(998.4, 2003.0, -3.14159, [True, False, True]))
        log.write(1100, "S", "S", {"gen": 1, "period_ms": 100, "counts": {"odometry": 1}})
        log.write(1200, "O", "C", {"gen": 2, "dl": 33, "dr": 31, "count": 1})
        log.write(1200, "S", "S", {"gen": 2, "period_ms": 100, "counts": {"odometry": 1}})
        log.write(1300, "O", "C", {"gen": 3, "dl": 40, "dr": 40, "count": 1})  # no S S follows


DATA = [
    # Zeitpunkt: the stamp as it is (ms since the start, as the seed text's S T at 0), not
    # shifted to the first synchronisation; the gyroscope: G C's turn, the angle of the period
    ["1000", "0", "120", "118", "0.001234567891", "1500", "2301", "0", "1234", "2346", "1",
     "1002", "2000", "0.01230", "1", "1", "1"],
    # LOPS heard one receiver and could not place the robot: its X, Y and valid flag 0; the
    # filter's y unknown: written 0, its flag 0
    ["1100", "100", "-5", "7", "-0.000500000000", "1499", "0", "0", "0", "0", "0",
     "998", "0", "-3.14159", "1", "0", "1"],
    # odometry alone: everything else unknown, written 0
    ["1200", "100", "33", "31", "0", "0", "0", "0", "0", "0", "0",
     "0", "0", "0", "0", "0", "0"],
]  # fmt: skip
SONAR = [
    ["650", "0", "0", "0", "-880", "0"],  # 500 mm ahead of (150, 0); none; 730 mm behind (-150, 0)
    ["0", "0", "0", "370", "0", "0"],  # 250 mm to the left of (0, 120)
    ["0", "0", "0", "0", "0", "0"],  # no sonar record in this synchronisation
]
#: table B.8 has sixteen sonars: the command line's sonar.dat fills each line up with 0 0
SEED_SONARS = 16
SONAR_FILE = [row + ["0"] * (2 * SEED_SONARS - len(row)) for row in SONAR]


def test_data_dat_has_table_b8s_fields_in_its_widths(tmp_path: Path) -> None:
    darmstadt_log(tmp_path / "a.trlog")
    data, sonar = convert_seed_dat(read_log(tmp_path / "a.trlog"))
    assert data.endswith("\n") and sonar.endswith("\n")
    assert [fixed_fields(line, DATA_WIDTHS) for line in data.splitlines()] == DATA
    assert [fixed_fields(line, [SONAR_WIDTH] * 2 * SEED_SONARS) for line in sonar.splitlines()] == SONAR_FILE


def test_the_gyroscope_column_is_the_seed_texts_g_c_value(tmp_path: Path) -> None:
    darmstadt_log(tmp_path / "a.trlog")
    log = read_log(tmp_path / "a.trlog")
    text = [line.split() for line in convert_seed_text(log).splitlines() if line.startswith("G C")]
    data = [line.split() for line in convert_seed_dat(log)[0].splitlines()]
    assert [t[3] for t in text] == [d[4] for d in data[:2]]


def test_a_hamburg_run_without_gyroscope_and_lops_writes_zeros_there(tmp_path: Path) -> None:
    with DataLog(tmp_path / "h.trlog", "20261124-120000", CONFIG) as log:
        for k in range(2):
            stamp = 500 + 100 * k
            log.write(stamp, "O", "C", {"gen": k, "dl": 10 + k, "dr": 12, "count": 1})
            log.write(stamp, "M", "C", {"gen": k, "heading": 0.5, "count": 1})
            distances = [400, 300, None]
            log.write(stamp, "W", "C", {"gen": k, "distances_mm": distances, "walls": [], "count": 1})
            log.write(stamp, "T", "P", position(100.0, 200.0, 0.5, [True, True, True]))
            log.write(stamp, "K", "P", position(101.0, 199.0, 0.5, [True, True, True]))
            log.write(stamp, "S", "S", {"gen": k, "period_ms": 100 * k, "counts": {"odometry": 1}})
    data, sonar = convert_seed_dat(read_log(tmp_path / "h.trlog"))
    rows = [fixed_fields(line, DATA_WIDTHS) for line in data.splitlines()]
    assert rows == [
        [str(500 + 100 * k), str(100 * k), str(10 + k), "12"]
        + ["0"] * 7  # Gyroskop, Entfernung 1-3, LOPS-X, LOPS-Y, LOPS-Valid
        + ["101", "199", "0.50000", "1", "1", "1"]
        for k in range(2)
    ]
    # 400 mm ahead of (150, 0), 300 mm to the left of (0, 120), nothing behind
    assert [fixed_fields(line, [SONAR_WIDTH] * 2 * SEED_SONARS) for line in sonar.splitlines()] == [
        ["550", "0", "0", "420"] + ["0"] * (2 * SEED_SONARS - 4)
    ] * 2


def test_the_command_line_writes_both_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    darmstadt_log(tmp_path / "a.trlog")
    out = tmp_path / "dat"
    assert cli_main(["log", "convert", str(tmp_path / "a.trlog"), "--to", "dat", "--out", str(out)]) == 0
    assert "3 synchronisations" in capsys.readouterr().out
    assert sorted(p.name for p in out.iterdir()) == ["data.dat", "sonar.dat"]
    assert [fixed_fields(line, DATA_WIDTHS) for line in (out / "data.dat").read_text().splitlines()] == DATA
    sonar = (out / "sonar.dat").read_text().splitlines()
    assert [fixed_fields(line, [SONAR_WIDTH] * 2 * SEED_SONARS) for line in sonar] == SONAR_FILE


def test_an_existing_output_is_refused_without_force(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    darmstadt_log(tmp_path / "a.trlog")
    out = tmp_path / "dat"
    out.mkdir()
    (out / "data.dat").write_text("older\n")
    args = ["log", "convert", str(tmp_path / "a.trlog"), "--to", "dat", "--out", str(out)]
    assert cli_main(args) == 2
    one_error_line(capsys, "data.dat", "exists", "--force")
    assert (out / "data.dat").read_text() == "older\n" and not (out / "sonar.dat").exists()
    (out / "data.dat").unlink()
    (out / "sonar.dat").write_text("older\n")
    assert cli_main(args) == 2
    one_error_line(capsys, "sonar.dat", "exists", "--force")
    assert (out / "sonar.dat").read_text() == "older\n" and not (out / "data.dat").exists()
    assert cli_main([*args, "--force"]) == 0
    assert [line.split() for line in (out / "sonar.dat").read_text().splitlines()] == SONAR_FILE


def test_a_missing_out_is_one_line_and_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    darmstadt_log(tmp_path / "a.trlog")
    assert cli_main(["log", "convert", str(tmp_path / "a.trlog"), "--to", "dat"]) == 2
    one_error_line(capsys, "--to dat", "data.dat", "--out")


def test_an_error_log_is_one_line_and_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with ErrorLog(tmp_path / "e.trerr", "20040120-130535") as log:
        log.message("I", 484, "Triggering Sensor: Odometry, Trigger count: 1")
    out = tmp_path / "dat"
    assert cli_main(["log", "convert", str(tmp_path / "e.trerr"), "--to", "dat", "--out", str(out)]) == 2
    one_error_line(capsys, "e.trerr", "data log")
    assert not out.exists()
