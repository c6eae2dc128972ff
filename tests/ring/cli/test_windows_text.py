"""Text from Windows editors (issue 52): every text input reads the same with a UTF-8 byte-order
mark and CRLF line ends as without — protocol, world, seed wall file, action file, localiser
configuration, chaos scenario, program, map — and UTF-16 text is refused by its name, never
with an invisible character in the message."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from modules.description import load_world
from modules.localization.config import load_config
from modules.navigation.actions import load_actions, parse_actions
from modules.pc.mapfiles import load_map_file
from tests.support.processes import REPO
from tests.support.refusal import refusal_line, run_refused
from tokenring.chaos.runner import load_scenario
from tokenring.contract.protocol import load_protocol
from tokenring.errors import TokenRingError
from tokenring.node.program import inspect_program, load_program_file

BOM = b"\xef\xbb\xbf"


def windows(text: str) -> bytes:
    """``text`` as a Windows editor saves it: a UTF-8 byte-order mark, CRLF line ends."""
    return BOM + text.replace("\r\n", "\n").replace("\n", "\r\n").encode("utf-8")


def protocol_summary(path: Path) -> object:
    protocol = load_protocol(path)
    return (protocol.frame_size, sorted((n.name, n.id) for n in protocol.nodes.values()))


def scenario_summary(path: Path) -> object:
    scenario = load_scenario(path)
    return (scenario.nodes, scenario.settle, [(f.at, f.node, f.kind, f.request) for f in scenario.faults])


def world_summary(path: Path) -> object:
    world = load_world(path)
    return (world.start, world.walls, world.circles)


def map_summary(path: Path) -> object:
    return load_map_file(str(path)).tolist()


MAP = json.dumps({"vectors": [[0, 0, 1000, 0], [1000, 0, 1000, 800]]}, indent=1) + "\n"
SEED_WALLS = "# the hall\n" + load_world("square").to_wall_file()
PROGRAM = (REPO / "modules" / "lcd.py").read_text()

#: name -> (file name, original text, reader giving something comparable)
INPUTS = {
    "protocol": ("protocol.yaml", (REPO / "protocol.yaml").read_text(), protocol_summary),
    "world": ("office.yaml", (REPO / "modules/description/rooms/office.yaml").read_text(), world_summary),
    "seed-walls": ("hall.walls", SEED_WALLS, world_summary),
    "actions": ("laps.act", (REPO / "actions/square-3-laps.act").read_text(), load_actions),
    "localizer": ("localization.yaml", (REPO / "config/localization.yaml").read_text(), load_config),
    "scenario": ("every-fault.yaml", (REPO / "scenarios/every-fault.yaml").read_text(), scenario_summary),
    "program": ("lcd.py", PROGRAM, lambda path: inspect_program(path.read_bytes(), str(path))),
    "program-load": ("lcd.py", PROGRAM, lambda path: load_program_file(path)[0].__name__),
    "map": ("map.json", MAP, map_summary),
}


@pytest.mark.parametrize("name", INPUTS)
def test_a_byte_order_mark_and_crlf_read_as_plain_text(name, tmp_path):
    filename, text, read = INPUTS[name]
    plain, bom = tmp_path / "plain", tmp_path / "windows"
    plain.mkdir()
    bom.mkdir()
    (plain / filename).write_text(text)
    (bom / filename).write_bytes(windows(text))
    if name == "localizer":  # its data logs go to a folder relative to the configuration
        for folder in (plain, bom):
            (folder / "logs").mkdir()
    assert read(bom / filename) == read(plain / filename)


def test_an_action_text_sent_with_its_mark_parses_on_the_node():
    """The PC strips the mark; main parses what arrives all the same."""
    assert parse_actions("\ufeffs 100\r\nr 90\r\n", "a.act") == parse_actions("s 100\nr 90\n", "a.act")


@pytest.mark.parametrize("encoding", ["utf-16", "utf-32"])
@pytest.mark.parametrize("name", ["protocol", "world", "actions", "localizer", "scenario"])
def test_utf16_text_is_refused_by_its_encoding(name, encoding, tmp_path):
    filename, text, read = INPUTS[name]
    path = tmp_path / filename
    path.write_bytes(text.encode(encoding))  # Python writes the byte-order mark first
    with pytest.raises(TokenRingError) as caught:
        read(path)
    message = str(caught.value)
    assert encoding.upper() in message and "UTF-8" in message and str(path) in message, message
    assert "\ufeff" not in message and "\\ufeff" not in message


#: what the command line does with a Windows file: (arguments with {f}, file name, text)
CLI = {
    "actions": (["up", "--actions", "{f}", "--duration", "1"], "bad.act", "s 100\r\nq 5\r\n"),
    "world": (
        ["up", "--world", "{f}", "--duration", "1"],
        "bad.yaml",
        "name: box\r\nwalls: [[0, 0, 0, 0]]\r\n",
    ),
    "scenario": (["chaos", "{f}"], "bad.yaml", "faults:\r\n  - {at: 1, node: sonar, kind: explode}\r\n"),
}


@pytest.mark.parametrize("name", CLI)
def test_a_mistake_in_a_windows_file_is_named_at_its_line(name, tmp_path):
    """Past the mark, the first error is the real one, at its real line (line 2)."""
    template, filename, text = CLI[name]
    path = tmp_path / filename
    path.write_bytes(BOM + text.encode())
    line = refusal_line(run_refused(*(a.format(f=path) for a in template)), f"{path}:2")
    assert "\ufeff" not in line and "\\ufeff" not in line and "\r" not in line, line
