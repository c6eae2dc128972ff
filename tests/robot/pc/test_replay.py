"""Offline replay reproduces the online positions bit for bit (from raw and from synchronised data)."""

from __future__ import annotations

import math

import pytest

from modules.localization.config import load_config
from modules.localization.localizer import LocalizationCore
from modules.localization.logs import DataLog, ErrorLog, LogError, read_log
from modules.pc.replay import replay
from tests.support.locsim import drive, square_moves
from tokenring.cli.main import main as cli_main


@pytest.fixture(scope="module")
def online_log(tmp_path_factory: pytest.TempPathFactory):
    """One online run: half a lap of the square with the default config, its logs and core."""
    directory = tmp_path_factory.mktemp("online")
    config = load_config()
    data = DataLog(directory / "run.trlog", "test", config)
    errors = ErrorLog(directory / "run.trerr", "test")
    core = LocalizationCore(config, data_log=data, error_log=errors)
    moves = square_moves(1, 3000)[:3]
    truth = None
    for i, sample in enumerate(drive(moves, seed=5, heading=lambda: core.ekf.pose[2])):
        core.feed(sample)
        core.maybe_sync()
        truth = sample.values if sample.sensor == "truth" else truth
        if i == 500:  # the operator sets the pose (SET_GLOBAL_POSITION): an event the replay must repeat
            core.event(
                "set_pose", x=truth["x"], y=truth["y"], psi=truth["theta"], sigma_mm=5.0, sigma_deg=0.5
            )
    core.close()
    return directory / "run.trlog", core


@pytest.mark.slow
def test_replay_from_raw_data_is_bit_identical(online_log, tmp_path) -> None:
    path, core = online_log
    result = replay(path, tmp_path / "again.trlog", mode="raw")
    assert result.identical, result.first_difference
    assert result.compared > 1000 and result.syncs == core.syncs
    # the positions are the same floats, not just close: compare the last filter record
    last = [r for r in read_log(tmp_path / "again.trlog").records if r[1] == "K" and r[2] == "P"][-1]
    assert last[3]["x"] == core.positions["K"]["x"] and last[3]["psi"] == core.positions["K"]["psi"]


def test_replay_from_synchronised_data_is_bit_identical(online_log, tmp_path) -> None:
    path, _ = online_log
    result = replay(path, tmp_path / "sync.trlog", mode="sync")
    assert result.identical, result.first_difference


@pytest.mark.slow
def test_a_log_from_before_the_floor_fields_replays_as_identical(online_log, tmp_path) -> None:
    """Logs written before the filter positions carried the floor's mean and σ still --check
    equal on every field they have; a changed value in one of them is still found."""
    path, _ = online_log
    original = read_log(path)

    def rewrite(target, change):
        log = DataLog(target, "test", original.header["config"], original.header.get("meta"))
        for stamp, source, kind, payload in original.records:
            if source == "K" and kind == "P":
                payload = change({k: v for k, v in payload.items() if not k.startswith("step_scale_mean")})
            log.write(stamp, source, kind, payload)
        log.close()
        return target

    older = rewrite(tmp_path / "older.trlog", lambda p: p)
    assert replay(older, tmp_path / "older-again.trlog", mode="sync").identical
    tampered = rewrite(tmp_path / "tampered.trlog", lambda p: {**p, "step_scale": p["step_scale"] + 1e-9})
    result = replay(tampered, tmp_path / "tampered-again.trlog", mode="sync")
    assert not result.identical and "K P" in (result.first_difference or "")


@pytest.mark.slow
def test_replay_with_other_settings_differs_and_retrigger_runs(online_log, tmp_path) -> None:
    path, core = online_log
    config = load_config({"filter": {"compass": {"sigma_deg": 3.0}, "estimate": ["glide", "step_scale"]}})
    other = replay(path, tmp_path / "straight.trlog", config, mode="sync")
    assert not other.identical
    truth = core.positions["T"]
    replayed = [r for r in read_log(tmp_path / "straight.trlog").records if r[1] == "K" and r[2] == "P"][-1][
        3
    ]
    assert math.hypot(replayed["x"] - truth["x"], replayed["y"] - truth["y"]) < 100.0
    every_third = load_config({"sync": {"trigger": {"sensor": "odometry", "count": 3}}})
    fewer = replay(path, tmp_path / "retrigger.trlog", every_third, mode="retrigger")
    assert 0 < fewer.syncs < core.syncs / 2


def test_replay_refuses_to_overwrite_and_bad_logs(online_log, tmp_path) -> None:
    path, _ = online_log
    with pytest.raises(LogError, match="new log"):
        replay(path, path)
    (tmp_path / "junk.trlog").write_bytes(b"\xc1\xc1 not msgpack")
    with pytest.raises(LogError, match="not a tokenring log"):
        replay(tmp_path / "junk.trlog", tmp_path / "out.trlog")
    with pytest.raises(LogError, match="errors log, not a data log"):
        replay(path.with_suffix(".trerr"), tmp_path / "out.trlog")


@pytest.mark.slow
def test_replay_command_line(online_log, tmp_path, capsys) -> None:
    path, _ = online_log
    code = cli_main(["replay", str(path), "--out", str(tmp_path / "cli.trlog"), "--check"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "identical" in out
    assert cli_main(["replay", str(tmp_path / "missing.trlog"), "--out", str(tmp_path / "x.trlog")]) == 2
    assert "no such log file" in capsys.readouterr().err
