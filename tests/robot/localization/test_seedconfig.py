"""The seed's configuration format (appendix B.1, table B.1) read beside the YAML: sections and
values by position, syncaria's typed values, what the Localizer takes of them, what does not apply
here, and a clean one-line error naming the line for anything else."""

from __future__ import annotations

import os
from dataclasses import fields
from pathlib import Path

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from modules.localization.config import ConfigError, load_config, parse_config, sensor_set_layer
from modules.localization.seedconfig import (
    LOPSCPP_DEFAULTS,
    Section,
    Value,
    Values,
    looks_like_seed_config,
    read_sections,
    read_seed_config,
)
from modules.pc.seedplots import parse_config as parse_analyser_config
from modules.pc.seedplots import read_config as read_analyser_config
from tokenring.errors import TokenRingError

HALL_RECEIVERS = [[100.0, 100.0], [4900.0, 100.0], [100.0, 4900.0]]

MAIN = """[Main]
real         # Anbindung
ncurses      # Benutzerschnittstelle
odo          # Trigger
2            # Triggeranzahl
yes          # Kalmanfilter
no           # Positionsinitialisierung
data.trlog   # Datenlogdatei
2            # Debuglevel
no           # Fehlerlog
"""
SENSORS = """[SENSORS]
odo  yes yes yes yes yes yes
"""
ODOMETRY = "[Odometry]\nno\n"
MINIMAL = MAIN + SENSORS + ODOMETRY
WALLS = """[Walls]
yes 60 1400 15 10 30 35 15 50 10
square
400 20
"""
LOPS = """[Lops]
robot-pc 4554 /dev/ttyS0
0.33 -42  0.33 -37  0.33 -45
100 100  4900 100  100 4900
no yes 10
"""


# --------------------------------------------------------------------------------------------
# the format


def test_sections_and_values_by_position_with_their_lines() -> None:
    text = '# a comment\n[Main]  # the heading\nreal stdout\n"a b c"#after\n\n[ MAIN two ]\n#\n"" x\n'
    first, second = read_sections(text, "f.cfg")
    assert (first.name, first.key, first.line) == ("Main", "main", 2)
    assert first.values == (Value("real", 3), Value("stdout", 3), Value("a b c", 4, True))
    assert (second.name, second.key, second.line) == ("MAIN two", "main two", 6)
    assert second.values == (Value("", 8, True), Value("x", 8))
    assert read_sections("", "f.cfg") == [] and read_sections("# only\n\n", "f.cfg") == []
    assert read_sections("\ufeff[A]\r\nv\rw\n", "f.cfg") == [Section("A", 1, (Value("v", 2), Value("w", 3)))]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("real\n[Main]\n", "f.cfg:1: 'real' stands before the first section ([Name])"),
        ("[Main\nreal\n", "f.cfg:1: a section name opened with '[' has no ']' on its line"),
        ("[]\n", "f.cfg:1: [] names no section"),
        ("[Ma#in]\n", "f.cfg:1: ['Ma#in']: '#' may not be in a section name"),
        ('[Main]\n\n"a b\n', "f.cfg:3: a value opened with '\"' is not closed on its line"),
        ('[Main]\n"a # b"\n', "f.cfg:2: 'a # b': '#' may not be in a value (it starts a comment)"),
        ('[Main]\n"a [b"\n', "f.cfg:2: 'a [b': '[' may not be in a value (it starts a section name)"),
        ("[Main]\nab[c]\n", "f.cfg:2: 'ab[c]': '[' may not be in a value (it starts a section name)"),
        (
            '[Main]\nab"c"\n',
            "f.cfg:2: 'ab\"c\"': '\"' may not be in a value (quotes go around a whole value)",
        ),
        ('[Main]\n"ab"c\n', "f.cfg:2: '\"ab\"c': a quoted value ends at its closing quote"),
        ("[Main]\na\x00b\n", "f.cfg:2: 'a\\x00b': a control character may not be in a value"),
    ],
)
def test_a_malformed_file_names_its_line(text: str, message: str) -> None:
    with pytest.raises(ConfigError) as caught:
        read_sections(text, "f.cfg")
    assert str(caught.value).startswith(message), str(caught.value)


def test_values_are_taken_in_order_each_checked() -> None:
    (section,) = read_sections("[Lops]\nyes 7 -1.5e2 NCurses\n", "f.cfg")
    r = Values(section, "f.cfg")
    assert r.yes_no("Gewichten") is True
    assert r.whole("Port", 1, 65535) == 7
    assert r.number("Offset 1") == -150.0
    assert r.choice("Benutzerschnittstelle", {"ncurses": "ncurses"}, "ui") == "ncurses"
    assert r.lines == {"Gewichten": 2, "Port": 2, "Offset 1": 2, "ui": 2} and not r.more()
    r.end()
    with pytest.raises(ConfigError, match=r"f.cfg:2: \[Lops\] ends after Benutzerschnittstelle: Grundwert"):
        r.number("Grundwert", positive=True)
    for text, taker, expected in (
        ("maybe", lambda r: r.yes_no("Gewichten"), "Gewichten: expected yes or no, got 'maybe'"),
        ("0", lambda r: r.whole("Port", 1, 65535), "Port: expected a whole number 1-65535, got '0'"),
        (
            "0,33",
            lambda r: r.number("Steigung 1"),
            "Steigung 1: expected a number (a point for decimals), got '0,33'",
        ),
        (
            "nan",
            lambda r: r.number("Steigung 1"),
            "Steigung 1: expected a number (a point for decimals), got 'nan'",
        ),
        ("1e999", lambda r: r.number("Steigung 1"), "Steigung 1: expected a number, got '1e999'"),
        ("0", lambda r: r.number("Steigung 1", positive=True), "Steigung 1: expected a number > 0, got '0'"),
    ):
        (section,) = read_sections(f"[Lops]\n\n{text}\n", "f.cfg")
        with pytest.raises(ConfigError) as caught:
            taker(Values(section, "f.cfg"))
        assert str(caught.value) == f"f.cfg:3: [Lops] {expected}"
    (section,) = read_sections("[Odometry]\nyes\nno\n", "f.cfg")
    r = Values(section, "f.cfg")
    r.yes_no("Kreisberechnung")
    with pytest.raises(
        ConfigError, match=r"f.cfg:3: \[Odometry\] 'no' is one value too many: the section ends after Kreis"
    ):
        r.end()


def test_a_file_is_the_seeds_when_its_first_token_is_a_section() -> None:
    assert looks_like_seed_config("# syncaria\n\n  [Main]\nreal\n")
    assert looks_like_seed_config("[MAIN] # x")
    assert not looks_like_seed_config("sensors:\n  gyro: {use: true}\n")
    assert not looks_like_seed_config("# [Main]\nfilter: {}\n")
    assert not looks_like_seed_config("[1, 2]\n")


# --------------------------------------------------------------------------------------------
# syncaria's values (table B.1)


def test_every_value_of_a_minimal_file_in_its_place() -> None:
    seed = read_seed_config(MINIMAL, "min.cfg")
    m = seed.main
    assert (m.connection, m.ui, m.trigger, m.trigger_count) == ("robot", "ncurses", "odometry", 2)
    assert (m.kalman_filter, m.position_init, m.data_log, m.debug_level) == (True, False, "data.trlog", 2)
    assert (m.error_log, m.error_log_file) == (False, None)
    (odo,) = seed.sensors
    assert (odo.name, odo.spelled, odo.line) == ("odometry", "odo", 12)
    assert [getattr(odo, f.name) for f in fields(odo)][2:8] == [True] * 6
    assert seed.odometry is not None and seed.odometry.circle is False
    assert (seed.ui, seed.mode, seed.debug_level, seed.offline) == ("ncurses", "robot", 2, None)
    assert seed.actions.auto is False and seed.actions.files == (None, None, None)
    assert seed.walls is None and seed.lops is None and seed.gyroscope is None


def test_the_localizer_takes_what_applies_and_names_every_lines() -> None:
    seed = read_seed_config(MINIMAL, "min.cfg")
    layer = seed.localization_layer()
    assert layer["sync"] == {
        "trigger": {"mode": "count", "sensor": "odometry", "count": 2, "min_period_ms": 0, "rounds": 0}
    }
    assert layer["filter"] == {"enabled": True, "odometry_model": "straight"}
    assert layer["logs"] == {"data": "data.trlog", "debug_level": 2, "error_log": False}
    assert layer["ui"] == "ncurses" and "actions" not in layer
    assert layer["sensors"]["odometry"] == {
        "use": True, "synchronise": True, "position": True, "log_raw": True, "log_sync": True,
        "log_position": True, "filter": True,
    }  # fmt: skip
    assert {name: s for name, s in layer["sensors"].items() if name != "odometry"} == {
        name: {"use": False} for name in ("compass", "gyro", "correlator", "sonar", "battery", "lops")
    }  # the truth is the emulator's reference: the seed never listed it
    lines = seed.layer_lines()
    assert lines[("sync", "trigger", "sensor")] == 4 and lines[("logs", "debug_level")] == 9
    assert lines[("sensors", "compass", "use")] == 11  # the [Sensors] heading: not listed there
    config = parse_config(MINIMAL, "min.cfg")
    assert config["sync"]["trigger"]["mode"] == "count" and config["logs"]["debug"] is False
    assert not config["sensors"]["compass"]["use"] and config["sensors"]["truth"]["use"]
    # what the seed has no option for is config/localization.yaml's (its sonar model here)
    assert config["walls"]["range_model"] == load_config("config/localization.yaml")["walls"]["range_model"]


def test_the_seeds_names_in_any_case_and_the_sensor_names_it_used() -> None:
    text = MAIN.replace("[Main]", "[MAIN]").replace("odo ", "Gyroscop ") + (
        "[sensors]\nOdometry yes yes yes yes yes yes\nGyroscop yes no no no no no\n"
        "walls yes no yes yes no no\n[ODOMETRY]\nYES\n[gyroscope]\n/dev/ttyS1\n" + WALLS
    )
    seed = read_seed_config(text, "case.cfg")
    assert [row.name for row in seed.sensors] == ["odometry", "gyro", "sonar"]
    assert seed.main.trigger == "gyro" and seed.odometry is not None and seed.odometry.circle
    config = parse_config(text, "case.cfg")
    assert config["sync"]["trigger"]["sensor"] == "gyro"
    assert config["sensors"]["gyro"]["position"] is False and config["sensors"]["sonar"]["filter"] is False
    assert config["walls"]["min_points_side"] == 15 and config["walls"]["association"]["max_d_mm"] == 400.0


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[Sensors]\nodo yes yes yes yes yes yes\n", "c.cfg: no [Main] section (table B.1)"),
        (MAIN, "c.cfg: no [Sensors] section"),
        (MINIMAL + "[Foo]\n", "c.cfg:15: [Foo] is no section of table B.1 ([Main], [Sensors], [Odometry]"),
        (MINIMAL + "[main]\n", "c.cfg:15: [main] again (the first at line 1)"),
        (MINIMAL.replace("real ", "mobile"), "c.cfg:2: [Main] Anbindung: expected robot or real or sim, got 'mobile'"),
        (MINIMAL.replace("ncurses", "gtk"), "c.cfg:3: [Main] Benutzerschnittstelle: expected stdout or ncurses or none"),
        (MINIMAL.replace("odo    ", "sextant"), "c.cfg:4: [Main] Trigger: expected odo or odometry or gyro"),
        (MINIMAL.replace("2            # Trig", "0            # Trig"), "c.cfg:5: [Main] Triggeranzahl: expected a whole number 1-1000000, got '0'"),
        (MINIMAL.replace("2            # Debug", "5            # Debug"), "c.cfg:9: [Main] Debuglevel: expected a whole number 0-4, got '5'"),
        (MINIMAL.replace("no           # Fehlerlog", "yes"), "c.cfg:10: [Main] Fehlerlog is yes: Fehlerlogdatei (a file name) must follow it"),
        (MAIN.replace("2            # Debuglevel\n", "\n") + SENSORS, "c.cfg:10: [Main] Debuglevel: expected a whole number 0-4, got 'no'"),
        (MINIMAL.replace("data.trlog", "logs/"), "c.cfg:8: [Main] Datenlogdatei: expected a file name, not a folder, got 'logs/'"),
        (MINIMAL.replace("no           # Fehlerlog", "no e.trerr extra"), "c.cfg:10: [Main] 'extra' is one value too many: the section ends after Fehlerlogdatei"),
        (MAIN + "[Sensors]\n" + ODOMETRY, "c.cfg:11: [Sensors] lists no sensor (7 values each)"),
        (MAIN + "[Sensors]\nodo yes yes yes\n" + ODOMETRY, "c.cfg:12: [Sensors] ends after Rohdatenlogging of odo: Synchronisation loggen of odo (yes or no) is missing"),
        (MINIMAL.replace("odo  yes", "odo yes yes yes yes yes yes\nodo  yes"), "c.cfg:13: [SENSORS] odo: odometry is listed twice (first at line 12)"),
        (MINIMAL.replace("odo  yes", "lidar yes"), "c.cfg:12: [SENSORS] Sensorname: expected odo or odometry"),
        (MINIMAL.replace("odo  yes yes yes", "odo  yes maybe yes"), "c.cfg:12: [SENSORS] Position of odo: expected yes or no, got 'maybe'"),
        (MINIMAL.replace("odo  yes", "odo  no"), "c.cfg:12: [SENSORS] Synchronisieren of odo: no is not possible here: the odometry's synchronised steps"),
        (MINIMAL.replace("odo  yes", "gyro yes yes yes yes yes yes\nodo  yes"), "c.cfg:12: [Sensors] gyro is listed, but there is no [Gyroscop] section for it"),
        (MAIN + SENSORS, "c.cfg:12: [Sensors] odo is listed, but there is no [Odometry] section for it"),
        (MINIMAL.replace("odo          # Trigger", "lops"), "c.cfg:4: [Main] Trigger: lops triggers the synchronisation but is not listed in [Sensors]"),
        (MINIMAL.replace("no           # Positionsinitialisierung", "yes"), "c.cfg:7: [Main] Positionsinitialisierung: yes initialises the position by LOPS, which is not listed"),
        (MINIMAL + "[Gyroscop]\n\"\"\n", "c.cfg:16: [Gyroscop] Schnittstelle: expected a name, not an empty value, got ''"),
        (MINIMAL + WALLS.replace("square", "nowhere-hall"), "c.cfg:17: [Walls] Wanddatei: nowhere-hall: no such world file or bundled world"),
        (MINIMAL + WALLS.replace(" 15 10 ", " 2 10 "), "c.cfg:16: [Walls] min. Punkte (Seite): expected a whole number >= 3, got '2'"),
        (MINIMAL + WALLS.replace("400 20", "400"), "c.cfg:18: [Walls] ends after max. Δd (Zuordnung): max. Δα (Zuordnung) (a number 0-180) is missing"),
        (MINIMAL + LOPS.replace("0.33 -42", "0.343 -42"), "c.cfg:17: [Lops] Steigung 1: 0.343 is lopscpp's, and the LOPS tokenring up --sensors darmstadt starts runs with 0.33"),
        (MINIMAL + LOPS.replace("no yes 10", "yes yes 10"), "c.cfg:19: [Lops] Gewichten: yes is lopscpp's"),
        (MINIMAL + LOPS.replace("no yes 10", "no yes 10 0.2"), "c.cfg:19: [Lops] Grundwert: 0.2 is lopscpp's"),
        (MINIMAL + LOPS.replace("4554", "99999"), "c.cfg:16: [Lops] Port: expected a whole number 1-65535, got '99999'"),
        (MINIMAL + "[Offline]\nresult.trlog errors.trerr\n", "c.cfg:16: [Offline] ends after Fehlerdatei: Synchronisierte Daten (yes or no) is missing"),
        (MINIMAL + "[Action]\nyes\n", "c.cfg:16: [Action] Auto is yes: Datei 1 (the action file driven at the start) must follow"),
        (MINIMAL + "[Action]\nno a.act b.act c.act d.act\n", "c.cfg:16: [Action] 'd.act' is one value too many: the section ends after Datei 3"),
    ],
)  # fmt: skip
def test_every_error_is_one_line_naming_the_file_line_value_and_what_was_expected(
    text: str, message: str
) -> None:
    with pytest.raises(ConfigError) as caught:
        parse_config(text, "c.cfg")
    assert str(caught.value).startswith(message), str(caught.value)
    assert "\n" not in str(caught.value)


def test_a_check_of_the_yaml_names_the_seeds_line() -> None:
    """A value the seed's reader takes but the Localizer's checks refuse names the .cfg's line."""
    text = MINIMAL.replace("odo  yes", "truth yes yes yes yes yes yes\nodo  yes")
    with pytest.raises(
        ConfigError, match=r"^c.cfg:12: sensors.truth.filter: the ground truth is a reference only"
    ):
        parse_config(text, "c.cfg")


def test_a_sensor_not_synchronised_is_noted_or_refused() -> None:
    rows = "odo yes yes yes yes yes yes\ngyro no no yes yes yes yes\nbattery yes yes yes yes no no\n"
    text = MAIN + "[Sensors]\n" + rows + ODOMETRY + "[Gyroscop]\n/dev/ttyS1\n"
    seed = read_seed_config(text, "n.cfg")
    gyro = seed.localization_layer()["sensors"]["gyro"]
    assert gyro == {"use": True, "synchronise": False, "position": False, "log_raw": True, "log_sync": False,
                    "log_position": False, "filter": False}  # fmt: skip
    assert [(n.line, n.option) for n in seed.notes()] == [
        (2, "[Main] Anbindung"),
        (13, "[Sensors] gyro Synchronisation loggen"),
        (13, "[Sensors] gyro Kalmanfilter"),
        (13, "[Sensors] gyro Positionslogging"),
        (14, "[Sensors] battery Position"),
        (18, "[Gyroscop] Schnittstelle"),
    ]
    config = parse_config(text, "n.cfg")
    assert config["sensors"]["gyro"]["use"] and not config["sensors"]["gyro"]["synchronise"]
    with pytest.raises(
        ConfigError, match=r"n.cfg:13: \[Sensors\] Position of gyro: yes with Synchronisieren no"
    ):
        read_seed_config(text.replace("gyro no no", "gyro no yes"), "n.cfg")


def test_lopscpps_values_are_the_ones_the_started_lops_runs_with() -> None:
    from modules.lops.config import LopsConfig

    started = LopsConfig(receivers=((0.0, 0.0), (1.0, 0.0), (0.0, 1.0)))
    assert {
        "slopes": started.slopes,
        "offsets": started.offsets,
        "weighting": started.weighting,
        "position_filter": started.position_filter,
        "history_length": started.history_length,
        "grundwert": started.grundwert,
    } == LOPSCPP_DEFAULTS


def test_lops_receivers_other_than_the_started_lopss_are_refused() -> None:
    text = MINIMAL.replace("odo  yes", "lops yes yes yes yes yes yes\nodo  yes") + LOPS
    under = sensor_set_layer("darmstadt", HALL_RECEIVERS)
    assert parse_config(text, "l.cfg", under)["lops"]["receivers"] == HALL_RECEIVERS
    moved = [[100.0, 100.0], [4900.0, 100.0], [100.0, 4800.0]]
    with pytest.raises(ConfigError, match=r"^l.cfg:19: \[Lops\] X/Y-Position 3: 100 4900 mm, but the LOPS"):
        parse_config(text, "l.cfg", sensor_set_layer("darmstadt", moved))


def test_files_to_read_are_the_config_files_folder_and_logs_the_logs_folder(tmp_path: Path) -> None:
    (tmp_path / "walls.txt").write_text("1000 0 0 2000 0 2000 -100 100 0 90\n")
    text = MINIMAL.replace("odo  yes", "walls yes yes yes yes yes no\nodo  yes") + WALLS.replace(
        "square", "walls.txt"
    )
    text += "[Offline]\nout.trlog /tmp/out.trerr yes\n[Action]\nno one.act\n"
    path = tmp_path / "run.cfg"
    path.write_text(text)
    seed = read_seed_config(path)
    assert seed.actions.files == (tmp_path / "one.act", None, None)
    assert seed.localization_layer()["walls"]["file"] == str(tmp_path / "walls.txt")
    assert seed.offline is not None
    assert (seed.offline.input, seed.offline.result) == (Path("logs/data.trlog"), Path("logs/out.trlog"))
    assert (seed.offline.errors, seed.offline.synchronised) == (Path("/tmp/out.trerr"), True)
    config = load_config(path)
    assert config["actions"] == {"auto": False, "files": [str(tmp_path / "one.act")]}
    assert config["walls"]["file"] == str(tmp_path / "walls.txt")


def test_a_log_name_is_taken_as_written_braces_and_all() -> None:
    config = parse_config(MINIMAL.replace("data.trlog", "run{1}.trlog"), "b.cfg")
    assert config["logs"]["data"].format(start="x") == "run{1}.trlog"


# --------------------------------------------------------------------------------------------
# the ways in: load_config, tokenring replay --config (tokenring up --localizer: test_syncaria_cfg.py)


def test_load_config_takes_a_cfg_file_or_seed_text_under_any_name(tmp_path: Path) -> None:
    (tmp_path / "run.cfg").write_text(MINIMAL)
    (tmp_path / "run.txt").write_text(MINIMAL)
    assert load_config(tmp_path / "run.cfg") == load_config(tmp_path / "run.txt")
    assert load_config(tmp_path / "run.cfg")["filter"]["odometry_model"] == "straight"
    (tmp_path / "yaml.cfg").write_text("filter: {enabled: false}\n")
    with pytest.raises(ConfigError, match=r"yaml.cfg:1: 'filter:' stands before the first section"):
        load_config(tmp_path / "yaml.cfg")


def test_replay_takes_a_seed_file(tmp_path: Path) -> None:
    from modules.localization.localizer import LocalizationCore
    from modules.localization.logs import DataLog, read_log
    from tests.support.locsim import drive
    from tokenring.cli.main import main as cli_main

    config = load_config()
    with DataLog(tmp_path / "run.trlog", "test", config) as log:
        core = LocalizationCore(config, data_log=log)
        for sample in drive([("s", 300.0)], seed=1):
            core.feed(sample)
            core.maybe_sync()
    seed = tmp_path / "mine.cfg"
    seed.write_text(MINIMAL)
    out = tmp_path / "again.trlog"
    assert cli_main(["replay", str(tmp_path / "run.trlog"), "--out", str(out), "--config", str(seed)]) == 0
    replayed = read_log(out)
    assert replayed.header["config"]["filter"]["odometry_model"] == "straight"
    assert not any(source == "M" for _, source, _, _ in replayed.records)  # not listed: not used


# --------------------------------------------------------------------------------------------
# never a traceback

FUZZ = settings(
    max_examples=int(os.environ.get("TOKENRING_FUZZ_EXAMPLES", "60")),
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
#: the words of table B.1's files, so that random files reach past the first checks
WORDS = [
    "[Main]", "[Sensors]", "[Odometry]", "[Gyroscop]", "[Walls]", "[Lops]", "[Offline]", "[Action]",
    "real", "sim", "stdout", "ncurses", "none", "odo", "gyro", "walls", "lops", "compass", "truth",
    "yes", "no", "0", "1", "3", "4", "15", "60", "-42", "0.33", "1e9", "1e10", "4900", "square",
    "darmstadt-hall", "a.act", "/dev/ttyS1", '"a b"', "#", "\n", " ", "\t", "[", "]", '"', "\x00",
    "\u2028", "\ud800", "x" * 300,
]  # fmt: skip


def one_line_or_nothing(call) -> None:
    try:
        call()
    except TokenRingError as exc:
        assert str(exc).strip() and "\n" not in str(exc).strip(), repr(str(exc))


@FUZZ
@given(text=st.text(max_size=400))
@example(text="[Main]\n\u2028")
@example(text='[A] "')
@example(text='[MAIN] "')
def test_random_text_is_a_clean_error(text: str) -> None:
    """Table B.1's readers (syncaria's file, tokenring's YAML) and table B.2's (the analyser's)."""
    one_line_or_nothing(lambda: read_seed_config(text, "fuzz.cfg"))
    one_line_or_nothing(lambda: parse_config(text, "fuzz.cfg"))
    one_line_or_nothing(lambda: parse_analyser_config(text, "fuzz.cfg"))


@FUZZ
@given(data=st.binary(max_size=400))
def test_random_bytes_are_a_clean_error(data: bytes, tmp_path_factory: pytest.TempPathFactory) -> None:
    path = tmp_path_factory.mktemp("fuzz") / "input.cfg"
    path.write_bytes(data)
    one_line_or_nothing(lambda: load_config(path))
    one_line_or_nothing(lambda: read_seed_config(data, "fuzz.cfg"))
    one_line_or_nothing(lambda: read_analyser_config(path))


@FUZZ
@given(words=st.lists(st.sampled_from(WORDS), max_size=80))
@example(words=MINIMAL.split())
def test_files_of_the_seeds_words_are_a_clean_error_or_a_configuration(words: list[str]) -> None:
    text = " ".join(words)
    one_line_or_nothing(lambda: parse_config(text, "fuzz.cfg"))
    one_line_or_nothing(lambda: parse_config(MINIMAL + text, "fuzz.cfg"))


#: table B.2 of seed 000 (the logfileanalyser's file), its sections and values in order; "*": the
#: value repeats (per position, wheel, sonar, sensor)
TABLE_B2: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("MAIN", ("Logdatei", "Output", "Pfadplot", "LOPS-Plot", "Gyroskopplot", "Odometrieplot", "Sonarplot",
              "Timeplot")),
    ("POSITION", ("Format", "Position*", "Stil*")),
    ("ODOMETRY", ("Format", "Stil*")),
    ("GYROSCOP", ("Format", "Stil")),
    ("SONAR", ("Format", "Stil*")),
    ("TIME", ("Format", "Synchronisation", "Stil", "Sensor*", "Stil*")),
)  # fmt: skip


def doc_table(heading: str) -> dict[str, list[tuple[str, str]]]:
    """docs/seed-config.md's table under ``heading``: each section's rows as (value, status)."""
    from tests.support.processes import REPO

    doc = (REPO / "docs" / "seed-config.md").read_text()
    part = doc[doc.index(heading) :]
    rows: dict[str, list[tuple[str, str]]] = {}
    section = ""
    for line in part.splitlines()[1:]:
        if line.startswith("## "):
            break
        if not line.startswith("| ") or line.startswith(("| section ", "|---")):
            continue
        cells = [cell.strip() for cell in line.strip("|").split(" | ")]
        assert len(cells) == 5, line
        section = cells[0].split("]")[0].removeprefix("[") if cells[0] else section
        rows.setdefault(section, []).append((cells[1], cells[3]))
    return rows


@pytest.mark.parametrize(
    ("heading", "table"),
    [("## syncaria's file (table B.1)", "B1"), ("## The logfileanalyser's file (table B.2)", "B2")],
)
def test_the_docs_table_names_every_value_of_tables_b1_and_b2(heading: str, table: str) -> None:
    """Every value of the table in its section's rows, each row honoured, a note or refused."""
    from modules.localization.seedconfig import TABLE_B1

    rows = doc_table(heading)
    for section, options in TABLE_B1 if table == "B1" else TABLE_B2:
        assert section in rows, (table, section)
        values = " ".join(value for value, _ in rows[section])
        for option in options:
            name = option.rstrip("*?").removesuffix(" n")
            assert name in values, (table, section, name)
    for section, section_rows in rows.items():
        for value, status in section_rows:
            assert set(status.split(", or ")) <= {"honoured", "note", "refused"}, (section, value, status)


#: the words of table B.2's files (the logfileanalyser's), so that random files reach past the
#: first checks
B2_WORDS = [
    "[MAIN]", "[POSITION]", "[LOPS]", "[ODOMETRY]", "[GYROSCOP]", "[SONAR]", "[TIME]", "log.txt",
    "out", "yes", "no", "pngcairo", "x11", '"pngcairo size 800,800"', '"lines lw 2"', "lines",
    "points", "kalman", "odometrie", "lops", "truth", "gyro", "0", "1", "-1", "1e9", "#", "\n", " ", "\t", "[", "]", '"', "\x00",
    "\u2028", "\ud800", "x" * 300,
]  # fmt: skip


@FUZZ
@given(words=st.lists(st.sampled_from(B2_WORDS), max_size=80))
@example(words=["[POSITION]", "pngcairo", "kalman", "lines"])
def test_files_of_the_analysers_words_are_a_clean_error_or_a_configuration(words: list[str]) -> None:
    text = " ".join(words)
    main = "[MAIN]\nlog.txt out yes no no no no no\n"  # (a configuration, with [POSITION] after it)
    one_line_or_nothing(lambda: parse_analyser_config(text, "fuzz.cfg"))
    one_line_or_nothing(lambda: parse_analyser_config(main + text, "fuzz.cfg"))
