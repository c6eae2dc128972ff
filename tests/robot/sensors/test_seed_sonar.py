"""The sonar in seed mode (issue 20, seed §4.3.2): the seed's two-sample tangent, its first-match
distance areas, its behaviour table with the PROGRESSIVE flaw, and its main loop writing the data
channel after every pair — each beside ours. Expected values are worked out here from the seed's
text, not taken from the code under test."""

from __future__ import annotations

import copy
import statistics
import threading
from collections import deque

import numpy as np
import pytest

from modules.description.room import Pose, Wall, World
from modules.sensors import sonar as algo
from modules.variants import ENV
from modules.world import echo
from modules.world.clock import SimClock
from tests.support.hwprograms import program
from tests.support.memring import MemoryRing, wait_for

SonarProgram = program("sonar")
THRESHOLD = 40
SAMPLES = 510
ALERT, CLOSE, NEAR, MIDDLE, FAR, NO_CONTACT = range(6)  # protocol.yaml enums.distance_area
NONE, LINEAR, PROGRESSIVE, DEGRESSIVE = range(4)  # protocol.yaml enums.behaviour


def ramp(start: int, slope: float = 2.0) -> np.ndarray:
    """A clean echo edge: 0 counts until ``start``, then rising ``slope`` counts per sample."""
    k = np.arange(SAMPLES)
    return np.clip(slope * (k - start), 0, 200).astype(np.uint8)


def seed_formula(env: np.ndarray) -> int:
    """Seed §4.3.2 written out: first sample n above the threshold, tangent through samples n-1
    and n, its zero crossing, ÷3 (truncating; before the ping: 0)."""
    n = next(i for i, v in enumerate(env.tolist()) if v > THRESHOLD)
    s_n, s_prev = float(env[n]), float(env[n - 1])
    crossing = n - s_n / (s_n - s_prev)
    return int(max(0.0, crossing)) // 3


# -- contact --------------------------------------------------------------------------------------


def test_on_a_clean_edge_the_seeds_tangent_and_ours_find_the_echos_start():
    for start in (75, 300, 301, 302):  # 25 cm; 100 cm; and 1/3, 2/3 of a cm further
        env = ramp(start)
        # the first sample above 40 is start + 21 (42 counts), the one before has 40: the
        # tangent's slope is 2 and it crosses zero at start + 21 - 42 / 2 = start
        assert algo.contact_seed_tangent(env) == start // 3
        assert algo.contact_tangent(env) == round(start / 3)


def test_noise_on_the_edge_moves_the_seeds_tangent_not_ours():
    low = ramp(300)
    low[320] = 34  # sample n-1 = 320 six counts low: slope 42 - 34 = 8, 321 - 42/8 = 315.75
    assert algo.contact_seed_tangent(low) == 105  # 5 cm late
    assert algo.contact_tangent(low) == 100
    high = ramp(300)
    high[321] = 41  # sample n = 321 one count above the threshold: slope 1, 321 - 41 = 280
    assert algo.contact_seed_tangent(high) == 93  # 7 cm early
    assert algo.contact_tangent(high) == 100


def test_on_noisy_edges_the_seeds_tangent_scatters_and_ours_does_not():
    rng = np.random.default_rng(20)
    seed_cm, ours_cm = [], []
    for _ in range(200):
        env = np.clip(ramp(300).astype(float) + rng.normal(0, 2, SAMPLES) + 3, 0, 255).astype(np.uint8)
        seed = algo.contact_seed_tangent(env)
        assert seed == seed_formula(env)
        seed_cm.append(seed)
        ours_cm.append(algo.contact_tangent(env))
    assert abs(statistics.median(ours_cm) - 100) <= 1
    assert statistics.pstdev(ours_cm) < 1.5
    assert statistics.pstdev(seed_cm) > 2 * statistics.pstdev(ours_cm), (seed_cm, ours_cm)


def wall_ahead(distance_mm: float) -> World:
    return World("t", (Wall(distance_mm, -3000, distance_mm, 3000),), Pose(-5000, 0, 0))


def test_on_the_simulated_wall_the_seeds_tangent_reads_25_cm_and_scatters_further_out():
    """Seed §4.3.2: the tangent reads the 25 cm echo where the threshold reads 28 cm. Further out
    the edge is flatter and noisier, and two raw samples scatter where ours holds."""
    spread = {}
    for distance in (250, 500, 1000):
        envs = [
            echo.envelope(wall_ahead(distance), 0, 0, 0.0, np.random.default_rng(s), jitter_mm=0)
            for s in range(40)
        ]
        seed = [algo.contact_seed_tangent(e) for e in envs]
        assert seed == [seed_formula(e) for e in envs]
        assert abs(statistics.median(seed) - distance / 10) <= 1
        if distance == 250:
            assert statistics.median(algo.contact_threshold(e) for e in envs) == 28
        spread[distance] = (
            statistics.pstdev(seed),
            statistics.pstdev([algo.contact_tangent(e) for e in envs]),
        )
    for distance in (500, 1000):
        seed_sd, ours_sd = spread[distance]
        assert seed_sd > 1.5 * ours_sd, spread


def test_a_weak_echo_puts_the_seeds_tangent_before_the_ping():
    env = np.zeros(SAMPLES, dtype=np.uint8)
    env[200:260] = 38
    env[230] = 40
    env[231] = 41  # peaks just over the threshold: slope 1, 231 - 41 = 190 samples
    assert algo.contact_seed_tangent(env) == 63
    env[231] = 45  # slope 5: 231 - 9 = 222 -> 74
    assert algo.contact_seed_tangent(env) == 74
    weak = np.zeros(SAMPLES, dtype=np.uint8)
    weak[20], weak[21] = 40, 41  # 21 - 41 < 0: the tangent lands before the ping -> 0 cm
    assert algo.contact_seed_tangent(weak) == 0
    assert algo.contact_seed_tangent(np.full(SAMPLES, 40)) == 255  # nothing above the threshold
    assert algo.contact_seed_tangent(np.full(SAMPLES, 41)) == 0  # above from the first sample


def test_contact_method_picks_the_seeds_tangent_in_seed_mode_only():
    env = ramp(300)
    env[320] = 34
    assert algo.contact_method(tangent=True, seed=True)(env) == 105
    assert algo.contact_method(tangent=True, seed=False)(env) == 100
    for seed in (True, False):  # SET_METHOD tangent=0: the first sample above 40 is 321 -> 107
        assert algo.contact_method(tangent=False, seed=seed)(env) == 107


# -- distance areas -------------------------------------------------------------------------------

# seed §4.3.2: ALERT 0-4, CLOSE 4-12, NEAR 10-30, MIDDLE 25-65, FAR 60-255, read in this order
SEED_TABLE = [(ALERT, 0, 4), (CLOSE, 4, 12), (NEAR, 10, 30), (MIDDLE, 25, 65), (FAR, 60, 255)]


def seed_area_by_hand(cm: int) -> int:
    return next(area for area, lo, hi in SEED_TABLE if lo <= cm <= hi)


def test_seed_areas_first_match_in_the_seeds_order_and_no_contact_is_far():
    assert [algo.seed_distance_area(cm) for cm in range(256)] == [seed_area_by_hand(cm) for cm in range(256)]
    bounds = (0, 4, 5, 10, 12, 13, 25, 30, 31, 60, 65, 66, 254, 255)
    assert [algo.seed_distance_area(cm) for cm in bounds] == [
        ALERT, ALERT, CLOSE, CLOSE, CLOSE, NEAR, NEAR, NEAR, MIDDLE, MIDDLE, MIDDLE, FAR, FAR, FAR,
    ]  # fmt: skip
    # ours without history: an area ends where the next begins, and 255 is NO_CONTACT
    assert [algo.distance_area(cm) for cm in bounds] == [
        ALERT, CLOSE, CLOSE, NEAR, NEAR, NEAR, MIDDLE, MIDDLE, MIDDLE, FAR, FAR, FAR, FAR, NO_CONTACT,
    ]  # fmt: skip


# -- the program ----------------------------------------------------------------------------------


class ScriptedSonar:
    """Sonar hardware whose pairs see scripted echoes: a distance d (cm) is a clean edge starting
    at sample 3 d, 255 no echo, an array that envelope. Each ping takes a script's next entry and
    the last one repeats; ``replace`` gives a pair a new script while the program runs. Every
    ping is logged, and the program's writes with it."""

    def __init__(self, scripts: dict[int, list], speed: float = 10.0) -> None:
        self.clock = SimClock(speed)
        self.scripts = {pair: deque(scripts.get(pair, [255])) for pair in range(8)}
        self.events: list[tuple] = []
        self.lock = threading.Lock()

    def replace(self, pair: int, entries: list) -> None:
        with self.lock:
            self.scripts[pair] = deque(entries)

    def ping(self, sensors: list[int], ping_samples: int = 60, slot_ms: float = 15.0):
        now = self.clock.now_ms()
        envelopes, seen = [], []
        with self.lock:
            for pair in sensors:
                script = self.scripts[pair]
                entry = script.popleft() if len(script) > 1 else script[0]
                if isinstance(entry, np.ndarray):
                    envelopes.append(entry)
                else:
                    envelopes.append(np.zeros(SAMPLES, np.uint8) if entry == 255 else ramp(3 * entry))
                seen.append((pair, entry))
            self.events.append(("ping", seen))
        return envelopes, [now + i * slot_ms for i in range(len(sensors))]

    def log(self) -> list[tuple]:
        with self.lock:
            return list(self.events)


class RecordingSonar(SonarProgram):
    """The sonar program with its data channel's writes logged beside the hardware's pings."""

    def setup(self) -> None:
        super().setup()
        channel, hw = self.out, self.hw

        class Recorder:
            def write(self, **fields) -> None:
                with hw.lock:
                    hw.events.append(("write", copy.deepcopy(fields)))
                channel.write(**fields)

        self.out = Recorder()


@pytest.fixture
def run_sonar(monkeypatch):
    rings = []

    def start(algorithms: str, scripts: dict[int, list]) -> tuple[ScriptedSonar, MemoryRing]:
        monkeypatch.setenv(ENV, algorithms)
        hw = ScriptedSonar(scripts)
        ring = MemoryRing([10, 30])
        rings.append(ring)
        ring.nodes[30].start_program(RecordingSonar, hw)
        return hw, ring

    yield start
    for ring in rings:
        ring.nodes[30].stop_program()
        ring.close()


def writes(events: list[tuple]) -> int:
    return sum(1 for kind, _ in events if kind == "write")


def noisy_edge() -> np.ndarray:
    env = ramp(300)
    env[320] = 34  # the seed's tangent reads 105 cm, ours 100 (worked out above)
    return env


SCRIPTS = {0: [4], 1: [12], 2: [30], 3: [65], 4: [255], 5: [5], 6: [13], 7: [noisy_edge()]}


def test_seed_mode_writes_the_data_channel_after_every_pair(run_sonar):
    hw, ring = run_sonar("sonar=seed", SCRIPTS)
    wait_for(lambda: writes(hw.log()) >= 20, 20, "20 writes")
    ring.nodes[30].stop_program()
    events = hw.log()
    expected_cm = [4, 12, 30, 65, 255, 5, 13, seed_formula(noisy_edge())]
    assert expected_cm[7] == 105
    assert events[0][0] == "ping"
    previous: dict | None = None
    for k in range(0, len(events) - 1, 2):  # ping one pair, write, ping the next pair, write ...
        (kind, seen), (next_kind, fields) = events[k], events[k + 1]
        assert (kind, next_kind) == ("ping", "write"), events[k : k + 2]
        [(pair, _entry)] = seen
        assert pair == (k // 2) % 8
        assert fields["distances"][pair] == expected_cm[pair]
        assert fields["areas"][pair] == seed_area_by_hand(expected_cm[pair])
        assert fields["sweep"] == (k // 2 + 1) // 8  # a sweep is counted when pair 7 is written
        if previous is not None:  # the other pairs keep what their last ping gave
            for other in set(range(8)) - {pair}:
                assert fields["distances"][other] == previous["distances"][other]
                assert fields["areas"][other] == previous["areas"][other]
        previous = fields
    first_sweep = [e for e in events if e[0] == "write"][:8]
    assert [f["distances"][7] for _, f in first_sweep[:7]] == [255] * 7  # pair 7 not pinged yet
    assert [f["areas"][7] for _, f in first_sweep[:7]] == [FAR] * 7  # the seed: 255 is FAR


def test_ours_writes_the_data_channel_once_per_sweep(run_sonar):
    hw, ring = run_sonar("sonar=ours", SCRIPTS)
    wait_for(lambda: writes(hw.log()) >= 3, 20, "3 writes")
    ring.nodes[30].stop_program()
    events = hw.log()
    for k in range(0, len(events) - 1, 2):
        (kind, seen), (next_kind, fields) = events[k], events[k + 1]
        assert (kind, next_kind) == ("ping", "write")
        assert [pair for pair, _ in seen] == list(range(8))
        assert fields["sweep"] == k // 2 + 1
        assert fields["distances"][:7] == [4, 12, 30, 65, 255, 5, 13]
        assert abs(fields["distances"][7] - 100) <= 1  # ours: the edge's true start, 300 / 3
        assert fields["areas"][:5] == [CLOSE, NEAR, MIDDLE, FAR, NO_CONTACT]


TABLE = [30, 32, 34, 50, 50, 50]  # seed §4.3.2's table


def behaviour_after_each_ping(events: list[tuple], pair: int) -> list[tuple[int, int]]:
    """(scripted distance, behaviour written for ``pair``) for each ping of ``pair``."""
    out, pending = [], None
    for kind, payload in events:
        if kind == "ping":
            pending = next((entry for p, entry in payload if p == pair), None)
        elif pending is not None:
            out.append((pending, payload["behaviours"][pair]))
            pending = None
    return out


@pytest.mark.parametrize(
    ("algorithms", "classes"),
    [
        ("seed", [NONE, NONE, LINEAR, DEGRESSIVE, PROGRESSIVE, LINEAR]),  # the seed's flaw
        ("ours", [NONE, NONE, LINEAR, DEGRESSIVE, NONE, LINEAR]),
    ],
)
def test_the_behaviour_table_in_the_program(run_sonar, algorithms, classes):
    hw, ring = run_sonar(f"sonar={algorithms}", {0: TABLE})
    wait_for(lambda: len(behaviour_after_each_ping(hw.log(), 0)) >= len(TABLE), 20, "the table's readings")
    ring.nodes[30].stop_program()
    got = behaviour_after_each_ping(hw.log(), 0)[: len(TABLE)]
    assert [d for d, _ in got] == TABLE
    assert [b for _, b in got] == classes


def test_set_method_switches_seed_mode_to_our_classifier(run_sonar):
    hw, ring = run_sonar("seed", {0: [255]})  # no contact: no history in either classifier
    assert ring.nodes[10].deliver("sonar", "SET_METHOD", tangent=1, seed_classifier=0, timeout=5)
    wait_for(lambda: not ring.nodes[30].program.seed_classifier, 5, "classifier switched")
    hw.replace(0, TABLE)
    wait_for(
        lambda: [d for d, _ in behaviour_after_each_ping(hw.log(), 0)][-len(TABLE) :] == TABLE,
        20,
        "the table's readings",
    )
    ring.nodes[30].stop_program()
    got = behaviour_after_each_ping(hw.log(), 0)[-len(TABLE) :]
    assert [b for _, b in got] == [NONE, NONE, LINEAR, DEGRESSIVE, NONE, LINEAR]
