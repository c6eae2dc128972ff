"""A sensor is one file (issue 53, item 6; seed 000, chapter 7 made good).

A made-up fourth Darmstadt sensor — a thermometer, letter ``H`` — is described and registered
here and nowhere else: the Localizer reads it from its data channel, synchronises it, logs its
``R`` and ``C`` records, fuses it through its own hook; the readers take its records, the
converters write its lines and columns, the analyser its summary entry and plot, and a replay
reproduces the run — with no other file edited. And the built-in eight keep their order.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from modules.localization import logs
from modules.localization.config import ConfigError, load_config
from modules.localization.localizer import LocalizationCore, Localizer
from modules.localization.logs import (
    DataLog,
    convert_csv,
    convert_seed_dat,
    convert_seed_text,
    convert_text,
    read_log,
)
from modules.localization.records import fields, integer, num, number
from modules.localization.sensors import (
    Analysis,
    Fail,
    Sensor,
    SyncContext,
    names,
    register,
    sensor_of_letter,
    sensor_settings,
    unregister,
)
from modules.localization.sync import Sample
from modules.pc.analysis import analyse, plots
from modules.pc.logmcap import log_topics
from modules.pc.replay import replay
from tests.support.locsim import drive

FUSED: list[tuple[int, float]] = []


class MeanTemperature:
    """The mean of the readings since the last synchronisation, less the configured offset."""

    def __init__(self, offset_mc: int) -> None:
        self.offset_mc = offset_mc

    def synchronise(self, samples: list[Sample], sync_ms: int) -> dict[str, Any] | None:
        if not samples:
            return None
        mean = sum(s.values["temp_mc"] for s in samples) / len(samples)
        return {"celsius": (mean - self.offset_mc) / 1000.0, "count": len(samples)}


def _synchroniser(context: SyncContext) -> MeanTemperature:
    return MeanTemperature(context.config["sensors"]["thermometer"]["offset_mc"])


def _check(config: dict[str, Any], fail: Fail) -> None:
    if abs(config["sensors"]["thermometer"]["offset_mc"]) > 10_000:
        raise fail(("sensors", "thermometer", "offset_mc"), "more than 10 °C off is a broken sensor")


def _text(kind: str, v: dict[str, Any]) -> str:
    return f"{v['temp_mc']:>6}" if kind == "R" else f"{num(v['celsius'], 7, 2)} {v['count']}"


def _collect(records: list[tuple[int, str, dict[str, Any]]]) -> list[float] | None:
    return [p["celsius"] for _, kind, p in records if kind == "C"] or None


def _summary(data: list[float]) -> dict[str, Any]:
    return {"syncs": len(data), "mean_c": sum(data) / len(data)}


def _plot(data: list[float], ax: Any, t0: float) -> None:
    ax.plot(range(len(data)), data)
    ax.set_title("thermometer")


THERMOMETER = Sensor(
    name="thermometer",
    letter="H",
    title="thermometer",
    rank=75,
    synchroniser=_synchroniser,
    channel="thermometer.data",
    seq_field="reading",
    value_fields=("temp_mc",),
    settings=sensor_settings(use=True, filter=True, offset_mc=0),
    check_settings=_check,
    raw=fields(temp_mc=integer),
    synchronised=fields(celsius=number, count=integer),
    text=_text,
    dat=lambda p: f"{0:7d}" if p is None else f"{p['celsius']:7.2f}",
    csv_columns=("celsius",),
    csv=lambda p: {"celsius": p["celsius"]},
    analysis=Analysis(_collect, _summary, _plot, "thermometer.png"),
    fuse=lambda core, record, stamp: FUSED.append((stamp, record["celsius"])),
)


@pytest.fixture
def thermometer() -> Iterator[Sensor]:
    FUSED.clear()
    register(THERMOMETER)
    try:
        yield THERMOMETER
    finally:
        unregister("thermometer")


def with_thermometer(samples: Iterator[Sample]) -> Iterator[Sample]:
    """The drive's samples and a reading 5 ms after every truth sample (21.000 °C and rising)."""
    reading = 0
    for sample in samples:
        yield sample
        if sample.sensor == "truth":
            yield Sample("thermometer", sample.stamp_ms + 5, {"temp_mc": 21_000 + reading}, seq=reading)
            reading += 1


def test_the_built_in_sensors_keep_their_order_and_letters() -> None:
    """Odometry first (the others carry their samples along its track), as before the registry."""
    assert names() == ("odometry", "compass", "gyro", "correlator", "sonar", "battery", "truth", "lops")
    assert logs.SENSOR_SOURCE == {
        "odometry": "O", "compass": "M", "gyro": "G", "correlator": "C",
        "sonar": "W", "battery": "B", "truth": "T", "lops": "L",
    }  # fmt: skip
    assert "thermometer" not in load_config()["sensors"]


def test_a_file_in_the_sensors_folder_is_a_sensor(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The folder is the list: a module dropped beside gyro.py registers itself on import."""
    import modules.localization.sensors as package

    (tmp_path / "hygrometer.py").write_text(
        "from modules.localization.sensors.base import Sensor, register\n"
        "from modules.localization.sync import NewestSync\n"
        "register(Sensor('hygrometer', 'Y', 'hygrometer', 80, lambda context: NewestSync('hygrometer')))\n"
    )
    monkeypatch.setattr(package, "__path__", [*package.__path__, str(tmp_path)])
    try:
        package._discover()
        assert names()[-1] == "hygrometer" and sensor_of_letter("Y") is not None
        assert load_config()["sensors"]["hygrometer"]["use"] is False
    finally:
        unregister("hygrometer")
        sys.modules.pop("modules.localization.sensors.hygrometer", None)
    assert "hygrometer" not in names()


def test_a_taken_name_or_letter_is_refused(thermometer: Sensor) -> None:
    with pytest.raises(ValueError, match="letter G is gyro's"):
        register(Sensor("hygrometer", "G", "hygrometer", 80, _synchroniser))
    with pytest.raises(ValueError, match="letter K is filter's"):
        register(Sensor("hygrometer", "K", "hygrometer", 80, _synchroniser))
    with pytest.raises(ValueError, match="registered already"):
        register(Sensor("thermometer", "Y", "thermometer", 80, _synchroniser))
    with pytest.raises(ValueError, match="settings lack"):
        Sensor("hygrometer", "Y", "hygrometer", 80, _synchroniser, settings={"use": True})


def test_its_settings_come_with_it(thermometer: Sensor) -> None:
    config = load_config()
    assert config["sensors"]["thermometer"] == {**sensor_settings(use=True, filter=True), "offset_mc": 0}
    assert list(config["sensors"])[-1] == "thermometer"  # after LOPS: its rank
    with pytest.raises(ConfigError, match=r"sensors\.thermometer\.offset_mc: more than 10 °C off"):
        load_config({"sensors": {"thermometer": {"offset_mc": 20_000}}})
    with pytest.raises(ConfigError, match=r"sensors\.thermometer\.offset_mc: expected a whole number"):
        load_config({"sensors": {"thermometer": {"offset_mc": "warm"}}})
    with pytest.raises(ConfigError, match=r"must be one of odometry, .*, lops, thermometer, got 'x'"):
        load_config({"sync": {"trigger": {"sensor": "x"}}})


def test_a_sensor_registered_here_is_synchronised_logged_converted_analysed_and_replayed(
    thermometer: Sensor, tmp_path: Path
) -> None:
    path = tmp_path / "run.trlog"
    config = load_config({"sensors": {"thermometer": {"offset_mc": 1000}}})
    core = LocalizationCore(config, data_log=DataLog(path, "20040120-130535", config))
    readings = 0
    for sample in with_thermometer(drive([("s", 300.0), ("r", 45.0)], seed=3)):
        readings += sample.sensor == "thermometer"
        core.feed(sample)
        core.maybe_sync()
    report = core.report()
    core.close()
    assert report["timing"]["thermometer"] == {"samples": readings, "missed": 0, "late": 0}

    log = read_log(path)  # its records are read, none taken for damage
    raw = [r for r in log.records if r[1:3] == ["H", "R"]]
    synced = [r for r in log.records if r[1:3] == ["H", "C"]]
    assert len(raw) == readings and raw[0][3]["v"] == {"temp_mc": 21_000} and raw[0][3]["seq"] == 0
    assert len(synced) > 20 and synced[0][3]["celsius"] == pytest.approx(20.0)
    assert sensor_of_letter("H") is thermometer and logs.SOURCE_SENSOR["H"] == "thermometer"
    # fused through its own hook, once per synchronised record (its sensors.thermometer.filter)
    assert [stamp for stamp, _ in FUSED] == [r[0] for r in synced]

    text = convert_text(log)
    assert f"H R {raw[0][0]:>8d}  21000" in text.splitlines()
    assert f"H C {synced[0][0]:>8d}   20.00 1" in text.splitlines()
    seed = convert_seed_text(log)  # no seed format of its own: ours
    assert f"H C {synced[0][0]:7d}   20.00 1" in seed.splitlines()
    data_dat, _ = convert_seed_dat(log)  # table B.8 and its column, before the filter's
    line = data_dat.splitlines()[-1].split()
    assert len(line) == 17 + 1 and float(line[-7]) == pytest.approx(synced[-1][3]["celsius"], abs=0.005)
    data_csv, _ = convert_csv(log)
    header, last = data_csv.splitlines()[0].split(","), data_csv.splitlines()[-1].split(",")
    assert header[6] == "celsius" and float(last[6]) == pytest.approx(synced[-1][3]["celsius"])
    assert "/log/thermometer/raw" in {t.name for t in log_topics(log)}

    summary, files = analyse(path, tmp_path / "plots")
    assert summary["thermometer"]["syncs"] == len(synced)
    assert summary["timing"]["thermometer"]["samples"] == readings
    assert tmp_path / "plots" / "thermometer.png" in files and "thermometer.png" in plots()
    json.dumps(summary)

    result = replay(path, tmp_path / "replayed.trlog")
    assert result.identical, result.first_difference
    again = read_log(tmp_path / "replayed.trlog")
    assert [r for r in again.records if r[1] == "H"] == [r for r in log.records if r[1] == "H"]


class FakeChannel:
    def __init__(self) -> None:
        self.values: dict[str, Any] | None = None

    @property
    def published(self) -> bool:
        return self.values is not None

    def read(self) -> dict[str, Any]:
        assert self.values is not None
        return dict(self.values)


class FakeOS:
    """What the Localizer asks of a module program's ring: its data channels and round counter."""

    name = "copro"
    counter = 0

    def __init__(self) -> None:
        self.channels: dict[str, FakeChannel] = {}

    def subscribe(self, channel: str) -> FakeChannel:
        return self.channels.setdefault(channel, FakeChannel())


def test_the_localizer_reads_it_from_its_own_data_channel(thermometer: Sensor, tmp_path: Path) -> None:
    ring = FakeOS()
    config = load_config({"logs": {"enabled": False}, "sync": {"trigger": {"sensor": "thermometer"}}})
    localizer = Localizer(ring, config)
    localizer.setup()
    assert "thermometer.data" in ring.channels
    results = []
    for reading in range(5):
        values = {"stamp_ms": 100 * reading, "temp_mc": 20_000 + reading, "reading": reading, "unit": 1}
        ring.channels["thermometer.data"].values = values
        results.append(localizer.step())
        assert localizer.step() is None  # the same reading again: not a new sample
    assert localizer.report()["timing"]["thermometer"]["samples"] == 5
    # its own trigger: a synchronisation at each reading (on the 100 ms grid of its time)
    assert [r.data["thermometer"] for r in results if r is not None] == [
        {"celsius": 20.0 + reading / 1000.0, "count": 1} for reading in range(5)
    ]
    localizer.close()
