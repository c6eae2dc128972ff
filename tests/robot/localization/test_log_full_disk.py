"""A full disk costs the localisation only its log (issue 52): the writer cuts the file back to
its last whole record, says so once, never appends after a torn record (not even once there is
room again), and the localisation goes on exactly as it would without a log."""

from __future__ import annotations

import errno
import logging
import os
from pathlib import Path
from types import SimpleNamespace

import msgpack
import pytest

from modules.localization import logs
from modules.localization.config import load_config
from modules.localization.localizer import LocalizationCore, Localizer
from modules.localization.logs import DataLog, ErrorLog, read_log
from tests.support.locsim import drive, square_moves
from tests.support.smalldisk import fill, listing, small_disk


def record(i: int) -> list:
    return [i, "O", "R", {"gen": 0, "n": i, "v": {"steps_left": i, "steps_right": -i}}]


class FullAfter:
    """``os.write`` for one file that takes ``whole`` writes, then half of the next one (a torn
    record), then fails with ENOSPC; ``room_again`` makes every later write succeed."""

    def __init__(self, path: Path, whole: int) -> None:
        self.path = str(path)
        self.whole = whole
        self.calls = 0
        self.after_failure = 0
        self.failed = False
        self.room_again = False
        self.real = os.write

    def __call__(self, fd: int, data: bytes) -> int:
        if os.readlink(f"/proc/self/fd/{fd}") != self.path:
            return self.real(fd, data)
        if self.failed:
            self.after_failure += 1
        if self.room_again:
            return self.real(fd, data)
        self.calls += 1
        if self.calls <= self.whole:
            return self.real(fd, data)
        if self.calls == self.whole + 1 and len(data) > 1:
            return self.real(fd, bytes(data)[: len(data) // 2])
        self.failed = True
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def test_a_torn_record_is_cut_off_and_nothing_is_written_after_it(tmp_path, monkeypatch) -> None:
    path = tmp_path / "full.trlog"
    disk = FullAfter(path, whole=6)  # the header and five records
    monkeypatch.setattr(logs.os, "write", disk)
    told: list[str] = []
    log = DataLog(path, "start", {}, on_failure=told.append)
    for i in range(20):
        log.write(i, *record(i)[1:])
    disk.room_again = True  # space comes back: the writer must stay ended
    for i in range(20, 30):
        log.write(i, *record(i)[1:])
    log.close()

    assert disk.failed and disk.after_failure == 0, "a write came after the failure"
    packer = msgpack.Packer(use_bin_type=True)
    header = {
        "tokenring_log": "data",
        "version": logs.FORMAT_VERSION,
        "start": "start",
        "config": {},
        "meta": {},
    }
    assert path.read_bytes() == packer.pack(header) + b"".join(packer.pack(record(i)) for i in range(5))
    back = read_log(path)  # without --salvage: no damage inside, no torn tail
    assert [r[0] for r in back.records] == [0, 1, 2, 3, 4] and not back.truncated and not back.damaged
    assert told == [
        f"{path}: cannot write: No space left on device; it ends at its last whole record (5 records)"
    ]
    assert log.failure == told[0]


def test_without_a_listener_the_error_is_raised_after_the_cut(tmp_path, monkeypatch) -> None:
    """A tool writing a log to a temporary file (replay, sort) gets the OSError itself."""
    path = tmp_path / "offline.trlog"
    monkeypatch.setattr(logs.os, "write", FullAfter(path, whole=3))
    log = ErrorLog(path, "start")
    log.message("I", 1, "one")
    log.message("I", 2, "two")
    with pytest.raises(OSError) as raised:
        log.message("W", 3, "three, torn")
    assert raised.value.errno == errno.ENOSPC
    log.message("W", 4, "four, never written")
    assert [r[2] for r in read_log(path).records] == ["one", "two"]


def test_a_header_that_does_not_fit_leaves_no_file(tmp_path, monkeypatch) -> None:
    path = tmp_path / "none.trlog"
    monkeypatch.setattr(logs.os, "write", FullAfter(path, whole=0))
    told: list[str] = []
    log = DataLog(path, "start", {"big": "x" * 1000}, on_failure=told.append)
    log.write(1, *record(1)[1:])
    assert not path.exists()
    assert told == [f"{path}: cannot write: No space left on device; no log kept"]


def final_pose(config: dict, data_log: DataLog | None, error_log: ErrorLog | None) -> tuple[float, ...]:
    core = LocalizationCore(config, data_log=data_log, error_log=error_log)
    for sample in drive(square_moves(1, 3000)[:2], seed=5, heading=lambda: core.ekf.pose[2]):
        core.feed(sample)
        core.maybe_sync()
    core.close()
    assert core.syncs > 100
    return (*core.ekf.pose, core.syncs)


def test_on_a_full_disk_the_localisation_goes_on_as_without_a_log(tmp_path) -> None:
    """A real full disk (a tmpfs of a few pages): the filter's pose at the end is the one of
    the same drive without any log, and each log is a readable prefix of what it should hold."""
    config = load_config()
    without = final_pose(config, None, None)
    told: list[str] = []
    with small_disk(tmp_path / "disk", 64 * 1024) as disk:
        fill(disk, leave=16 * 1024)
        data = DataLog(disk / "drive.trlog", "start", config, on_failure=told.append)
        errors = ErrorLog(disk / "drive.trerr", "start", on_failure=told.append)
        assert final_pose(config, data, errors) == without
        assert len(told) == 1 and str(disk / "drive.trlog") in told[0], told
        assert "No space left on device" in told[0]
        log = read_log(disk / "drive.trlog")
        assert log.records and not log.truncated and not log.damaged
        assert read_log(disk / "drive.trerr").records  # the error log still had room
        assert listing(disk) == ["drive.trerr", "drive.trlog"]


def test_the_localizer_says_it_in_one_line_and_tells_its_host(tmp_path, caplog) -> None:
    """Copro's component: one ERROR line per log naming the file, and ``on_log_failure`` (which
    tells ``tokenring up`` that the run is not whole) once per log."""
    config = load_config()
    config["logs"] = {**config["logs"], "enabled": True}
    node = SimpleNamespace(name="copro", subscribe=lambda channel: SimpleNamespace(published=False))
    told: list[str] = []
    with small_disk(tmp_path / "disk", 64 * 1024) as disk:
        fill(disk, leave=8 * 1024)
        localizer = Localizer(node, config, log_dir=disk, on_log_failure=told.append)
        caplog.set_level(logging.ERROR, logger="tokenring.localization")
        localizer.setup()
        core = localizer.core
        assert core is not None
        for sample in drive(square_moves(1, 3000)[:1], seed=5, heading=lambda: core.ekf.pose[2]):
            core.feed(sample)
            core.maybe_sync()
        localizer.close()
        lines = [r.getMessage() for r in caplog.records if r.name == "tokenring.localization"]
        assert lines and len(lines) == len(told) <= 2, lines
        assert all("cannot write: No space left on device" in line for line in lines)
        assert all(line.endswith("the localisation goes on without it") for line in lines)
        assert localizer.log_failures == told and core.syncs > 50
