"""The localisation's live state and its MessageHandler (seed 000 §6.6, §6.8.3), without a ring:
a core fed a simulated drive's samples, its snapshot checked against what was fed and against the
core's own position store, and its messages kept for a screen that opens later."""

from __future__ import annotations

import json
import math
from typing import Any

import msgpack
import pytest

from modules.localization.config import load_config
from modules.localization.liveview import SyncPeriods, plain, snapshot
from modules.localization.localizer import LocalizationCore
from modules.localization.logs import DataLog, ErrorLog, read_log
from modules.localization.sync import Sample
from tests.support.locsim import drive

DRIVE = [("s", 600.0), ("r", 90.0), ("s", 200.0)]


def fed_core(
    config: dict[str, Any] | None = None, **kwargs: Any
) -> tuple[LocalizationCore, SyncPeriods, dict]:
    """A core fed a short drive (its sync watched as copro watches it), and the last sample of
    every sensor fed."""
    core = LocalizationCore(load_config(config), **kwargs)
    periods = SyncPeriods()
    last: dict[str, Sample] = {}
    for sample in drive(DRIVE, seed=4):
        core.feed(sample)
        last[sample.sensor] = sample
        core.maybe_sync()
        periods.observe(core)
    return core, periods, last


# --------------------------------------------------------------------------------------------
# the MessageHandler


def test_messages_before_anyone_listens_are_kept_and_later_ones_told_as_they_come() -> None:
    core = LocalizationCore(load_config())
    (started,) = core.messages  # said while the core was built: no screen was open yet
    assert started["n"] == 0 and started["class"] == "I" and started["stamp_ms"] == 0
    assert started["text"].startswith("localisation started: sensors odometry, compass")
    heard: list[dict[str, Any]] = []
    core.message_listeners.append(heard.append)
    core.message("W", 1200, "compass rejected by the gate (NIS 14.2)")
    assert heard == [
        {"n": 1, "class": "W", "stamp_ms": 1200, "text": "compass rejected by the gate (NIS 14.2)"}
    ]
    assert list(core.messages) == [started, heard[0]] and core.messages_said == 2


def test_the_backlog_keeps_the_newest_thousand_and_debug_only_when_logged() -> None:
    core = LocalizationCore(load_config())
    for i in range(1, 1200):
        core.message("E", i, f"message {i}")
    core.message("D", 5000, "not kept: logs.debug is off")
    assert len(core.messages) == 1000 and core.messages_said == 1200
    assert [m["n"] for m in core.messages] == list(range(200, 1200))
    assert core.messages[-1]["text"] == "message 1199"
    debugging = LocalizationCore(load_config({"logs": {"debug": True}}))
    debugging.message("D", 7, "kept")
    assert debugging.messages[-1] == {"n": 1, "class": "D", "stamp_ms": 7, "text": "kept"}


def test_a_failing_listener_neither_stops_the_others_nor_the_error_log(tmp_path) -> None:
    errors = ErrorLog(tmp_path / "run.trerr", "start")
    core = LocalizationCore(load_config(), error_log=errors)
    heard: list[str] = []

    def broken(entry: dict[str, Any]) -> None:
        raise RuntimeError("the screen fell over")

    core.message_listeners += [broken, lambda entry: heard.append(entry["text"])]
    core.message("E", 300, "odometry: 2 samples missed")
    errors.close()
    assert heard == ["odometry: 2 samples missed"]
    texts = [record[2] for record in read_log(tmp_path / "run.trerr").records]
    assert texts[0].startswith("localisation started") and texts[1] == "odometry: 2 samples missed"


# --------------------------------------------------------------------------------------------
# the snapshot


def test_the_snapshot_is_what_was_fed_and_what_the_store_holds() -> None:
    core, periods, last = fed_core()
    shot = snapshot(core, periods)
    assert json.loads(json.dumps(shot, allow_nan=False)) == shot  # plain JSON values only
    assert msgpack.unpackb(msgpack.packb(shot), raw=False) == shot
    assert len(msgpack.packb(shot)) < 4096  # small: published five times a second

    # every configured sensor with its newest raw sample, by field name
    assert list(shot["sensors"]) == list(core.sensors)
    odometry = shot["sensors"]["odometry"]
    assert odometry["values"] == last["odometry"].values and odometry["stamp_ms"] == last["odometry"].stamp_ms
    assert odometry["values"]["steps_left"] != 0  # the drive moved the counters
    compass = shot["sensors"]["compass"]
    assert compass["seq"] == last["compass"].seq and compass["values"] == last["compass"].values
    assert compass["samples"] == core.timing["compass"].samples > 100
    assert compass["missed"] == 0  # numbered samples: a gap would be counted
    assert shot["sensors"]["sonar"]["values"]["distances"] == last["sonar"].values["distances"]
    assert shot["sensors"]["truth"]["missed"] is None  # no numbers, no period: not known
    battery = shot["sensors"]["battery"]  # configured, never heard from
    assert battery["values"] is None and battery["stamp_ms"] is None and battery["samples"] == 0

    # the synchronisation: the default period trigger, 100 ms of odometry time apart
    sync = shot["sync"]
    assert sync["mode"] == "period" and sync["sensor"] == "odometry" and sync["period_ms"] == 100
    assert sync["count"] is None and sync["syncs"] == core.syncs > 50
    assert sync["last_sync_ms"] == core.last_sync_ms == shot["stamp_ms"]
    assert sync["last_period_ms"] == 100.0 and sync["mean_period_ms"] == 100.0

    # the position store, with table B.7's validity bits
    positions = shot["positions"]
    assert {"odometry", "compass", "truth", "filter"} <= set(positions)
    for name, letter in (("odometry", "O"), ("compass", "M"), ("truth", "T"), ("filter", "K")):
        stored, shown = core.positions[letter], positions[name]
        assert shown["letter"] == letter and shown["stamp_ms"] == stored["stamp_ms"] == core.last_sync_ms
        assert (shown["x_mm"], shown["y_mm"], shown["heading_rad"]) == (
            stored["x"],
            stored["y"],
            stored["psi"],
        )
        assert [shown["x_valid"], shown["y_valid"], shown["heading_valid"]] == stored["valid"]
    assert [positions["compass"][k] for k in ("x_valid", "y_valid", "heading_valid")] == [False, False, True]
    assert positions["truth"]["x_mm"] == pytest.approx(last["truth"].values["x"], abs=30)

    # the filter's pose and its standard deviations
    assert core.ekf is not None
    filt = shot["filter"]
    assert filt["source"] == "ekf" and (filt["x_mm"], filt["y_mm"], filt["heading_rad"]) == core.ekf.pose
    sx, sy, spsi = core.ekf.sigmas()
    assert filt["sigma"] == {"x_mm": sx, "y_mm": sy, "heading_rad": spsi}
    assert filt["x_valid"] and filt["y_valid"] and filt["heading_valid"]
    assert shot["logs"] == {"data": None, "errors": None, "failure": None}
    assert shot["message_count"] == core.messages_said >= 1


def test_the_snapshot_names_the_log_files_and_the_seeds_count_trigger(tmp_path) -> None:
    config = load_config({"sync": {"trigger": {"mode": "count", "count": 2}}})
    data = DataLog(tmp_path / "run.trlog", "start", config)
    errors = ErrorLog(tmp_path / "run.trerr", "start")
    core = LocalizationCore(config, data_log=data, error_log=errors)
    shot = snapshot(core)  # nothing fed yet, periods not watched
    data.close()
    errors.close()
    assert shot["logs"] == {
        "data": str(tmp_path / "run.trlog"),
        "errors": str(tmp_path / "run.trerr"),
        "failure": None,
    }
    sync = shot["sync"]
    assert sync["mode"] == "count" and sync["count"] == 2 and sync["period_ms"] is None
    assert sync["syncs"] == 0 and sync["last_sync_ms"] is None and sync["last_period_ms"] is None
    assert shot["stamp_ms"] is None and shot["positions"] == {}
    assert all(s["values"] is None for s in shot["sensors"].values())
    assert shot["filter"]["source"] in ("ekf", "none")  # the wall file's start pose, or none yet


def test_sync_periods_from_outside_the_core() -> None:
    class Core:
        syncs, last_sync_ms = 0, None

    core, periods = Core(), SyncPeriods()
    periods.observe(core)  # type: ignore[arg-type]
    assert periods.last_period_ms is None and periods.mean_period_ms is None
    for syncs, stamp in ((1, 1000), (1, 1000), (2, 1100), (5, 1400), (6, 1600)):
        core.syncs, core.last_sync_ms = syncs, stamp
        periods.observe(core)  # type: ignore[arg-type]
    # the last step caught up by one; the one before by three at 100 ms each
    assert periods.last_period_ms == 200.0
    assert periods.mean_period_ms == (1600 - 1000) / 5


def test_plain_values_only() -> None:
    import numpy as np

    value = {"a": math.nan, "b": (1, 2.5, math.inf), 3: np.float64(0.25), "c": object}
    assert plain(value) == {"a": None, "b": [1, 2.5, None], "3": 0.25, "c": str(object)}
