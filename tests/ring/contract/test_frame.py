"""The token and its frame: CRC-16/ARC, header accessors, and rejection of malformed frames."""

from __future__ import annotations

import pytest

from tokenring.contract.frame import Token, crc16_arc, frame_problem
from tokenring.contract.protocol import default_protocol
from tokenring.errors import FrameError


def test_crc16_arc_check_value():
    assert crc16_arc(b"123456789") == 0xBB3D


def test_new_token_is_zero_but_for_the_markers():
    token = Token()
    frame = token.to_frame()
    assert len(frame) == 514
    assert frame[2] == 0 and frame[3] == 4
    assert not any(frame[4:512])
    assert frame[512] | frame[513] << 8 == crc16_arc(frame[:512])


def test_header_accessors_follow_the_protocol():
    token = Token()
    token.sid, token.did, token.counter = 10, 20, 200
    token["syscmd_issuer"] = 10
    assert token.header()["sid"] == 10 and token["did"] == 20
    back = Token.from_frame(token.to_frame())
    assert (back.sid, back.did, back.counter, back["syscmd_issuer"]) == (10, 20, 200, 10)


@pytest.mark.parametrize(
    ("mangle", "reason"),
    [
        (lambda f: f[:100], "length"),
        (lambda f: f + b"\0", "length"),
        (lambda f: f[:40] + bytes([f[40] ^ 0x10]) + f[41:], "crc"),
        (lambda f: f[:511] + bytes([f[511] ^ 1]) + f[512:], "crc"),
    ],
)
def test_malformed_frames_are_named(mangle, reason):
    frame = Token().to_frame()
    bad = mangle(frame)
    assert frame_problem(bad, default_protocol()) == reason
    with pytest.raises(FrameError) as info:
        Token.from_frame(bad)
    assert info.value.reason == reason


def test_wrong_markers_with_a_good_crc_are_refused():
    token = Token()
    token.buffer[3] = 5
    with pytest.raises(FrameError, match="markers"):
        Token.from_frame(token.to_frame())


def test_decode_names_every_channel():
    token = Token()
    sonar = token.protocol.channel("sonar.data")
    sonar.view(token.buffer)["distances"] = [10, 20, 30, 40, 50, 60, 70, 255]
    decoded = token.decode()
    assert decoded["channels"]["sonar.data"]["distances"][-1] == 255
    assert decoded["header"]["syscmd_code_name"] == "NONE"
    assert set(decoded["channels"]) == set(token.protocol.channels)
