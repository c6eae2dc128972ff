"""The robot's side of LOPS: copro's WLAN receiver takes the packets apart and stamps them, and
the Localizer logs them as appendix B's ``L`` records (raw, synchronised, position) and
lopscpp's messages in its error log. Packets are written here with a struct format from table
6.1, not with :mod:`modules.lops.packets`."""

from __future__ import annotations

import math
import struct
from pathlib import Path
from typing import Any

import pytest

from modules.localization.config import load_config
from modules.localization.localizer import LocalizationCore
from modules.localization.logs import DataLog, ErrorLog, convert_text, read_log
from modules.localization.sync import Sample
from modules.lops.receiver import LopsReceiver
from modules.pc.analysis import analyse

DATA = struct.Struct("<2si3d2d1s")  # table 6.1


def data_packet(counter: int, d: tuple[float, float, float], x: float, y: float) -> bytes:
    return DATA.pack(b"SD", counter, *d, x, y, b"E")


def message_packet(text: str) -> bytes:
    body = text.encode("latin-1")
    return b"SM" + bytes([len(body)]) + body + b"E"


class FakeSession:
    """Hands the subscriber's callback to the test, which puts the samples itself."""

    def __init__(self) -> None:
        self.keys: list[str] = []
        self.callback: Any = None

    def declare_subscriber(self, key: str, callback: Any) -> Any:
        self.keys.append(key)
        self.callback = callback
        return self

    def put(self, raw: bytes) -> None:
        class Payload:
            def to_bytes(self) -> bytes:
                return raw

        class Sample:
            payload = Payload()

        self.callback(Sample())


class StepClock:
    def __init__(self) -> None:
        self.t = 1000.0

    def now_ms(self) -> float:
        self.t += 98.0
        return self.t


def test_the_receiver_stamps_data_resyncs_past_a_lost_byte_and_passes_messages() -> None:
    session, clock = FakeSession(), StepClock()
    data: list[tuple[int, dict[str, Any]]] = []
    messages: list[tuple[int, str, str]] = []
    LopsReceiver(session, "r1", clock).subscribe(
        lambda s, v: data.append((s, v)), lambda *m: messages.append(m)
    )
    assert session.keys == ["tokenring/r1/robot/lops/packets"]

    first = data_packet(7, (1131.4, 3883.3, math.nan), 1000.5, 999.5)
    session.put(first)
    session.put(first[:20])  # one packet over two puts, as a byte stream may cut it
    session.put(first[20:])
    session.put(b"\x00" + data_packet(8, (1.0, 2.0, 3.0), math.nan, math.nan))  # a stray byte first
    session.put(message_packet("W receiver 3: no signal for 10 triggers"))
    session.put(message_packet("a message without a class"))

    assert [v["counter"] for _, v in data] == [7, 7, 8]
    stamp, values = data[0]
    assert stamp == 1098 and values == {
        "counter": 7,
        "d1": 1131.4,
        "d2": 3883.3,
        "d3": None,
        "x": 1000.5,
        "y": 999.5,
    }
    assert data[2][1]["x"] is None and data[2][1]["y"] is None and data[2][1]["d3"] == 3.0
    assert [(c, t) for _, c, t in messages] == [
        ("W", "LOPS: receiver 3: no signal for 10 triggers"),
        ("I", "LOPS: a message without a class"),
    ]


def test_the_localizer_logs_lops_as_l_records_and_its_messages_as_errors(tmp_path: Path) -> None:
    config = load_config({"sensors": {"lops": {"use": True}, "truth": {"use": False}}})
    data_log = DataLog(tmp_path / "data.trlog", "20261206-120000", config)
    error_log = ErrorLog(tmp_path / "errors.trlog", "20261206-120000")
    core = LocalizationCore(config, data_log=data_log, error_log=error_log, start_pose=(1000.0, 1000.0, 0.0))
    for i in range(12):
        t = 100 * i
        core.feed(Sample("odometry", t, {"steps_left": 0, "steps_right": 0}))
        if i % 3 == 1:  # a position; then one with a receiver lost and no position
            lops = {"counter": i, "d1": 1131.0, "d2": 3883.0, "d3": 3884.0, "x": 1001.0, "y": 998.0}
            if i % 2:
                lops = {**lops, "d3": None, "x": None, "y": None}
            core.feed(Sample("lops", t + 40, lops))
        core.maybe_sync()
    core.message("W", 450, "LOPS: receiver 3: no signal for 10 triggers")
    core.close()

    records = read_log(tmp_path / "data.trlog").records
    raw = [r for r in records if r[1] == "L" and r[2] == "R"]
    assert [r[3]["v"]["counter"] for r in raw] == [1, 4, 7, 10]
    synced = [r for r in records if r[1] == "L" and r[2] == "C"]
    assert synced and all(r[3]["count"] == 1 for r in synced)
    positions = [r[3] for r in records if r[1] == "L" and r[2] == "P"]
    # a position only while the newest packet had one; the heading is not LOPS's to give
    assert positions and all(
        p["valid"] == [True, True, False] and (p["x"], p["y"]) == (1001.0, 998.0) for p in positions
    )
    assert len(positions) < len(synced)
    lines = convert_text(read_log(tmp_path / "data.trlog")).splitlines()
    lops_raw = [line.split() for line in lines if line.startswith("L R")]
    assert lops_raw[0][3:] == ["1131", "3883", "0", "1"]  # nothing heard: 0; then the counter
    assert lops_raw[1][3:] == ["1131", "3883", "3884", "4"]
    errors = read_log(tmp_path / "errors.trlog").records
    assert [450, "W", "LOPS: receiver 3: no signal for 10 triggers"] in errors

    # the analyser's LOPS module: the distances plotted, the share without a position counted
    summary, files = analyse(tmp_path / "data.trlog", tmp_path / "plots")
    assert summary["lops"] == {"packets": 4, "without_position": 0.5, "heard": [1.0, 1.0, 0.5]}
    assert (tmp_path / "plots" / "lops.png") in files and (
        tmp_path / "plots" / "lops.png"
    ).stat().st_size > 1000
    assert summary["timing"]["lops"]["samples"] == 4


RECEIVERS = [[200.0, 200.0], [4800.0, 200.0], [200.0, 4800.0]]


def lops_drive(config: dict[str, Any], echo_every: int = 0) -> tuple[LocalizationCore, dict[str, float]]:
    """One lap of the square hall without the sonar's walls; LOPS's distances made here from the
    drive's truth (4 mm noise, a receiver lost every 7th, a late echo of +800 mm every
    ``echo_every``th), fed as copro's receiver feeds them."""
    import numpy as np

    from tests.support.locsim import drive, square_moves

    core = LocalizationCore(config)
    rng = np.random.default_rng(3)
    truth: dict[str, float] = {}
    k = 0
    for sample in drive(
        square_moves(1, 3000), seed=3, heading=lambda: core.ekf.pose[2] if core.ekf else None
    ):
        core.feed(sample)
        if sample.sensor == "truth":
            truth = sample.values
            k += 1
            d = [math.dist((truth["x"], truth["y"]), r) + rng.normal(0, 4.0) for r in RECEIVERS]
            if k % 7 == 0:
                d[k % 3] = None
            if echo_every and k % echo_every == 0:
                d[1] = d[1] + 800.0 if d[1] is not None else None
            core.feed(
                Sample(
                    "lops",
                    sample.stamp_ms,
                    {"counter": k, "d1": d[0], "d2": d[1], "d3": d[2], "x": None, "y": None},
                )
            )
        core.maybe_sync()
    return core, truth


@pytest.mark.slow  # two laps of the hall simulated, ~20 s
def test_the_filter_takes_lops_distances_one_receiver_at_a_time_and_gates_late_echoes() -> None:
    """With LOPS's distances in the EKF (also when a receiver is lost), one lap without walls
    ends within 2 cm of the truth, far better than without them; late echoes fail the gate."""
    base = {"sensors": {"sonar": {"use": False}, "lops": {"use": True}}, "lops": {"receivers": RECEIVERS}}
    without = load_config(base)
    with_lops = load_config({**base, "sensors": {**base["sensors"], "lops": {"use": True, "filter": True}}})
    core_without, truth_without = lops_drive(without)
    core, truth = lops_drive(with_lops, echo_every=10)  # the drive turns by the filter: its own truth

    def error(c: LocalizationCore, t: dict[str, float]) -> float:
        k = c.positions["K"]
        return math.hypot(k["x"] - t["x"], k["y"] - t["y"])

    ours, theirs = error(core, truth), error(core_without, truth_without)
    assert ours < 20.0 and ours < theirs / 3, (ours, theirs)
    gates = core.report()["gates"]
    assert gates["accepted"]["lops"] > 500
    assert gates["rejected"].get("lops", 0) >= 0.8 * (gates["accepted"]["lops"] // 3 // 10)  # the echoes


def test_lops_in_the_filter_needs_its_receivers() -> None:
    from modules.localization.config import ConfigError

    with pytest.raises(ConfigError, match=r"lops\.receivers"):
        load_config({"sensors": {"lops": {"use": True, "filter": True}}})
    with pytest.raises(ConfigError, match="three"):
        load_config({"lops": {"receivers": [[0, 0], [1, "x"], [2, 2]]}})
