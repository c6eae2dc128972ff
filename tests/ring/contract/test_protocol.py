"""protocol.yaml: the real file compiles, and every kind of broken file is refused by name."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import yaml

from tests.support.processes import REPO, run_tokenring
from tokenring.contract.protocol import load_protocol, parse_protocol
from tokenring.errors import ProtocolError

TEXT = (REPO / "protocol.yaml").read_text()
DOC = yaml.safe_load(TEXT)


def compile_doc(doc: dict) -> None:
    parse_protocol(yaml.safe_dump(doc, sort_keys=False), "broken.yaml")


def broken(mutate) -> ProtocolError:
    doc = copy.deepcopy(DOC)
    mutate(doc)
    with pytest.raises(ProtocolError) as info:
        compile_doc(doc)
    return info.value


def test_real_protocol_compiles_with_eight_nodes_in_id_order():
    """The Hamburg robot's eight, then the Darmstadt sensors' nodes (``up --sensors darmstadt``)."""
    protocol = load_protocol(REPO / "protocol.yaml")
    hamburg = ["main", "motor", "sonar", "compass", "copro", "map", "lcd", "charger"]
    assert list(protocol.nodes) == [*hamburg, "gyro", "correlator"]
    ids = [n.id for n in protocol.nodes.values()]
    assert ids == sorted(ids) and len(set(ids)) == 10
    assert [n.seed_name for n in protocol.nodes.values()][:2] == ["ROBMAIN", "ROBMOTOR"]
    assert protocol.header.sid == 0 and protocol.header.counter == 4 and protocol.header_size == 12
    assert protocol.system_data_offset == 12 and protocol.system_data_size == 32
    assert protocol.frame_size == 514
    for ch in protocol.channels.values():
        assert ch.address >= 12 and ch.end <= 512, ch.name
    # the Darmstadt nodes are optional: a ring named by nobody starts without them
    assert [n.name for n in protocol.nodes.values() if n.optional] == ["gyro", "correlator"]
    assert [n.name for n in protocol.default_nodes] == hamburg


def test_optional_must_be_a_boolean():
    def mutate(doc):
        doc["nodes"]["gyro"]["optional"] = "yes"

    assert "nodes.gyro.optional" in str(broken(mutate))


def test_channel_views_are_zero_copy_over_the_token():
    protocol = load_protocol(REPO / "protocol.yaml")
    token = bytearray(514)
    sonar = protocol.channel("ROBSONAR_DATA")
    view = sonar.view(token)
    view["distances"][2] = 77
    view["sweep"] = 0x1234
    fields = {f.name: f for f in sonar.fields}
    assert token[sonar.address + fields["distances"].offset + 2] == 77
    offset = sonar.address + fields["sweep"].offset
    assert token[offset : offset + 2] == b"\x34\x12"  # little-endian
    token[sonar.address] = 5
    assert view["distances"][0] == 5  # the view follows the buffer
    assert sonar.decode(token)["distances"][:3] == [5, 0, 77]


def test_command_dtypes_overlay_the_header_and_arguments():
    protocol = load_protocol(REPO / "protocol.yaml")
    inbox = protocol.channel("motor.command")
    move = inbox.command("MOVE_FORWARD")
    assert move.dtype.itemsize == inbox.size
    assert move.dtype.names[:5] == ("sender", "state", "code", "seq", "incarnation")
    assert inbox.command(move.code) is move
    assert "VECTOR" in inbox.commands  # common commands are accepted by every inbox
    header_size = sum(f.size for f in protocol.command_header)
    assert header_size == 9  # u8 sender, state, code; u16 seq; u32 incarnation
    assert np.dtype(move.dtype).fields["distance_mm"][1] == header_size


def test_missing_file_is_named():
    with pytest.raises(ProtocolError, match=r"nope\.yaml: no such protocol file"):
        load_protocol("/tmp/nope.yaml")


def test_yaml_syntax_error_names_line():
    with pytest.raises(ProtocolError, match=r"line \d+, column \d+: YAML syntax error"):
        parse_protocol("version: 1\ntoken: {size: 512\n", "bad.yaml")


def test_overlapping_channels_name_both():
    err = broken(lambda d: d["nodes"]["sonar"]["data"].__setitem__("address", 60))
    assert "nodes.sonar.data" in str(err)
    assert "overlaps motor.data" in str(err) or "overlaps motor.command" in str(err)


def test_channel_past_byte_511():
    err = broken(lambda d: d["nodes"]["charger"]["data"].__setitem__("address", 500))
    assert "nodes.charger.data" in str(err) and "past the token's last byte 511" in str(err)


def test_channel_into_the_header():
    err = broken(lambda d: d["nodes"]["main"]["command"].__setitem__("address", 8))
    assert "nodes.main.command" in str(err) and "inside the token header" in str(err)


def test_field_that_does_not_fit_its_channel():
    err = broken(lambda d: d["nodes"]["sonar"]["data"]["fields"].__setitem__("extra", "u8[8]"))
    assert "nodes.sonar.data.fields.extra" in str(err) and "overflows the 32-byte channel" in str(err)


def test_command_arguments_that_do_not_fit():
    def mutate(d):
        d["nodes"]["motor"]["command"]["commands"]["MOVE_FORWARD"]["args"]["padding"] = "u8[14]"

    err = broken(mutate)
    assert "MOVE_FORWARD.args.padding" in str(err) and "overflows" in str(err)


def test_duplicate_ids():
    err = broken(lambda d: d["nodes"]["sonar"].__setitem__("id", 20))
    assert "nodes.sonar.id" in str(err) and "already used by node 'motor'" in str(err)


def test_duplicate_names_are_caught_as_duplicate_keys():
    text = TEXT.replace("  charger:\n    id: 80", "  motor:\n    id: 80")
    with pytest.raises(ProtocolError, match="duplicate key 'motor'"):
        parse_protocol(text, "dup.yaml")


def test_an_enum_name_yaml_reads_as_a_bool_is_refused():
    text = TEXT.replace('"OFF": 4', "OFF: 4")
    assert text != TEXT
    with pytest.raises(ProtocolError, match=r"enums\.motor_state\.False.*not text: quote it"):
        parse_protocol(text, "bare.yaml")


def test_duplicate_seed_names():
    err = broken(lambda d: d["nodes"]["map"].__setitem__("seed_name", "ROBSONAR"))
    assert "nodes.map.seed_name" in str(err) and "already used by 'sonar'" in str(err)


def test_duplicate_addresses():
    def mutate(d):
        d["nodes"]["lcd"]["data"]["address"] = d["nodes"]["map"]["data"]["address"]

    err = broken(mutate)
    assert "nodes.lcd.data" in str(err) and "overlaps map.data" in str(err)


def test_unknown_type():
    err = broken(lambda d: d["nodes"]["compass"]["data"]["fields"].__setitem__("heading_cdeg", "u12"))
    assert "nodes.compass.data.fields.heading_cdeg" in str(err) and "unknown type 'u12'" in str(err)


def test_typo_in_a_key_is_refused():
    err = broken(lambda d: d["nodes"]["map"]["data"].__setitem__("fileds", {}))
    assert "nodes.map.data" in str(err) and "unknown key(s) fileds" in str(err)


def test_duplicate_command_codes():
    def mutate(d):
        d["nodes"]["motor"]["command"]["commands"]["STOP"]["code"] = 1

    err = broken(mutate)
    assert "nodes.motor.command.commands.STOP" in str(err) and "already used by 'MOVE_FORWARD'" in str(err)


def test_header_field_missing():
    err = broken(lambda d: d["token"]["header"].pop("counter"))
    assert "token.header" in str(err) and "counter" in str(err)


def test_cli_refuses_a_broken_protocol_with_exit_code_2(tmp_path):
    bad = tmp_path / "protocol.yaml"
    sonar_data = load_protocol(REPO / "protocol.yaml").channel("sonar.data").address
    assert TEXT.count(f"address: {sonar_data}\n") == 1
    bad.write_text(TEXT.replace(f"address: {sonar_data}\n", "address: 600\n"))
    result = run_tokenring("up", "--protocol", str(bad), "--duration", "1", timeout=30)
    assert result.returncode == 2
    assert "nodes.sonar.data" in result.stderr and "past the token's last byte" in result.stderr
    assert "Traceback" not in result.stderr


def test_system_window_layouts_are_checked_against_the_32_byte_window():
    err = broken(lambda d: d["system"]["window"]["ARCNET_ERROR"]["request"].__setitem__("text", "str[31]"))
    assert "system.window.ARCNET_ERROR.request.text" in str(err) and "overflows the 32-byte channel" in str(
        err
    )
    err = broken(lambda d: d["system"]["window"].__setitem__("ARCNET_REBOOT", {"request": {"x": "u8"}}))
    assert "system.window.ARCNET_REBOOT" in str(err) and "not a system command" in str(err)
