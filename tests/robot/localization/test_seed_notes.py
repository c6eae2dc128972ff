"""The seed file's values that are accepted but do not apply here (``SeedConfig.notes``) reach the
operator: every command that takes such a file (``up --localizer``, ``console -C``, ``replay
--config``) says each once, ``file:line: [Section] option: why`` on stderr, and goes on; ``--json``
keeps stderr quiet, and a library call (copro's) says nothing. The console's own runs:
tests/robot/pc/test_console_modes.py."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from modules.localization.config import (
    ConfigError,
    load_config,
    read_seed_file,
    seed_notes,
)
from modules.localization.localizer import LocalizationCore
from modules.localization.logs import DataLog
from modules.localization.seedconfig import read_seed_config
from tests.support.locsim import drive
from tests.support.processes import REPO, run_tokenring

SYNCARIA = REPO / "config" / "syncaria.cfg"


def test_syncaria_cfgs_notes_are_one_line_each_in_file_order() -> None:
    lines = read_seed_config(SYNCARIA).note_lines()
    assert len(lines) == 17
    assert lines[0] == (
        f"{SYNCARIA}:13: [Main] Anbindung: the ring is the robot either way: tokenring up runs it on the "
        "world simulator (with --no-world on hardware); kept as SeedConfig.mode"
    )
    assert lines[1].startswith(f"{SYNCARIA}:71: [Gyroscop] Schnittstelle: the gyroscope is the ring's")
    numbers = [int(line.split(":")[1]) for line in lines]
    assert numbers == sorted(numbers) and all("\n" not in line for line in lines)


def test_said_once_while_a_command_holds_them_open_and_never_outside() -> None:
    said: list[str] = []
    load_config(SYNCARIA)  # no command: nobody is told (copro, the Localizer)
    with seed_notes(say=said.append):
        load_config(SYNCARIA)
        read_seed_file(SYNCARIA)
        with seed_notes(say=lambda line: said.append(f"inner {line}")):  # replay inside console -Moffline
            load_config(SYNCARIA)
    assert said == read_seed_config(SYNCARIA).note_lines()
    quiet: list[str] = []
    with seed_notes(quiet=True, say=quiet.append):
        load_config(SYNCARIA)
    assert quiet == []


def test_a_refused_file_says_only_its_error(tmp_path: Path) -> None:
    bad = tmp_path / "bad.cfg"
    bad.write_text(SYNCARIA.read_text().replace("0.33  -37", "0.4  -37"))
    said: list[str] = []
    with seed_notes(say=said.append), pytest.raises(ConfigError, match=r"bad.cfg:119: \[Lops\] Steigung 2"):
        load_config(bad)
    assert said == []


def test_up_says_them_before_anything_starts(capsys: pytest.CaptureFixture[str]) -> None:
    from modules.plugin import RobotExtension
    from tokenring.cli.commands import up
    from tokenring.contract.protocol import load_protocol

    parser = argparse.ArgumentParser()
    up.add_parser(parser.add_subparsers())
    args = parser.parse_args(
        ["up", "--sensors", "darmstadt", "--world", "darmstadt-hall", "--localizer", "syncaria"]
    )
    args.log_level = "info"  # the main parser's option, before the verb
    RobotExtension().plan_up(args, load_protocol(REPO / "protocol.yaml"))
    # by name: the bundled file's path names the lines
    assert capsys.readouterr().err.splitlines() == read_seed_config(SYNCARIA).note_lines()


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short drive's data log, recorded with the default configuration."""
    path = tmp_path_factory.mktemp("notes") / "run.trlog"
    config = load_config()
    core = LocalizationCore(config, data_log=DataLog(path, "test", config))
    for sample in drive([("s", 300.0)], seed=2):
        core.feed(sample)
        core.maybe_sync()
    core.close()
    return path


@pytest.mark.timeout(300)
def test_replay_says_them_on_stderr_and_keeps_quiet_under_json(recorded: Path, tmp_path: Path) -> None:
    told = run_tokenring(
        "replay", str(recorded), "--out", str(tmp_path / "a.trlog"), "--config", "config/syncaria.cfg",
        cwd=REPO, timeout=240,
    )  # fmt: skip
    assert told.returncode == 0, told.stderr
    notes = [line for line in told.stderr.splitlines() if line.startswith("config/syncaria.cfg:")]
    assert notes == [
        line.replace(str(SYNCARIA), "config/syncaria.cfg") for line in read_seed_config(SYNCARIA).note_lines()
    ]
    assert "synchronisations" in told.stdout
    quiet = run_tokenring(
        "replay", str(recorded), "--out", str(tmp_path / "b.trlog"), "--config", "config/syncaria.cfg",
        "--json", cwd=REPO, timeout=240,
    )  # fmt: skip
    assert quiet.returncode == 0, quiet.stderr
    assert "syncaria.cfg" not in quiet.stderr
    assert json.loads(quiet.stdout)["syncs"] > 0
