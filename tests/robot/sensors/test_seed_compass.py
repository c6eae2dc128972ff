"""The seed's compass loop (seed §3.3.3): flip, measure, drive the compensation coil, measure again
until the two flip readings lie symmetric round zero; bounded, and not getting there is reported.

The judges here write the bridge out on their own: a KMZ51 reads ``mid + g(c)·(H + c) + o`` with
the flip coil set and ``mid - g(c)·(H + c) + o`` reset, ``g(c) = 20·(1 - 0.002·|c|)`` counts/µT
(the coil's field lowers the gain: seed "beeinflusst die Amplitude"), ``o`` the bridge's offset.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from modules.description import load_world
from modules.sensors.compass import compensate_until_symmetric, heading_from_bridges
from modules.world.clients import CompassHardware
from modules.world.magnetics import CompassBridges
from modules.world.sim import Simulator
from tests.support.hwprograms import program
from tests.support.memring import MemoryRing, wait_for

CompassProgram = program("compass")

MID = 2048.0
G = 20.0  # counts per µT, the KMZ51 module's datasheet value
LOSS = 0.002  # gain lost per µT of coil field
TOLERANCE_UT = 0.25


def gain(coil_ut: float) -> float:
    return G * (1.0 - LOSS * abs(coil_ut))


class Bridges:
    """Two noiseless bridges seeing ``field`` (µT, after nothing), with offsets ``offsets`` (counts)."""

    def __init__(self, field: tuple[float, float], offsets: tuple[float, float]) -> None:
        self.field = field
        self.offsets = list(offsets)
        self.calls = 0

    def pair(self, plus: tuple[float, float], minus: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
        self.calls += 1
        vp = [MID + gain(plus[b]) * (self.field[b] + plus[b]) + self.offsets[b] for b in range(2)]
        vm = [MID - gain(minus[b]) * (self.field[b] + minus[b]) + self.offsets[b] for b in range(2)]
        return np.array(vp), np.array(vm)


def measurements_until_symmetric(field: float, static: float, offset: float) -> int:
    """One bridge, by hand: the coil carries static + k flipped and static - k reset; the pair's
    midpoint m (counts) over the phases' mean gain is the offset left in µT; k -= that; stop when
    it is within the tolerance."""
    k, n = 0.0, 0
    while True:
        n += 1
        up, down = static + k, static - k
        m = (gain(up) * (field + up) - gain(down) * (field + down)) / 2 + offset
        g = (gain(up) + gain(down)) / 2
        if abs(m) / g <= TOLERANCE_UT:
            return n
        k -= m / g
        assert n < 50


def first_value_alone(v_plus: float, static: float, k: float) -> float:
    """The field (after the static compensation) from the flipped reading alone, once the pair is
    symmetric: ``mid + g+·(H+s+k) + o`` with ``o = -(g+ + g-)·k/2 - (g+ - g-)·(H+s)/2`` is
    ``mid + (g+ + g-)/2·(H+s) + (g+ - g-)·k/2`` (the seed: the coil's field as a known factor)."""
    gp, gm = gain(static + k), gain(static - k)
    return (v_plus - MID - (gp - gm) * k / 2) / ((gp + gm) / 2)


def test_one_step_leaves_the_gain_loss_and_the_loop_measures_again() -> None:
    """Offsets 600 and -300 counts (30 and 15 µT): the first compensation cancels them at the
    uncompensated gain, the coil's field lowers it (without a static field 1.9 µT and 0.46 µT are
    left), so the loop measures again; with the static field cancelled too, three flip pairs."""
    bridges = Bridges(field=(11.0, -7.0), offsets=(600.0, -300.0))
    static = (-6.0, 4.0)
    expected = max(
        measurements_until_symmetric(11.0, -6.0, 600.0), measurements_until_symmetric(-7.0, 4.0, -300.0)
    )
    # by hand, static 0: k1 = -600/20 = -30 µT, left 600·0.002·30 = 36 counts = 1.9 µT at g = 18.8
    assert measurements_until_symmetric(11.0, 0.0, 600.0) == 3
    result = compensate_until_symmetric(bridges.pair, static)
    assert result.converged
    assert result.measurements == expected == bridges.calls
    assert expected >= 3  # the seed's "ansonsten muß erneut kompensiert werden" really happens
    # symmetric: the flipped reading alone now gives the field (seed: "reicht der erste Wert")
    k = result.offset_ut
    plus, minus = bridges.pair((static[0] + k[0], static[1] + k[1]), (static[0] - k[0], static[1] - k[1]))
    for b, h in enumerate((11.0 + static[0], -7.0 + static[1])):
        assert abs(plus[b] + minus[b] - 2 * MID) / 2 <= TOLERANCE_UT * G  # round zero
        assert first_value_alone(plus[b], static[b], k[b]) == pytest.approx(h, abs=TOLERANCE_UT)


def test_a_symmetric_sensor_needs_one_measurement_and_no_coil() -> None:
    bridges = Bridges(field=(18.0, 0.0), offsets=(1.0, -2.0))  # 0.05 and 0.1 µT: within tolerance
    result = compensate_until_symmetric(bridges.pair, (0.0, 0.0))
    assert result.converged and result.measurements == 1
    assert result.offset_ut.tolist() == [0.0, 0.0]


def test_an_offset_beyond_the_coils_reach_is_reported_after_the_bound() -> None:
    """3000 counts = 150 µT of offset: the coil makes at most 50 µT, the pair never gets symmetric."""
    bridges = Bridges(field=(18.0, 0.0), offsets=(3000.0, 0.0))
    result = compensate_until_symmetric(bridges.pair, (0.0, 0.0), max_measurements=6)
    assert not result.converged
    assert result.measurements == 6 == bridges.calls
    assert abs(result.offset_ut[0]) <= 50.0
    assert abs(result.midpoint_counts[0]) > 1000  # what is left, for the report


def test_readings_that_scatter_more_than_the_tolerance_never_loop_forever() -> None:
    class Jumpy(Bridges):
        def pair(self, plus: Any, minus: Any) -> tuple[np.ndarray, np.ndarray]:
            self.offsets[1] = 40.0 if self.calls % 2 else -40.0  # ±2 µT from pair to pair
            return super().pair(plus, minus)

    bridges = Jumpy(field=(0.0, 18.0), offsets=(0.0, 0.0))
    result = compensate_until_symmetric(bridges.pair, (0.0, 0.0), max_measurements=8)
    assert not result.converged and bridges.calls == 8


def test_the_simulated_bridges_with_noise_get_symmetric_and_the_coil_carries_the_offset() -> None:
    world = load_world("empty")
    bridges = CompassBridges(world, np.random.default_rng(4))
    bridges.offsets[:] = [300.0, -250.0]
    static = (-6.0, 4.0)  # the simulated motors' static field, cancelled
    t = [0.0]

    def pair(plus: tuple[float, float], minus: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
        p = bridges.measure(0, 0, 0.3, False, 1, plus, 20, t[0])
        m = bridges.measure(0, 0, 0.3, False, -1, minus, 20, t[0] + 20)
        t[0] += 40
        return p.mean(axis=1), m.mean(axis=1)

    result = compensate_until_symmetric(pair, static)
    assert result.converged and result.measurements <= 4
    # the coil's offset part k cancels o: g(s+k)(k) ... at s ± k the mean gain; solve numerically
    for b, o in enumerate((300.0, -250.0)):
        k = result.offset_ut[b]
        left = (gain(static[b] + k) + gain(static[b] - k)) / 2 * k + o
        assert abs(left) / G <= 2 * TOLERANCE_UT, (b, k)
    # the flipped reading alone gives the heading now, as the seed meant to take it
    plus, _ = pair(
        (static[0] + result.offset_ut[0], static[1] + result.offset_ut[1]),
        (static[0] - result.offset_ut[0], static[1] - result.offset_ut[1]),
    )
    alone = [first_value_alone(plus[b], static[b], result.offset_ut[b]) for b in range(2)]
    truth = bridges.field(0, 0, 0.3, False) + np.array(static)
    assert alone == pytest.approx(truth.tolist(), abs=0.5)
    heading, _ = heading_from_bridges(*alone)
    true_heading, _ = heading_from_bridges(*truth)
    assert abs(math.remainder(heading - true_heading, 2 * math.pi)) < math.radians(2)


def settled_offset_ut(offset: float) -> float:
    """The coil field k with no static field that makes a pair symmetric: g(k)·k + o = 0, i.e.
    G·L·k² - G·|k| + |o| = 0, the smaller root, signed against o."""
    magnitude = (G - math.sqrt(G * G - 4 * G * LOSS * abs(offset))) / (2 * G * LOSS)
    return -math.copysign(magnitude, offset)


def test_the_program_settles_at_start_and_follows_a_drifting_offset() -> None:
    sim = Simulator(load_world("empty"), seed=9, speed=40.0)
    sim.bridges.offsets[:] = [300.0, -250.0]
    ring = MemoryRing([10, 40])
    main = ring.nodes[10]
    main.set_own_input_id()
    data = main.subscribe("compass.data")
    ring.nodes[40].start_program(CompassProgram, CompassHardware.local(sim))
    try:
        wait_for(lambda: data.visits and data.read()["sample"] > 2, 10, "compass samples")
        compass = ring.nodes[40].program
        report = compass.report()
        assert report["symmetry"]["converged"], report["symmetry"]
        assert 2 <= report["symmetry"]["measurements"] <= 4
        for k, o in zip(report["offset_compensation_ut"], (300.0, -250.0), strict=True):
            assert k == pytest.approx(settled_offset_ut(o), abs=0.4)
        # warm the sensor: bridge 0's offset jumps by 100 counts; each sample is a round of the loop
        sim.bridges.offsets[0] += 100.0
        wait_for(
            lambda: compass.offset_compensation[0] == pytest.approx(settled_offset_ut(400.0), abs=0.4),
            10,
            "the coil following the offset",
        )
        assert compass.report()["asymmetric_rounds"] < 8
    finally:
        ring.nodes[40].stop_program()
        ring.close()
