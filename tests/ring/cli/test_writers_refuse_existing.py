"""Every verb that writes a file refuses an existing one unless ``--force`` (issue 52): exit 2,
one line naming the option the user gave, the file byte for byte as it was, and nothing started
or left beside it; with ``--force`` it is replaced through a temporary file and a rename."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

OLDER = b"an older file the user wants to keep\n"

#: (name, arguments, the option named in the refusal, the file to put there first: {out} or
#: {dir}/NAME, whether the verb runs offline with --force). {log}: a data log, {map}: a map.
WRITERS = [
    ("map", ["map", "--from", "{map}", "--out", "{out}.png"], "--out", "{out}.png", True),
    ("map-json", ["map", "--from", "{map}", "--out", "{out}.json"], "--out", "{out}.json", True),
    ("replay", ["replay", "{log}", "--out", "{out}"], "--out", "{out}", True),
    ("replay-errors", ["replay", "{log}", "--out", "{dir}/new.trlog", "--errors", "{out}"], "--errors", "{out}", True),
    ("log-convert", ["log", "convert", "{log}", "--out", "{out}"], "--out", "{out}", True),
    ("log-convert-seed", ["log", "convert", "{log}", "--to", "seed", "--out", "{out}"], "--out", "{out}", True),
    ("log-convert-mcap", ["log", "convert", "{log}", "--to", "mcap", "--out", "{out}"], "--out", "{out}", True),
    ("log-convert-csv", ["log", "convert", "{log}", "--to", "csv", "--out", "{dir}"], "--out", "{dir}/data.csv", True),
    ("log-convert-dat", ["log", "convert", "{log}", "--to", "dat", "--out", "{dir}"], "--out", "{dir}/sonar.dat", True),
    ("log-sort", ["log", "sort", "{log}", "--out", "{out}"], "--out", "{out}", True),
    ("analyze", ["analyze", "{log}", "--out", "{dir}"], "--out", "{dir}/paths.png", True),
    ("analyze-seed-out", ["analyze", "{log}", "--seed-out", "{dir}"], "--seed-out", "{dir}/logfile.cfg", True),
    ("world-generate", ["world", "generate", "--seed", "3", "--out", "{out}"], "--out", "{out}", True),
    ("world-drive", ["world", "drive", "--world", "office", "--seed", "3", "--out", "{out}"], "--out", "{out}", True),
    # verbs of a running ring: refused before anything starts or joins
    ("up-map-out", ["up", "--explore", "2", "--map-out", "{out}.json", "--duration", "5"], "--map-out", "{out}.json", False),
    ("up-record", ["up", "--record", "{out}", "--duration", "5"], "--record", "{out}", False),
    ("load-upload", ["load", "-u", "{out}.dxf"], "--upload", "{out}.dxf", False),
    ("record", ["record", "{out}", "--duration", "1"], "FILE", "{out}", False),
    ("sniff-write", ["sniff", "--write", "{out}", "-n", "1"], "--write", "{out}", False),
    ("sniff-write-pcapng", ["sniff", "--write", "{out}.pcapng", "-n", "1"], "--write", "{out}.pcapng", False),
    ("record-pcap", ["record", "--pcap", "{out}.pcapng", "--duration", "1"], "--pcap", "{out}.pcapng", False),
    ("record-mcap-pcap", ["record", "{dir}/new.mcap", "--pcap", "{out}.pcapng", "--duration", "1"], "--pcap", "{out}.pcapng", False),
    ("watch-record", ["watch", "--record", "{out}", "--duration", "1"], "--record", "{out}", False),
    ("watch-pcap", ["watch", "--pcap", "{out}.pcapng", "--duration", "1"], "--pcap", "{out}.pcapng", False),
    ("up-pcap", ["up", "--pcap", "{out}.pcapng", "--duration", "5"], "--pcap", "{out}.pcapng", False),
]  # fmt: skip
FORCED = [w for w in WRITERS if w[4]]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A short data log of a drive and a saved map, as the offline verbs read them."""
    from modules.localization.config import load_config
    from modules.localization.localizer import LocalizationCore
    from modules.localization.logs import DataLog
    from modules.pc.mapfiles import write_map
    from tests.support.locsim import drive, square_moves

    folder = tmp_path_factory.mktemp("inputs")
    config = load_config()
    core = LocalizationCore(config, data_log=DataLog(folder / "drive.trlog", "20240101-120000", config))
    for sample in drive(square_moves(1, 2000)[:1], seed=2, heading=lambda: core.ekf.pose[2]):
        core.feed(sample)
        core.maybe_sync()
    core.close()
    write_map(np.array([[0.0, 0.0, 1000.0, 0.0], [1000.0, 0.0, 1000.0, 800.0]]), str(folder / "map.json"))
    return {"log": folder / "drive.trlog", "map": folder / "map.json"}


def run(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, TOKENRING_ENDPOINT="tcp/127.0.0.1:9")  # no ring to find, ever
    return subprocess.run(
        [sys.executable, "-m", "tokenring", *args], capture_output=True, text=True, timeout=120, cwd=cwd, env=env
    )  # fmt: skip


def prepare(
    template: list[str], existing: str, inputs: dict[str, Path], work: Path
) -> tuple[list[str], Path]:
    """The command line and the existing output file (written with :data:`OLDER`)."""
    fill = {"log": inputs["log"], "map": inputs["map"], "out": work / "out", "dir": work / "plots"}
    (work / "plots").mkdir()
    target = Path(existing.format(**fill))
    target.write_bytes(OLDER)
    return [a.format(**fill) for a in template], target


def snapshot(folder: Path) -> dict[str, tuple[int, int, bytes]]:
    return {
        str(p.relative_to(folder)): (p.stat().st_mtime_ns, p.stat().st_size, p.read_bytes())
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


@pytest.mark.parametrize(
    ("name", "template", "option", "existing", "offline"), WRITERS, ids=[w[0] for w in WRITERS]
)
def test_an_existing_output_is_refused_without_force(
    name, template, option, existing, offline, inputs, tmp_path
):
    args, target = prepare(template, existing, inputs, tmp_path)
    before = snapshot(tmp_path)
    result = run(args, tmp_path)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, (result.returncode, result.stdout[-500:], result.stderr[-800:])
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert f"{option} {target}" in lines[0] and "exists" in lines[0] and "--force" in lines[0], lines[0]
    assert "starting" not in result.stdout, result.stdout  # refused before anything started
    assert snapshot(tmp_path) == before  # byte for byte, and nothing beside it


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "template", "option", "existing", "offline"), FORCED, ids=[w[0] for w in FORCED]
)
def test_with_force_it_is_replaced_whole(name, template, option, existing, offline, inputs, tmp_path):
    args, target = prepare(template, existing, inputs, tmp_path)
    result = run([*args, "--force"], tmp_path)
    assert result.returncode == 0, (result.stdout[-500:], result.stderr[-800:])
    assert "Traceback" not in result.stderr, result.stderr
    assert target.read_bytes() != OLDER and target.stat().st_size > 0
    temporary = [p.name for p in tmp_path.rglob(".*") if p.is_file()] + [
        p.name for p in tmp_path.rglob("*.part")
    ]
    assert temporary == [], temporary  # the temporary file was renamed, not left


def test_a_map_is_never_written_over_its_input(inputs, tmp_path):
    copy = tmp_path / "map.json"
    copy.write_bytes(inputs["map"].read_bytes())
    result = run(["map", "--from", str(copy), "--out", str(copy), "--force"], tmp_path)
    assert result.returncode == 2 and "is the input" in result.stderr, result.stderr
    assert copy.read_bytes() == inputs["map"].read_bytes()
