"""``tokenring analyze --seed-out``: the seed's logfileanalyser output (seed 000, §9.2, appendix B.4).

A recorded drive with all the Darmstadt sensors is analysed; the real ``gnuplot`` then runs
``gnuplot command`` in every module's directory, as the seed's user did, and the images it draws
must be whole PNGs of the terminal's size. The data files are judged against table B.9's widths
typed out here (each field right-aligned in its width, one blank between), and their values
against the log's records read here, not with the writer's helpers.
"""

from __future__ import annotations

import itertools
import math
import re
import shutil
import struct
import subprocess
from pathlib import Path

import pytest

from modules.localization.config import default_config_path, load_config, sensor_set_layer
from modules.localization.localizer import LocalizationCore
from modules.localization.logs import DataLog, read_log
from tests.robot.localization.test_all_sensors import RECEIVERS, with_lops
from tests.support.locsim import drive, with_gyro
from tokenring.cli.main import main as cli_main

#: table B.9: each file's fields and their widths in characters
WIDTHS = {
    "gyroskop": [8, 15],  # Zeit, Drehrate (rad)
    "lops": [8, 8],  # Zeit, Entfernung (mm)
    "odometrie": [8, 8],  # Zeit, Enkoderinkrement
    "position": [8, 8],  # X-Position, Y-Position (mm)
    "sonar": [8, 8],  # Zeit, Entfernung (mm)
    "time": [8, 5],  # Zeit, Dauer (ms)
}
MODULES = {"position", "odometrie", "gyroskop", "lops", "sonar", "time"}
PNG = b"\x89PNG\r\n\x1a\n"
GNUPLOT = shutil.which("gnuplot")
#: the seed's own configuration file, figure 10.1, as printed
FIGURE_10_1 = """[Main]
data.log
default
yes yes yes yes yes yes

[Position]
"fig color big metric"
kalman lines
lops lines
odometrie lines

[Lops]
"fig color big metric"
dots dots dots

[Odometry]
"fig color big metric"
lines lines

[Gyroskop]
"fig color big metric"
dots

[Sonar]
"fig color big metric"
dots dots dots dots dots dots dots dots
dots dots dots dots dots dots dots dots

[Time]
"fig color big metric"
yes
dots
gyro dots
lops dots
"""


def needs_gnuplot() -> str:
    """The gnuplot the tests run: missing, the test fails and says which package brings it."""
    assert GNUPLOT is not None, "gnuplot is not installed (Debian: gnuplot-nox; .ci/run installs it)"
    return GNUPLOT


def fields(line: str, widths: list[int]) -> list[str]:
    """A fixed-width line's fields: each right-aligned in its width, one blank between them."""
    pattern = " ".join(f"(.{{{w}}})" for w in widths)
    match = re.fullmatch(pattern, line)
    assert match, (widths, line)
    out = []
    for width, column in zip(widths, match.groups(), strict=True):
        value = column.strip()
        assert value and " " not in value and column == value.rjust(width), (width, column, line)
        out.append(value)
    return out


def rows(path: Path, module: str) -> list[list[str]]:
    return [fields(line, WIDTHS[module]) for line in path.read_text().splitlines()]


@pytest.fixture(scope="module")
def darmstadt_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A recorded drive with odometry, compass, sonar, gyroscope and LOPS (a fifth of its packets
    with a late echo and no position), one packet with a receiver that heard nothing."""
    path = tmp_path_factory.mktemp("seed") / "drive.trlog"
    config = load_config(default_config_path(), under=sensor_set_layer("darmstadt", RECEIVERS))
    config["lops"]["delay_ms"] = 40.0
    core = LocalizationCore(config, data_log=DataLog(path, "20040120-130535", config))
    moves = [("s", 600.0), ("r", 90.0), ("s", 300.0)]
    for sample in with_lops(with_gyro(drive(moves, seed=3, heading=lambda: core.ekf.pose[2])), 3):
        if sample.sensor == "gyro":  # a rate of its own: the test's gyro sums only angles
            sample.values["rate_urad_s"] = -187 + 50 * (sample.stamp_ms % 3)
        if sample.sensor == "lops" and sample.values["counter"] == 20:
            sample.values["d2"] = None  # receiver 2 heard nothing
        core.feed(sample)
        core.maybe_sync()
    core.close()
    return path


@pytest.fixture(scope="module")
def hamburg_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The default configuration's sensors: no gyroscope, no LOPS."""
    path = tmp_path_factory.mktemp("hamburg") / "drive.trlog"
    config = load_config()
    core = LocalizationCore(config, data_log=DataLog(path, "20240101-120000", config))
    for sample in drive([("s", 300.0)], seed=4, heading=lambda: core.ekf.pose[2]):
        core.feed(sample)
        core.maybe_sync()
    core.close()
    return path


@pytest.fixture(scope="module")
def seed_out(darmstadt_log: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("out") / "seed"
    assert cli_main(["analyze", str(darmstadt_log), "--seed-out", str(out)]) == 0
    return out


def png_size(path: Path) -> tuple[int, int]:
    """A PNG's width and height, after checking it is whole: its signature, IHDR first, IEND last."""
    data = path.read_bytes()
    assert data[:8] == PNG, path
    length, kind = struct.unpack(">I4s", data[8:16])
    assert kind == b"IHDR" and length == 13, path
    assert data[-12:] == b"\x00\x00\x00\x00IEND\xaeB`\x82", path
    return struct.unpack(">II", data[16:24])


def gnuplot(folder: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [needs_gnuplot(), "command"], cwd=folder, capture_output=True, text=True, timeout=60, check=False
    )


def test_gnuplot_draws_every_module_of_a_recorded_drive(seed_out: Path) -> None:
    needs_gnuplot()
    assert {p.name for p in seed_out.iterdir() if p.is_dir()} == MODULES
    for module in MODULES:
        result = gnuplot(seed_out / module)
        assert result.returncode == 0, (module, result.stderr)
        image = seed_out / module / f"{module}.png"
        assert image.stat().st_size > 10_000, module  # axes, a key and the data: not a blank image
        assert png_size(image) == ((800, 800) if module == "position" else (900, 600)), module


def test_the_data_files_have_table_b9s_widths_and_the_logs_values(
    seed_out: Path, darmstadt_log: Path
) -> None:
    records = read_log(darmstadt_log).records
    of = lambda source, kind: [(s, p) for s, src, k, p in records if (src, k) == (source, kind)]  # noqa: E731

    steps = of("O", "C")
    assert rows(seed_out / "odometrie" / "links", "odometrie") == [
        [str(s), str(round(p["dl"]))] for s, p in steps
    ]
    assert rows(seed_out / "odometrie" / "rechts", "odometrie") == [
        [str(s), str(round(p["dr"]))] for s, p in steps
    ]

    # the seed's G R: the angle of one 20.48 ms sample in rad (figure 10.2)
    gyro = rows(seed_out / "gyroskop" / "gyroskop", "gyroskop")
    expected = [(s, p["v"]["rate_urad_s"] * 1e-6 * 0.02048) for s, p in of("G", "R")]
    assert [int(r[0]) for r in gyro] == [s for s, _ in expected] and len(gyro) > 100
    assert all(float(r[1]) == pytest.approx(v, abs=1e-12) for r, (_, v) in zip(gyro, expected, strict=True))
    assert {r[1] for r in gyro} >= {"-0.000003829760", "-0.000002805760"}

    for i, key in enumerate(("d1", "d2", "d3")):  # a receiver that heard nothing: no line
        heard = [[str(s), str(round(p["v"][key]))] for s, p in of("L", "R") if p["v"][key] is not None]
        assert rows(seed_out / "lops" / f"empfaenger{i + 1}", "lops") == heard
    assert (
        len(heard) == len(of("L", "R"))
        and len(rows(seed_out / "lops" / "empfaenger2", "lops")) == len(heard) - 1
    )

    sweeps = of("W", "R")
    for i in range(8):  # no contact (255 cm): no line; a sonar that never saw anything: no file
        seen = [
            [str(s), str(p["v"]["distances"][i] * 10)] for s, p in sweeps if p["v"]["distances"][i] != 255
        ]
        file = seed_out / "sonar" / f"empfaenger{i}"
        assert (rows(file, "sonar") if file.exists() else []) == seen
    assert len(list((seed_out / "sonar").glob("empfaenger*"))) >= 3

    def xy(source: str) -> list[list[str]]:
        return [[str(round(p["x"])), str(round(p["y"]))] for _, p in of(source, "P") if all(p["valid"][:2])]

    for name, source in (("kalman", "K"), ("odometrie", "O"), ("lops", "L"), ("truth", "T")):
        assert rows(seed_out / "position" / name, "position") == xy(source), name
    assert len(xy("L")) > 50 and len(xy("K")) == len(of("K", "P"))

    syncs = [s for s, _ in of("S", "S")]
    expected_sync = [[str(b), str(b - a)] for a, b in itertools.pairwise(syncs)]
    assert rows(seed_out / "time" / "synchronisation", "time") == expected_sync
    lops = [s for s, _ in of("L", "R")]
    assert rows(seed_out / "time" / "lops", "time") == [
        [str(b), str(b - a)] for a, b in itertools.pairwise(lops)
    ]
    assert {p.name for p in (seed_out / "time").iterdir()} >= {
        "synchronisation",
        "odometry",
        "gyro",
        "lops",
        "command",
    }


def test_the_configuration_is_table_b2s(seed_out: Path, darmstadt_log: Path) -> None:
    """logfile.cfg: [MAIN] the log, the output, six yes/no switches; each module's terminal and
    styles, the positions and the timed sensors (values by position, # comments)."""
    values: dict[str, list[str]] = {}
    section = ""
    for line in (seed_out / "logfile.cfg").read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if line.startswith("["):
            section = line.strip("[]")
            values[section] = []
        elif line:
            values[section] += [v.strip('"') for v in re.findall(r'"[^"]*"|\S+', line)]
    assert list(values) == ["MAIN", "POSITION", "LOPS", "ODOMETRY", "GYROSCOP", "SONAR", "TIME"]
    assert values["MAIN"] == [str(darmstadt_log), str(seed_out), *["yes"] * 6]
    assert values["POSITION"][0].startswith("pngcairo") and values["POSITION"][1:3] == ["kalman", "lines"]
    assert values["POSITION"][1::2] == ["kalman", "odometrie", "lops", "truth"]
    assert len(values["ODOMETRY"]) == 3 and len(values["GYROSCOP"]) == 2 and len(values["LOPS"]) == 4
    assert len(values["SONAR"]) == 1 + 16  # table B.2: a style for each of the 16 sonars
    assert values["TIME"][1] == "yes" and "lops" in values["TIME"][3::2] and "gyro" in values["TIME"][3::2]


def test_a_log_without_lops_and_gyroscope_says_so_in_one_line_each(
    hamburg_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "seed"
    assert cli_main(["analyze", str(hamburg_log), "--seed-out", str(out)]) == 0
    err = capsys.readouterr().err.splitlines()
    assert {p.name for p in out.iterdir()} == {"position", "odometrie", "sonar", "time", "logfile.cfg"}
    for module, what in (("lops", "LOPS"), ("gyroskop", "gyroscope")):
        said = [line for line in err if f"no {module}/" in line]
        assert len(said) == 1 and what in said[0], err
    for module in ("position", "odometrie", "sonar", "time"):
        assert gnuplot(out / module).returncode == 0
        assert png_size(out / module / f"{module}.png")[0] > 0


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_an_existing_output_is_refused_without_force(
    darmstadt_log: Path, hamburg_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "seed"
    out.mkdir()
    (out / "time").mkdir()
    (out / "time" / "synchronisation").write_text("older\n")
    args = ["analyze", str(darmstadt_log), "--seed-out", str(out)]
    before = snapshot(tmp_path)
    assert cli_main(args) == 2
    line = one_line(capsys)
    assert f"--seed-out {out / 'time'}" in line and "exists" in line and "--force" in line
    assert snapshot(tmp_path) == before
    (out / "time" / "synchronisation").unlink()
    (out / "time").rmdir()
    (out / "logfile.cfg").write_text("older\n")
    assert cli_main(args) == 2
    assert f"--seed-out {out / 'logfile.cfg'}" in one_line(capsys)
    assert (out / "logfile.cfg").read_text() == "older\n" and sorted(out.iterdir()) == [out / "logfile.cfg"]
    # --force: replaced whole; a module this log has no data for does not stay from the older run
    assert cli_main([*args, "--force"]) == 0
    assert (out / "lops" / "empfaenger1").exists()
    assert cli_main(["analyze", str(hamburg_log), "--seed-out", str(out), "--force"]) == 0
    assert not (out / "lops").exists() and not (out / "gyroskop").exists()
    assert [p.name for p in out.rglob(".*")] == []  # no temporary left


def one_line(capsys: pytest.CaptureFixture[str]) -> str:
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in captured.err, captured.err
    return lines[0]


def test_bad_input_is_one_line_exit_2_and_nothing_written(
    darmstadt_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "seed"
    assert cli_main(["analyze", str(tmp_path / "missing.trlog"), "--seed-out", str(out)]) == 2
    assert "missing.trlog" in one_line(capsys) and not out.exists()
    assert cli_main(["analyze", str(darmstadt_log), "--seed-config", str(tmp_path / "x.cfg")]) == 2
    assert "--seed-out" in one_line(capsys)
    args = ["analyze", str(darmstadt_log), "--seed-out", str(out), "--seed-config", str(tmp_path / "x.cfg")]
    assert cli_main(args) == 2
    assert "x.cfg" in one_line(capsys) and not out.exists()
    # an input inside a module's directory is never replaced, not even with --force
    (out / "time").mkdir(parents=True)
    inside = out / "time" / "drive.trlog"
    inside.write_bytes(darmstadt_log.read_bytes())
    assert cli_main(["analyze", str(inside), "--seed-out", str(out), "--force"]) == 2
    assert "holds the input" in one_line(capsys) and inside.read_bytes() == darmstadt_log.read_bytes()


# ---------------------------------------------------------------------------------------------
# the logfileconverter (seed §9.3, table B.8) on the same drive

#: table B.8's data.dat, in characters: Zeitpunkt, Takt, Enkoder links, rechts, Gyroskop,
#: Entfernung 1-3, LOPS-X, LOPS-Y, LOPS-Valid, X-Position, Y-Position, Drehung, X-, Y-,
#: Drehung-Valid; sonar.dat: X and Y of each of the 16 sonars, 6 each
DATA_DAT = struct.Struct("8sx4sx8sx8sx15sx8sx8sx8sx8sx8sx1sx8sx8sx8sx1sx1sx1s")
SONAR_DAT = struct.Struct("x".join(["6s"] * 32))


def unpack(layout: struct.Struct, line: str) -> list[str]:
    """A line cut at table B.8's widths: the blanks between the fields where the table puts
    them, each field right-aligned and without a blank inside."""
    raw = line.encode("ascii")
    assert len(raw) == layout.size, (len(raw), layout.size, line)
    out = []
    start = 0
    for value in layout.unpack(raw):
        text = value.decode()
        assert text.strip() and text == text.strip().rjust(len(text)) and " " not in text.strip(), line
        start += len(value)
        assert start == len(raw) or raw[start : start + 1] == b" ", line
        start += 1
        out.append(text.strip())
    return out


def test_log_convert_to_dat_writes_table_b8_exactly(darmstadt_log: Path, tmp_path: Path) -> None:
    from modules.description.robot import SONAR_MOUNTS

    out = tmp_path / "dat"
    assert cli_main(["log", "convert", str(darmstadt_log), "--to", "dat", "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["data.dat", "sonar.dat"]  # the table's names
    data = [unpack(DATA_DAT, line) for line in (out / "data.dat").read_text().splitlines()]
    sonar = [unpack(SONAR_DAT, line) for line in (out / "sonar.dat").read_text().splitlines()]

    # the records of each synchronisation, up to its S S, typed out from the log here
    expected_data, expected_sonar, sync = [], [], {}
    for stamp, source, kind, p in read_log(darmstadt_log).records:
        if (kind == "C" and source in "OGLW") or (source, kind) == ("K", "P"):
            sync[source] = p
        if (source, kind) != ("S", "S"):
            continue
        o, g, lops, k = sync.get("O"), sync.get("G"), sync.get("L"), sync.get("K")
        row = [str(stamp), str(p["period_ms"])]
        row += [str(round(o["dl"])), str(round(o["dr"]))] if o else ["0", "0"]
        row.append(f"{g['turn']:.12f}" if g else "0")  # the angle of the period in rad (G C)
        if lops:
            row += [str(round(lops[d])) if lops[d] is not None else "0" for d in ("d1", "d2", "d3")]
            placed = lops["x"] is not None
            row += [str(round(lops["x"])), str(round(lops["y"])), "1"] if placed else ["0", "0", "0"]
        else:
            row += ["0"] * 6
        if k:
            vx, vy, vpsi = (bool(v) for v in k["valid"])
            row += [str(round(k["x"])) if vx else "0", str(round(k["y"])) if vy else "0"]
            row += [f"{k['psi']:.5f}" if vpsi else "0", str(int(vx)), str(int(vy)), str(int(vpsi))]
        else:
            row += ["0"] * 6
        expected_data.append(row)
        points = []
        distances = sync["W"]["distances_mm"] if "W" in sync else []
        for i in range(16):  # the robot's eight sonars, then the table's other eight: none
            d = distances[i] if i < len(distances) else None
            if d is None:
                points += ["0", "0"]
            else:
                m = SONAR_MOUNTS[i]
                points += [str(round(m.x + d * math.cos(m.angle))), str(round(m.y + d * math.sin(m.angle)))]
        expected_sonar.append(points)
        sync = {}
    assert len(data) > 100 and data == expected_data
    assert sonar == expected_sonar
    assert any(row[10] == "0" for row in data) and any(row[10] == "1" for row in data)  # LOPS lost, found
    assert any(float(row[4]) != 0 for row in data)  # the gyroscope turned


# ---------------------------------------------------------------------------------------------
# --seed-config: a table B.2 file honoured


def analyse_with(log: Path, out: Path, config: Path, *more: str) -> int:
    return cli_main(["analyze", str(log), "--seed-out", str(out), "--seed-config", str(config), *more])


def test_the_seeds_own_file_figure_10_1_is_honoured(darmstadt_log: Path, tmp_path: Path) -> None:
    """Its positions (kalman, lops, odometrie: not our truth), its time module (the
    synchronisation, gyro, lops), its styles and its terminal: xfig's ``fig``. gnuplot 5 knows
    ``fig color big`` but no more gnuplot 3.7's ``metric``: drawn here without it."""
    needs_gnuplot()
    config = tmp_path / "logfile.cfg"
    config.write_text(FIGURE_10_1)
    out = tmp_path / "seed"
    assert analyse_with(darmstadt_log, out, config) == 0
    assert {p.name for p in (out / "position").iterdir()} == {"kalman", "lops", "odometrie", "command"}
    assert {p.name for p in (out / "time").iterdir()} == {"synchronisation", "gyro", "lops", "command"}
    for module in MODULES:
        command = (out / module / "command").read_text()
        assert "set terminal fig color big metric\n" in command and f"set output '{module}.fig'" in command
        assert " with lines" in command if module in ("position", "odometrie") else " with dots" in command
        (out / module / "command").write_text(command.replace(" metric", ""))
        result = gnuplot(out / module)
        assert result.returncode == 0, (module, result.stderr)
        assert (out / module / f"{module}.fig").read_text().startswith("#FIG 3.2\n")
    # the same data files as without a configuration: the positions and sensors it names
    plain = tmp_path / "plain"
    assert cli_main(["analyze", str(darmstadt_log), "--seed-out", str(plain)]) == 0
    for file in (
        "position/kalman",
        "lops/empfaenger3",
        "time/gyro",
        "gyroskop/gyroskop",
        "sonar/empfaenger2",
    ):
        assert (out / file).read_text() == (plain / file).read_text(), file


def test_the_plot_switches_turn_modules_off_and_the_written_file_reads_back(
    darmstadt_log: Path, seed_out: Path, tmp_path: Path
) -> None:
    config = tmp_path / "my.cfg"
    text = (seed_out / "logfile.cfg").read_text()
    config.write_text(text.replace("yes yes yes yes yes yes", "yes no no yes no no"))
    out = tmp_path / "seed"
    assert analyse_with(darmstadt_log, out, config) == 0
    assert {p.name for p in out.iterdir()} == {"position", "odometrie", "logfile.cfg"}
    assert "\nyes no no yes no no\n" in (out / "logfile.cfg").read_text()
    # the file written read back: the same output as the one it was written with
    again = tmp_path / "again"
    assert analyse_with(darmstadt_log, again, seed_out / "logfile.cfg") == 0
    assert snapshot(again) == {
        name: data for name, data in snapshot(seed_out).items() if not name.endswith(".png")
    }


#: a bad table B.2 file: (what is changed in the written one, the words of the one line)
BAD_CONFIGS = [
    ("kalman lines", "kalman dots;", ["logfile.cfg:13", "[POSITION]", "'dots;'", "gnuplot style"]),
    ('"pngcairo size 800,800"', '"pngcairo `touch x`"', [":12", "[POSITION]", "terminal"]),
    ("kalman lines", "wand lines", [":13", "no position 'wand'", "kalman"]),
    ("\nlines lines\n", "\nlines lines lines\n", ["[ODOMETRY]", "a value too many", "'lines'"]),
    ("yes yes yes yes yes yes", "yes yes yes yes vielleicht yes", [":8", "[MAIN]", "Sonarplot", "yes or no"]),
    ("[SONAR]", "[SONAREN]", ["[SONAREN]", "table B.2"]),
    ("odometry", "odometrie_", ["[TIME]", "no sensor 'odometrie_'"]),
    ('"pngcairo size 900,600"\ndots dots', '"pngcairo size 900,600\ndots dots', ['"', "not closed"]),
]


@pytest.mark.parametrize(("old", "new", "words"), BAD_CONFIGS, ids=[b[1][:20] for b in BAD_CONFIGS])
def test_a_malformed_configuration_is_one_line_exit_2_and_nothing_written(
    old: str, new: str, words: list[str], darmstadt_log: Path, seed_out: Path, tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:  # fmt: skip
    text = (seed_out / "logfile.cfg").read_text().replace('"points pt 7 ps 0.3"', "dots")
    assert old in text
    config = tmp_path / "logfile.cfg"
    config.write_text(text.replace(old, new, 1))
    out = tmp_path / "seed"
    out.mkdir()
    (out / "time").mkdir()
    (out / "time" / "synchronisation").write_text("older\n")
    before = snapshot(tmp_path)
    assert analyse_with(darmstadt_log, out, config, "--force") == 2
    line = one_line(capsys)
    assert str(config) in line
    for word in words:
        assert word in line, (word, line)
    assert snapshot(tmp_path) == before


def test_fewer_sonar_styles_than_the_logs_sonars_is_refused(
    darmstadt_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    config = tmp_path / "logfile.cfg"
    config.write_text(FIGURE_10_1.replace("dots dots dots dots dots dots dots dots\ndots", "dots dots\n#"))
    assert analyse_with(darmstadt_log, tmp_path / "seed", config) == 2
    line = one_line(capsys)
    assert f"{config}:" in line and "[SONAR] has 2 styles" in line and "8 sonars" in line
    assert not (tmp_path / "seed").exists()


def test_json_lists_the_modules_written_and_why_others_are_not(
    hamburg_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import json

    out = tmp_path / "seed"
    assert cli_main(["analyze", str(hamburg_log), "--seed-out", str(out), "--json"]) == 0
    captured = capsys.readouterr()
    seed = json.loads(captured.out)["seed_out"]
    assert seed["dir"] == str(out) and captured.err == ""
    assert set(seed["modules"]) == {"position", "odometrie", "sonar", "time"}
    assert "command" in seed["modules"]["odometrie"] and "links" in seed["modules"]["odometrie"]
    assert any(note.startswith("lops: ") and "no lops/" in note for note in seed["notes"])
