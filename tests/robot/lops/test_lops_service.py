"""LOPS as a process beside a world over real Zenoh: ``python -m modules.lops`` measures where the
world has the robot every 98 simulated ms and puts tables 6.1/6.2's packets on
``robot/lops/packets``. The judge reads the packets with a struct format written from the
tables and the distances from its own geometry, nothing from :mod:`modules.lops`."""

from __future__ import annotations

import itertools
import math
import signal
import statistics
import struct
import sys
import threading
from typing import Any

import pytest

from tests.support.ringutil import tap, wait_until

#: table 6.1: 'S' 'D', counter (long), distances (double[3]), X, Y (double), 'E'; little-endian
DATA = struct.Struct("<2si3d2d1s")
RECEIVERS = ((200.0, 200.0), (4800.0, 200.0), (200.0, 4800.0))
START = (1000.0, 1000.0)  # the square hall's start pose (modules/description/rooms/square.yaml)


class Packets:
    """Every packet put on the key, parsed by the tables: data as tuples, messages as text."""

    def __init__(self, session: Any, key: str) -> None:
        self.data: list[tuple[int, tuple[float, float, float], float, float]] = []
        self.messages: list[str] = []
        self.malformed: list[bytes] = []
        self.lock = threading.Lock()
        self.sub = session.declare_subscriber(key, self._on)

    def _on(self, sample: Any) -> None:
        raw = sample.payload.to_bytes()
        with self.lock:
            if raw[:2] == b"SD" and len(raw) == DATA.size and raw[-1:] == b"E":
                _, counter, d1, d2, d3, x, y, _ = DATA.unpack(raw)
                self.data.append((counter, (d1, d2, d3), x, y))
            elif raw[:2] == b"SM" and len(raw) == raw[2] + 4 and raw[-1:] == b"E":
                self.messages.append(raw[3:-1].decode("latin-1"))
            else:
                self.malformed.append(raw)

    def count(self) -> int:
        with self.lock:
            return len(self.data)


@pytest.mark.slow
def test_lops_beside_a_world_sends_the_robots_distances_and_position(
    procs: Any, ring_name: str, endpoint: str
) -> None:
    world = procs.start(
        [sys.executable, "-m", "modules.world", "--ring", ring_name, "--listen", endpoint, "--world", "square",
         "--speed", "5", "--seed", "2"]
    )  # fmt: skip
    with tap(endpoint) as session:
        packets = Packets(session, f"tokenring/{ring_name}/robot/lops/packets")
        lops = procs.start(
            [sys.executable, "-m", "modules.lops", "--ring", ring_name, "--connect", endpoint, "--seed", "4",
             "--receivers", *(f"{x:g},{y:g}" for x, y in RECEIVERS)]
        )  # fmt: skip
        wait_until(lambda: packets.count() >= 80, 120, "80 LOPS data packets")
        lops.send_signal(signal.SIGTERM)
        output, _ = lops.communicate(timeout=30)
        packets.sub.undeclare()
    world.terminate()
    assert world.wait(30) == 0
    assert lops.returncode == 0, output
    assert "Traceback" not in output and "lops: stopped after" in output, output

    data = list(packets.data)
    assert not packets.malformed, packets.malformed[:3]
    counters = [c for c, *_ in data]
    assert all(b > a for a, b in itertools.pairwise(counters)), counters  # in order
    assert any("lopscpp started" in m for m in packets.messages), packets.messages

    # the robot stands at the start: each distance heard is the true one within the noise
    true = [math.dist(START, r) for r in RECEIVERS]
    for i in range(3):
        heard = [d[i] for _, d, _, _ in data if not math.isnan(d[i])]
        assert len(heard) > len(data) * 0.6, (i, len(heard), len(data))
        assert statistics.median(abs(h - true[i]) for h in heard) < 10.0, (i, true[i], heard[:10])
    # a position in most packets, within a few cm (the seed: about 20 % without one, +-1 cm)
    positions = [(x, y) for _, _, x, y in data if not (math.isnan(x) or math.isnan(y))]
    assert 0.5 * len(data) < len(positions) < len(data), (len(positions), len(data))
    errors = sorted(math.dist(START, p) for p in positions)
    assert errors[len(errors) // 2] < 15.0, errors[-10:]


@pytest.mark.parametrize(
    ("args", "named"),
    [
        (["--receivers", "1,2", "3,x", "5,6"], "--receivers"),
        (["--receivers", "1,2", "nan,4", "5,6"], "--receivers"),
        (["--receivers", "1,2", "3,1e300", "5,6"], "--receivers"),
        (["--duration", "-1"], "--duration"),
        (["--seed", "-1"], "--seed"),
        (["--config", "/nonexistent/lops.cfg"], "lops.cfg"),
    ],
)
def test_lops_refuses_bad_input_in_one_line(procs: Any, args: list[str], named: str) -> None:
    proc = procs.start([sys.executable, "-m", "modules.lops", *args])
    output, _ = proc.communicate(timeout=60)
    assert proc.returncode == 2, output
    lines = [line for line in output.splitlines() if line.strip()]
    assert len(lines) == 1 and named in lines[0] and "Traceback" not in output, output
