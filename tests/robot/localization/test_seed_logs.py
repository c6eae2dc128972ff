"""The logs in the seed's own text (seed 000, appendix B): ``tokenring log convert --to seed``.

The expected lines are typed out by hand: where figure B.3 (the seed's data log) shows a line,
the line is copied from the figure character for character; the sonar lines, which the figure
shows only in an older eight-value form, are written from table B.7's fields.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from modules.localization.logs import DataLog, ErrorLog, LogError, convert_seed_text, read_log
from tokenring.cli.main import main as cli_main

#: three sonars: ahead 150 mm in front, to the left 120 mm out, behind 150 mm back
CONFIG = {"robot": {"sonars": [[150, 0, 0], [0, 120, 90], [-150, 0, 180]]}}
GYRO_RAD = -0.000003835885  # figure B.3's gyro value
NO_WALL = "0 0.00000 0.0 -1"


def urad_s(rad_per_sample: float) -> float:
    """The seed's gyro value (the angle of one 20.48 ms sample) as gyro.data's rate in µrad/s."""
    return rad_per_sample / 0.02048 * 1e6


def position(x: float, y: float, psi: float, valid: tuple[bool, bool, bool]) -> dict:
    return {"x": x, "y": y, "psi": psi, "valid": list(valid)}


def figure_log(path: Path) -> None:
    """Figure B.3's first two synchronisations in our record order (the positions, then S S),
    a third with a wall-derived fix (y unknown), and sonar raw and synchronised data."""
    with DataLog(path, "20040120-130535", CONFIG) as log:
        gyro = {"rate_urad_s": urad_s(GYRO_RAD), "angle_mrad": 0, "state": 2}
        log.write(3536, "G", "R", {"gen": 0, "n": 0, "v": gyro})
        log.write(3536, "G", "P", position(0.0, 0.0, -0.000004, (False, False, True)))
        log.write(3542, "O", "R", {"gen": 0, "n": 1, "v": {"steps_left": 0, "steps_right": 0}})
        log.write(3542, "O", "C", {"gen": 0, "dl": 0, "dr": 0, "count": 1})
        log.write(3542, "G", "C", {"gen": 0, "rate": GYRO_RAD / 0.006, "turn": GYRO_RAD, "count": 1})
        log.write(3542, "O", "P", position(0.0, 0.0, 0.0, (True, True, True)))
        log.write(3542, "K", "P", position(0.0, 0.0, 0.0, (True, True, True)) | {"walls": []})
        log.write(3542, "S", "S", {"gen": 0, "period_ms": 0, "counts": {"odometry": 1}})
        log.write(3572, "L", "P", position(0.0, 0.0, 0.0, (False, False, False)))
        log.write(3641, "W", "R", {"gen": 1, "n": 2, "v": {"distances": [100, 255, 50]}})
        log.write(3645, "W", "R", {"gen": 1, "n": 3, "v": {"distances": [100, 60, 50]}})
        log.write(3647, "G", "C", {"gen": 1, "rate": -0.000182662, "turn": -0.000019179423, "count": 5})
        wall = {"alpha": 1.5708, "d": 1200.0, "kind": "side"}
        log.write(3647, "W", "C", {"gen": 1, "distances_mm": [1000, 600, None], "walls": [wall], "count": 2})
        log.write(3647, "K", "P", position(0.0, 0.0, 0.0, (True, True, True)) | {"walls": [[3, 1]]})
        log.write(3647, "S", "S", {"gen": 1, "period_ms": 105, "counts": {"odometry": 1}})
        log.write(3747, "K", "P", position(1003.6, 998.1, 0.01, (True, False, True)) | {"walls": []})
        log.write(3747, "S", "S", {"gen": 2, "period_ms": 100, "counts": {"odometry": 1}})


EXPECTED = [
    "S T      0 20. 1.2004 13: 5:35",  # figure B.3
    "G R    3536 -0.000003835885",  # figure B.3
    "G P    3536      0      0 -0.00000 0 0 1",  # figure B.3
    "O R    3542      0      0",  # figure B.3
    "O C    3542      0      0 1",  # figure B.3
    "G C    3542 -0.000003835885 1",  # figure B.3
    "O P    3542      0      0 0.00000 1 1 1",  # figure B.3
    "K P    3542      0      0 0.00000 1 1 1",  # figure B.3
    "S S    3542      0      0      0 0 0 0",  # figure B.3: nothing known when the first sync began
    "L P    3572      0      0      0 0 0 0",  # figure B.3
    # table B.7: new flags; obstacle x y per sonar (robot frame); distances; nine wall blocks
    "W R    3641 1 1 1  1150     0     0     0  -650     0  1000     0   500 " + " ".join([NO_WALL] * 9),
    "W R    3645 0 1 0  1150     0     0   720  -650     0  1000   600   500 " + " ".join([NO_WALL] * 9),
    "G C    3647 -0.000019179423 5",  # figure B.3
    "W C    3647 1 1 1  1150     0     0   720     0     0  1000   600     0 1 1.57080 1200.0  3 "
    + " ".join([NO_WALL] * 8)
    + " 2",
    "K P    3647      0      0 0.00000 1 1 1",  # figure B.3
    "S S    3647      0      0 0.00000 1 1 1",  # figure B.3: the filter's position of the sync before
    "K P    3747   1004      0 0.01000 1 0 1",  # y unknown: written 0, its flag 0
    "S S    3747      0      0 0.00000 1 1 1",
]


def test_a_data_log_in_the_seeds_line_formats(tmp_path: Path) -> None:
    figure_log(tmp_path / "a.trlog")
    assert convert_seed_text(read_log(tmp_path / "a.trlog")).splitlines() == EXPECTED


def test_the_command_line_writes_the_same_lines(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    figure_log(tmp_path / "a.trlog")
    assert cli_main(["log", "convert", str(tmp_path / "a.trlog"), "--to", "seed"]) == 0
    assert capsys.readouterr().out.splitlines() == EXPECTED
    out = tmp_path / "a.txt"
    assert cli_main(["log", "convert", str(tmp_path / "a.trlog"), "--to", "seed", "--out", str(out)]) == 0
    assert out.read_text().splitlines() == EXPECTED


def test_an_error_log_as_figure_b2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with ErrorLog(tmp_path / "e.trerr", "20040120-130535", debug=True) as log:
        log.message("I", 484, "Triggering Sensor: Odometry, Trigger count: 1")
        log.message("D", 317467, "Gyroskop Thread beendet")
    assert cli_main(["log", "convert", str(tmp_path / "e.trerr"), "--to", "seed"]) == 0
    assert capsys.readouterr().out.splitlines() == [
        "I      484 Triggering Sensor: Odometry, Trigger count: 1",  # figure B.2
        "D   317467 Gyroskop Thread beendet",  # figure B.2
    ]


def test_a_start_time_is_padded_with_blanks_as_the_seed_wrote_it(tmp_path: Path) -> None:
    with DataLog(tmp_path / "a.trlog", "20261124-090705", {}):
        pass
    assert convert_seed_text(read_log(tmp_path / "a.trlog")) == "S T      0 24.11.2026  9: 7: 5\n"


def one_error_line(capsys: pytest.CaptureFixture[str], *words: str) -> None:
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in captured.err, captured.err
    for word in words:
        assert word in lines[0], (word, lines[0])
    assert captured.out == ""


def test_a_file_that_is_no_log_is_one_line_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.trlog"
    bad.write_text("S T      0 20. 1.2004 13: 5:35\n")  # a text log is not the msgpack log
    assert cli_main(["log", "convert", str(bad), "--to", "seed"]) == 2
    one_error_line(capsys, "bad.trlog", "not a tokenring log")


def test_damage_inside_a_log_is_one_line_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    figure_log(tmp_path / "a.trlog")
    data = bytearray((tmp_path / "a.trlog").read_bytes())
    middle = len(data) // 2
    data[middle : middle + 8] = b"\xc1" * 8  # 0xc1: a byte msgpack never uses
    (tmp_path / "a.trlog").write_bytes(bytes(data))
    assert cli_main(["log", "convert", str(tmp_path / "a.trlog"), "--to", "seed"]) == 2
    one_error_line(capsys, "a.trlog", "damaged")


def test_a_start_time_the_seed_cannot_show_is_one_line_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with DataLog(tmp_path / "a.trlog", "yesterday", {}):
        pass
    with pytest.raises(LogError, match="yesterday"):
        convert_seed_text(read_log(tmp_path / "a.trlog"))
    assert cli_main(["log", "convert", str(tmp_path / "a.trlog"), "--to", "seed"]) == 2
    one_error_line(capsys, "a.trlog", "'yesterday'", "YYYYmmdd-HHMMSS")


# ---------------------------------------------------------------------------------------------
# the wall-derived position in the store (seed 000 §6.2.4): one coordinate and the heading


def test_a_wall_parallel_to_x_gives_y_and_the_heading_x_invalid() -> None:
    from modules.localization.walls import KnownWall, wall_position

    # the robot is truly at (1000, 500) heading 0.1 rad; the filter believes (1030, 480, 0.08)
    top = KnownWall.segment(0, 2000, 4000, 2000)  # y = 2000: 1500 mm above the robot
    # seen from the robot: the wall's normal points up (π/2 in the world), 0.1 rad less in its frame
    fit = (math.pi / 2 - 0.1, 1500.0, top)
    fix = wall_position((1030.0, 480.0, 0.08), [fit])
    assert fix is not None and fix["valid"] == [False, True, True]
    assert fix["x"] == 1030.0  # uncorrected: the reference value, flagged invalid
    assert fix["y"] == pytest.approx(500.0) and fix["psi"] == pytest.approx(0.1)


def test_two_walls_in_a_corner_give_both_coordinates_errors_averaged() -> None:
    from modules.localization.walls import KnownWall, wall_position

    top = KnownWall.segment(0, 2000, 4000, 2000)
    right = KnownWall.segment(3000, 0, 3000, 4000)  # x = 3000: 2000 mm right of the robot
    # heading errors of 0.02 and 0.04 rad against the reference 0.08: averaged to 0.03
    fits = [(math.pi / 2 - 0.10, 1500.0, top), (0.0 - 0.12, 2000.0, right)]
    fix = wall_position((1030.0, 480.0, 0.08), fits)
    assert fix is not None and fix["valid"] == [True, True, True]
    assert fix["x"] == pytest.approx(1000.0) and fix["y"] == pytest.approx(500.0)
    assert fix["psi"] == pytest.approx(0.08 + (0.02 + 0.04) / 2)
    assert wall_position((1030.0, 480.0, 0.08), []) is None


def run_at_rest(tmp_path: Path, log_wall_position: bool) -> list:
    """A short drive in the square room then rest beside its walls, logged."""
    from modules.localization.config import load_config
    from modules.localization.localizer import LocalizationCore
    from tests.support.locsim import drive

    config = load_config({"sensors": {"sonar": {"log_position": log_wall_position}}})
    with DataLog(tmp_path / "w.trlog", "20261124-120000", config) as log:
        core = LocalizationCore(config, data_log=log)
        for sample in drive([("s", 300.0)], world="square", seed=2, rest_ms=8000):
            core.feed(sample)
            core.maybe_sync()
    return read_log(tmp_path / "w.trlog").records


def test_the_localizer_logs_the_wall_position_when_the_seeds_switch_says_so(tmp_path: Path) -> None:
    """Each W P written by hand from its wall: an axis-parallel wall at c, seen d away, puts the
    robot at c ∓ d across it; the heading is the world direction towards the wall minus the
    direction the robot saw it in (its own frame). The coordinate along the wall stays unknown."""
    from modules.description import load_world

    records = run_at_rest(tmp_path, True)
    segments = [(w.x1, w.y1, w.x2, w.y2) for w in load_world("square").walls]
    truth = {r[0]: r[3] for r in records if r[1] == "T" and r[2] == "P"}
    filtered = {r[0]: r[3] for r in records if r[1] == "K" and r[2] == "P"}
    seen = {r[0]: r[3]["walls"] for r in records if r[1] == "W" and r[2] == "C"}
    fixes = [r for r in records if r[1] == "W" and r[2] == "P"]
    assert len(fixes) >= 5
    for stamp, _, _, fix in fixes:
        matched = [(w, i) for w, (i, _) in zip(seen[stamp], filtered[stamp]["walls"], strict=True) if i >= 0]
        assert len(matched) == 1  # at rest beside one wall: one wall per synchronisation
        wall, index = matched[0]
        x1, y1, x2, y2 = segments[index]
        k = filtered[stamp]
        if y1 == y2:  # parallel to X: y and the heading
            below = k["y"] < y1
            expected_y = y1 - wall["d"] if below else y1 + wall["d"]
            towards = math.pi / 2 if below else -math.pi / 2
            assert fix["valid"] == [False, True, True]
            assert fix["y"] == pytest.approx(expected_y) and abs(fix["y"] - truth[stamp]["y"]) < 100.0
        else:  # parallel to Y: x and the heading
            assert x1 == x2
            left = k["x"] < x1
            expected_x = x1 - wall["d"] if left else x1 + wall["d"]
            towards = 0.0 if left else math.pi
            assert fix["valid"] == [True, False, True]
            assert fix["x"] == pytest.approx(expected_x) and abs(fix["x"] - truth[stamp]["x"]) < 100.0
        assert math.remainder(fix["psi"] - (towards - wall["alpha"]), 2 * math.pi) == pytest.approx(
            0, abs=1e-9
        )
    lines = convert_seed_text(read_log(tmp_path / "w.trlog")).splitlines()
    for stamp, _, _, fix in fixes:
        fields = next(line for line in lines if line.startswith(f"W P {stamp:7d}")).split()
        flags = [int(v) for v in fix["valid"]]
        assert [int(f) for f in fields[-3:]] == flags
        for value, flag in zip(fields[3:5], flags[:2], strict=True):
            assert flag or value == "0"  # an unknown coordinate is written 0 (table B.7)


def test_by_default_the_wall_position_stays_out_of_the_log(tmp_path: Path) -> None:
    records = run_at_rest(tmp_path, False)
    assert not [r for r in records if r[1] == "W" and r[2] == "P"]
    assert [r for r in records if r[1] == "K" and r[2] == "P" and any(w[0] >= 0 for w in r[3]["walls"])]


NUMBERS = st.one_of(
    st.integers(min_value=-(2**40), max_value=2**40), st.floats(allow_nan=True, allow_infinity=True)
)
#: msgpack holds integers from -2**63 to 2**64 - 1; no log the writer can write holds others
LOGGABLE_INTEGERS = st.integers(min_value=-(2**63), max_value=2**64 - 1)
JUNK = st.one_of(
    st.none(),
    st.text(max_size=3),
    st.just("a\nb"),
    LOGGABLE_INTEGERS,
    st.lists(LOGGABLE_INTEGERS, max_size=2),
)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    numbers=st.lists(NUMBERS, min_size=6, max_size=6),
    sonar=st.lists(st.integers(min_value=0, max_value=255), min_size=1, max_size=10),
    synced=st.lists(st.one_of(st.none(), NUMBERS), min_size=1, max_size=10),
    junk=JUNK,
)
def test_any_readable_log_converts_to_one_line_per_record(
    numbers: list, sonar: list[int], synced: list, junk: object, tmp_path_factory: pytest.TempPathFactory
) -> None:
    """Whatever the reader accepts (extreme numbers, junk in the fields it does not check), the
    seed's text has a line for it: no crash, no line break inside a record."""
    a, b, c, d, e, f = numbers
    path = tmp_path_factory.mktemp("seed") / "x.trlog"
    with DataLog(path, "20261124-120000", {"robot": {"sonars": junk}}) as log:
        log.write(1, "O", "R", {"gen": 0, "n": 0, "v": {"steps_left": 2**40, "steps_right": -1}})
        log.write(1, "O", "C", {"gen": 0, "dl": a, "dr": b, "count": 1})
        log.write(1, "G", "R", {"gen": 0, "n": 1, "v": {"rate_urad_s": c, "angle_mrad": d}})
        log.write(1, "G", "C", {"gen": 0, "rate": c, "turn": d, "count": 1})
        log.write(1, "M", "R", {"gen": 0, "n": 1, "v": {"heading_cdeg": c}})
        log.write(1, "M", "C", {"gen": 0, "heading": d, "count": 1})
        log.write(1, "W", "R", {"gen": 0, "n": 2, "v": {"distances": sonar}})
        wall = {"alpha": e, "d": f, "assoc": junk}
        log.write(1, "W", "C", {"gen": 0, "distances_mm": synced, "walls": [wall] * 10, "count": 1})
        log.write(1, "T", "C", {"gen": 0, "x": a, "y": b, "theta": c, "count": 1})
        log.write(1, "K", "P", {"x": d, "y": e, "psi": f, "valid": [True, 0, 1], "walls": junk})
        log.write(1, "S", "S", {"gen": 0, "period_ms": 0, "counts": {}})
        log.write(1, "S", "E", {"gen": 0, "event": "set_pose", "x": junk})
    text = convert_seed_text(read_log(path))
    lines = text.split("\n")  # the seed's line ends only (splitlines would split at \x1e too)
    assert (
        lines.pop() == ""
        and len(lines) == 13
        and all(line[:2] in ("S ", "O ", "G ", "M ", "W ", "T ", "K ") for line in lines)
    )
