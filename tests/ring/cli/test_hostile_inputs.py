"""Hostile and careless input files, table-driven: every verb that reads a file refuses a bad one
with exit code 2 and one line on stderr naming it, no traceback, no hang, nothing changed, and
before it starts anything (issue 19)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.support.processes import REPO

#: (name, arguments with {f} for the file) of every verb option that reads a file
READERS = [
    ("protocol", ["up", "--protocol", "{f}", "--duration", "1"]),
    ("world", ["up", "--world", "{f}", "--duration", "1"]),
    ("actions", ["up", "--actions", "{f}", "--duration", "1"]),
    ("localizer", ["up", "--localizer", "{f}", "--duration", "1"]),
    ("scenario", ["chaos", "{f}"]),
    ("program", ["load", "-s", "{f}"]),
    ("map", ["score", "{f}", "--world", "office"]),
    ("map-from", ["map", "--from", "{f}", "--out", "{out}"]),
    ("sniff-protocol", ["sniff", "--protocol", "{f}", "-n", "1"]),
    ("sniff-read", ["sniff", "--read", "{f}"]),
    ("dissector-protocol", ["dissector", "--protocol", "{f}"]),
]


def make(kind: str, directory: Path) -> Path:
    """A hostile file of ``kind`` in ``directory``."""
    path = directory / f"{kind}.yaml"
    if kind == "binary":
        path.write_bytes(b"\xff\xfe\x00\x01 not text \x80\x81")
    elif kind == "empty":
        path.write_bytes(b"")
    elif kind == "huge":
        with path.open("wb") as out:  # sparse: 200 MB on paper, nothing on disk
            out.truncate(200 * 1024 * 1024)
    elif kind == "fifo":
        os.mkfifo(path)
    elif kind == "directory":
        path.mkdir()
    elif kind == "missing":
        pass
    elif kind == "device":
        return Path("/dev/zero")
    return path


KINDS = ["binary", "empty", "huge", "fifo", "directory", "missing", "device"]
#: combinations that are valid input by design, with the reason
DOCUMENTED = {("localizer", "empty"): "an empty localisation configuration means its defaults"}
CASES = [(r, t, k) for r, t in READERS for k in KINDS if (r, k) not in DOCUMENTED]


def fingerprint(path: Path) -> tuple | None:
    try:
        info = path.lstat()
    except FileNotFoundError:
        return None
    content = path.read_bytes()[:4096] if path.is_file() and info.st_size < 1 << 20 else b""
    return (info.st_mode, info.st_size, info.st_mtime_ns, content)


@pytest.mark.slow
@pytest.mark.parametrize(("reader", "template", "kind"), CASES, ids=[f"{r}-{k}" for r, _, k in CASES])
def test_a_bad_file_is_one_clear_line_and_exit_2(reader, template, kind, tmp_path):
    file = make(kind, tmp_path)
    out = tmp_path / "out.json"
    before = fingerprint(file)
    args = [a.format(f=file, out=out) for a in template]
    env = dict(os.environ, TOKENRING_ENDPOINT="tcp/127.0.0.1:9")  # no ring to find, ever
    result = subprocess.run(
        [sys.executable, "-m", "tokenring", *args],
        capture_output=True, text=True, timeout=60, cwd=REPO, env=env,
    )  # fmt: skip
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, (result.returncode, result.stdout[-500:], result.stderr[-800:])
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert file.name in lines[0] or str(file) in lines[0], lines[0]
    assert "starting" not in result.stdout, result.stdout  # refused before anything started
    assert fingerprint(file) == before
    assert not out.exists()
