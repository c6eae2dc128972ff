"""Texts in the system commands' fixed fields (a 31-byte answer detail, GET_STATUS's 29-byte
error) are cut cleanly, at a word or at least a character, ending in ``...``; the whole text
reaches main in an ARCNET_ERROR report (up to 240 bytes), so ``load`` prints it in full."""

from __future__ import annotations

import errno

import pytest

from tests.support.memring import MemoryRing, wait_for
from tokenring.node.store import ProgramStore
from tokenring.node.system.layer import SystemLayer
from tokenring.node.system.vocabulary import SystemCommandError, _clipped, _short

PROGRAM = b"""
from tokenring import UserProgram


class Program(UserProgram):
    module = "motor"
"""
MISSING = "/var/lib/tokenring/a/store/that/is/gone/motor.py"


class GoneStore(ProgramStore):
    """A store whose folder went away under the node: every save fails as the kernel says."""

    def save(self, source: bytes, digest: bytes, stamp_ms: int) -> str:
        raise FileNotFoundError(errno.ENOENT, "No such file or directory", MISSING)


@pytest.mark.parametrize(
    ("text", "size", "clipped"),
    [
        ("no program installed", 31, "no program installed"),
        ("store: No such file or directory", 31, "store: No such file or..."),
        ("store: No such file or directory", 29, "store: No such file or..."),
        ("ZeroDivisionError: division by zero", 29, "ZeroDivisionError..."),
        ("x" * 40, 29, "x" * 26 + "..."),
        ("Größenüberschreitung" * 2, 29, None),  # checked below: whole characters only
    ],
)
def test_a_text_too_long_for_its_field_ends_at_a_word_with_an_ellipsis(text, size, clipped):
    raw = _clipped(text, size)
    assert len(raw) <= size
    decoded = raw.decode("utf-8")  # never half a character
    if clipped is not None:
        assert decoded == clipped
    else:
        assert decoded.endswith("...") and text.startswith(decoded[:-3])


def test_a_name_is_cut_at_a_character():
    assert _short("überlänge", 4).decode("utf-8") == "übe"
    assert _short("lcd", 10) == b"lcd"


def test_a_store_error_is_clipped_in_the_answer_and_whole_in_the_report(tmp_path):
    ring = MemoryRing([10, 20], bitrate=None)
    layers = {
        10: SystemLayer(ring.nodes[10], store=ProgramStore(tmp_path / "main", "main")).install(),
        20: SystemLayer(ring.nodes[20], store=GoneStore(tmp_path / "motor", "motor")).install(),
    }
    try:
        ring.wait_rounds(10)
        main = layers[10]
        with pytest.raises(SystemCommandError) as failure:
            main.execute(main.download_steps(20, PROGRAM, 1000, start=False), "download to 20", 10.0)
        assert str(failure.value).endswith("STORE_ERROR: store: No such file or...")
        wait_for(lambda: main.errors, 5, "motor's ARCNET_ERROR at main")
        assert main.errors[-1]["name"] == "motor"
        assert main.errors[-1]["text"] == (
            f"cannot store the program: [Errno 2] No such file or directory: '{MISSING}'"
        )
    finally:
        for layer in layers.values():
            layer.close()
        ring.close()
