"""A full disk (a small tmpfs) costs only the file (issue 52). The offline tools: exit 2, one
line naming the file and why, no traceback, and the disk as it was (the older file given with
``--force`` intact, no temporary, ``.part`` or empty file). A run: the localisation goes on
without its log, ``--map-out`` keeps the older map, and the exit code says the run was not whole."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from tests.support.processes import run_tokenring
from tests.support.smalldisk import fill, listing, small_disk

OLDER = b"an older file, to be kept\n"
NO_SPACE = "No space left on device"

#: (name, arguments, the file there before: on the disk {disk}, the inputs {log} and {map})
OFFLINE = [
    ("log-convert", ["log", "convert", "{log}", "--out", "{disk}/drive.txt"], "{disk}/drive.txt"),
    ("log-convert-seed", ["log", "convert", "{log}", "--to", "seed", "--out", "{disk}/drive.log"], "{disk}/drive.log"),
    ("log-convert-csv", ["log", "convert", "{log}", "--to", "csv", "--out", "{disk}/csv"], "{disk}/csv/data.csv"),
    ("log-convert-mcap", ["log", "convert", "{log}", "--to", "mcap", "--out", "{disk}/d.mcap"], "{disk}/d.mcap"),
    ("log-sort", ["log", "sort", "{log}", "--out", "{disk}/sorted.trlog"], "{disk}/sorted.trlog"),
    ("replay", ["replay", "{log}", "--out", "{disk}/again.trlog"], "{disk}/again.trlog"),
    ("analyze", ["analyze", "{log}", "--out", "{disk}/plots"], "{disk}/plots/paths.png"),
    ("map-png", ["map", "--from", "{map}", "--out", "{disk}/m.png"], "{disk}/m.png"),
    ("map-dxf", ["map", "--from", "{map}", "--out", "{disk}/m.dxf"], "{disk}/m.dxf"),
    ("map-json", ["map", "--from", "{map}", "--out", "{disk}/m.json"], "{disk}/m.json"),
    ("world-generate", ["world", "generate", "--seed", "5", "--out", "{disk}/room.yaml"], "{disk}/room.yaml"),
    ("world-drive", ["world", "drive", "--world", "office", "--seed", "5", "--out", "{disk}/d.act"], "{disk}/d.act"),
]  # fmt: skip


@pytest.fixture(scope="module")
def inputs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    from modules.localization.config import load_config
    from modules.localization.localizer import LocalizationCore
    from modules.localization.logs import DataLog
    from modules.pc.mapfiles import write_map
    from tests.support.locsim import drive, square_moves

    folder = tmp_path_factory.mktemp("inputs")
    config = load_config()
    core = LocalizationCore(config, data_log=DataLog(folder / "drive.trlog", "20240101-120000", config))
    for sample in drive(square_moves(1, 2000)[:1], seed=3, heading=lambda: core.ekf.pose[2]):
        core.feed(sample)
        core.maybe_sync()
    core.close()
    rng = np.random.default_rng(1)
    write_map(rng.uniform(0, 5000, (200, 4)), str(folder / "map.json"))
    return {"log": folder / "drive.trlog", "map": folder / "map.json"}


def contents(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.slow
@pytest.mark.parametrize(("name", "template", "existing"), OFFLINE, ids=[w[0] for w in OFFLINE])
def test_an_offline_tool_on_a_full_disk_is_one_line_and_keeps_the_older_file(
    name, template, existing, inputs, tmp_path
):
    with small_disk(tmp_path / "disk", 64 * 1024) as disk:
        fill_in = {"log": inputs["log"], "map": inputs["map"], "disk": disk}
        target = Path(existing.format(**fill_in))
        target.parent.mkdir(exist_ok=True)
        target.write_bytes(OLDER)
        fill(disk)
        before = contents(disk)
        result = run_tokenring(*(a.format(**fill_in) for a in template), "--force", timeout=120)
        lines = result.stderr.strip().splitlines()
        assert result.returncode == 2, (result.returncode, result.stdout[-500:], result.stderr[-800:])
        assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
        assert (
            NO_SPACE in lines[0] and str(target.parent if name == "log-convert-csv" else target) in lines[0]
        )
        assert contents(disk) == before, listing(disk)  # the older file as it was, nothing beside it


@pytest.mark.slow
def test_a_full_disk_under_the_localisation_log_costs_only_the_log(ring_name, endpoint, tmp_path):
    """The robot stands with the Darmstadt setup and its logs on a tiny disk: each log says once
    that it ends, whole; nothing raises, the localisation never falls back to dead reckoning,
    the ring runs its time, and the run ends with exit code 1 (not whole), saying so."""
    with small_disk(tmp_path / "disk", 32 * 1024) as disk:
        env = dict(os.environ, TOKENRING_LOG_DIR=str(disk))
        result = subprocess.run(
            [sys.executable, "-m", "tokenring", "up", "--ring", ring_name, "--listen", endpoint,
             "--localizer", "config/localization.yaml", "--speed", "5", "--duration", "12"],
            capture_output=True, text=True, timeout=240, env=env, cwd=Path(__file__).resolve().parents[3],
        )  # fmt: skip
        out = result.stdout
        assert result.returncode == 1, (result.returncode, out[-3000:], result.stderr[-2000:])
        assert "Traceback" not in out + result.stderr, out[-3000:]
        lost = [line for line in out.splitlines() if "cannot write" in line]
        assert lost and all(line.split("|")[0].strip() == "copro" and NO_SPACE in line for line in lost), lost
        assert len(lost) == len({line.split(": cannot write")[0].split()[-1] for line in lost}) <= 2, lost
        assert all("the localisation goes on without it" in line for line in lost), lost
        assert "back to dead reckoning" not in out and "localizer unavailable" not in out, out[-3000:]
        assert any("this run is not whole" in line for line in out.splitlines()), out[-3000:]
        from modules.localization.logs import read_log

        for name in listing(disk):  # what each log kept is whole: no damage, no torn tail
            log = read_log(disk / name)
            assert log.records and not log.truncated and not log.damaged, name


@pytest.mark.slow
def test_map_out_onto_a_full_disk_exits_1_and_keeps_the_older_map(ring_name, endpoint, tmp_path):
    with small_disk(tmp_path / "disk", 64 * 1024) as disk:
        target = disk / "office.png"
        target.write_bytes(OLDER)
        fill(disk)
        result = run_tokenring(
            "up", "--ring", ring_name, "--listen", endpoint, "--explore", "2", "--speed", "10",
            "--bitrate", "max", "--duration", "10", "--map-out", str(target), "--force",
            timeout=300,
        )  # fmt: skip
        out = result.stdout
        assert result.returncode == 1, (result.returncode, out[-3000:], result.stderr[-2000:])
        assert "Traceback" not in out + result.stderr, out[-3000:]
        failed = [line for line in out.splitlines() if "cannot write" in line]
        assert len(failed) == 1 and f"--map-out {target}: cannot write: {NO_SPACE}" in failed[0], failed
        assert target.read_bytes() == OLDER and listing(disk) == ["office.png"]


def test_a_map_out_the_ring_stopped_before_is_a_failure(monkeypatch):
    """``up --map-out`` whose map was never written (the ring stopped first: its duration, a
    signal, every node gone) does not end with exit code 0: the mission names --map-out."""
    from modules.pc.mission import Mission

    said: list[str] = []
    launcher = SimpleNamespace(
        stopping=True, say=lambda text, name="": said.append(text), request_stop=lambda: None
    )
    mission = Mission(launcher, 2, "m.png", 30.0)
    monkeypatch.setattr(mission, "_mission", lambda: None)  # the ring stopped before the map was fetched
    mission.start()
    text = "--map-out m.png: no map written (the ring stopped before it was fetched)"
    assert mission.failure() == text and said == [text]
