"""``tokenring console``'s command line: the seed's spelling (table 8.1), its configuration's
user interface and action files (bound to a, b, c), and bad input as one line with exit code 2.
The modes run to the end: test_console_modes.py."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import pytest

from modules.pc.commands import console
from modules.pc.operator import Operator
from tests.support.processes import REPO, run_tokenring
from tokenring import UsageError


def parse(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    console.add_parser(sub)
    return parser.parse_args(["console", *argv])


@pytest.mark.parametrize(
    ("argv", "mode"),
    [((), "online"), (("-Online",), "online"), (("-Moffline",), "offline"), (("-Monline",), "online")],
)
def test_the_seeds_command_line_is_taken_as_it_was_spelled(argv: tuple[str, ...], mode: str) -> None:
    assert console.program_mode(parse(*argv)) == mode


def test_c_names_the_configuration_as_the_seed_wrote_it() -> None:
    args = parse("-Cconfig/syncaria.cfg")
    assert args.config == "config/syncaria.cfg"


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (("-Ofline",), "-Ofline: the seed's option is -Online"),
        (("-Mbatch",), "-Mbatch: the mode is online or offline"),
        (("-Online", "-Moffline"), "both given"),
    ],
)
def test_a_mode_that_is_not_the_seeds_is_refused(argv: tuple[str, ...], message: str) -> None:
    with pytest.raises(UsageError, match=message):
        console.program_mode(parse(*argv))


def test_the_seeds_configuration_gives_the_screen_and_the_action_files() -> None:
    chosen = console.settings(parse("-C", str(REPO / "config" / "syncaria.cfg")))
    assert chosen["ui"] == "stdout"  # figure B.1's choice
    first = chosen["files"][0]
    assert first is not None and Path(first).name == "square-3-laps.act" and Path(first).is_file()
    assert chosen["offline"] is not None


class Link:
    """main's PC link as the operator uses it, recording the action files it is sent."""

    def __init__(self) -> None:
        self.sent: list[dict[str, Any]] = []

    def request(self, verb: str, **payload: Any) -> dict[str, Any]:
        if verb == "actions":
            self.sent.append(payload)
        return {"running": bool(self.sent), "queue": []}


@pytest.mark.parametrize("auto", ["yes", "no"])
def test_the_seeds_action_section_binds_its_three_files_to_a_b_and_c(tmp_path: Path, auto: str) -> None:
    texts = {"one.act": "s 100\n", "two.act": "r 90\n", "three.act": "s -50\n"}
    for name, text in texts.items():
        (tmp_path / name).write_text(text)
    cfg = tmp_path / "keys.cfg"
    cfg.write_text(
        "[Main]\nsim none odo 1 yes no data.trlog 2 no\n[Sensors]\nodo yes yes yes yes yes yes\n"
        f"[Odometry]\nyes\n[Action]\n{auto}\n" + "\n".join(texts) + "\n"
    )
    chosen = console.settings(parse("-C", str(cfg)))
    assert chosen["auto"] is (auto == "yes") and chosen["ui"] == "none"
    link = Link()
    operator = Operator(link, chosen["files"])
    for key in "cab":
        assert operator.press(key).ok
    assert [(Path(p["name"]).name, p["text"]) for p in link.sent] == [
        ("three.act", "s -50\n"), ("one.act", "s 100\n"), ("two.act", "r 90\n")
    ]  # fmt: skip


def test_the_command_line_wins_over_the_configuration(tmp_path: Path) -> None:
    mine = tmp_path / "mine.act"
    mine.write_text("s 100\n")
    chosen = console.settings(
        parse("-C", str(REPO / "config" / "syncaria.cfg"), "--ui", "none", "--action", str(mine))
    )
    assert chosen["ui"] == "none" and chosen["files"][0] == str(mine)


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["-Ofline"], "-Ofline: the seed's option is -Online"),
        (["--action", "/nonexistent/a.act"], "action file /nonexistent/a.act: no such file"),
        (["--action", "BAD"], ":2: unknown action 'fly'"),
        (["-C", "BADCFG"], "bad.cfg"),
        (["-Moffline"], "-Moffline replays the data log that the configuration names"),
        (["--auto"], "--auto runs the first action file, and none is given"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(tmp_path: Path, argv: list[str], needle: str) -> None:
    bad = tmp_path / "bad.act"
    bad.write_text("s 100\nfly 3\n")
    cfg = tmp_path / "bad.cfg"
    cfg.write_text("[Main]\nreal\nncurses\nodometry\nzero\n")
    argv = [str(bad) if a == "BAD" else str(cfg) if a == "BADCFG" else a for a in argv]
    result = run_tokenring("console", *argv, "--ring", "nobody-here", timeout=60)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], result.stderr
    assert "Traceback" not in result.stderr


def test_without_c_a_default_cfg_in_the_working_directory_is_read(tmp_path: Path) -> None:
    """Table 8.1: the configuration is default.cfg unless -C names another."""
    (tmp_path / "default.cfg").write_text(
        "[Main]\nsim none odo 1 yes no data.trlog 2 no\n[Sensors]\nodo yes yes yes yes yes yes\n"
        "[Odometry]\nyes\n[Action]\nno\nmissing.act\n"
    )
    result = run_tokenring("console", "--ring", "nobody-here", timeout=60, cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert "reading default.cfg" in result.stderr and "missing.act" in result.stderr, result.stderr
    assert "Traceback" not in result.stderr
    mine = tmp_path / "mine.cfg"
    mine.write_text(
        "[Main]\nsim none odo 1 yes no data.trlog 2 no\n[Sensors]\nodo yes yes yes yes yes yes\n[Odometry]\nyes\n"
    )
    chosen = console.settings(parse("-C", str(mine)))
    assert not any(chosen["files"]) and chosen["ui"] == "none"  # -C's file, not default.cfg's
