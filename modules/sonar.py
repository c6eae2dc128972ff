"""The sonar module (seed §4.3.2): sweeps the eight transmitter/receiver pairs and publishes
distances, behaviours and distance areas.

Each sweep pings pair 0..7 one after another, 15 simulated ms apart (120 ms per sweep, 8.3 Hz),
reads each pair's 510-sample echo envelope from the hardware and finds the contact with the
threshold + tangent method (SET_METHOD tangent=0: plain thresholding, for comparison), ÷3 -> cm,
255 = no contact. Then the distance area (overlaps read as hysteresis) and the behaviour per
pair: ours by default, the seed's classifier (with its PROGRESSIVE/DEGRESSIVE jump) with
SET_METHOD seed_classifier=1. ``stamp_ms`` is when pair 0 was pinged; pair i was pinged
``15 i`` ms later.

Seed mode (``--algorithms sonar=seed``, seed §4.3.2 "Hauptprogramm"): each pair is pinged on its
own, 15 ms apart, and the data channel is written after every pair (its distance, area and
behaviour; the others keep the values of their last ping), with the seed's two-sample tangent,
the seed's first-match areas (no contact reads FAR) and the seed's classifier (SET_METHOD still
switches both). ``sweep`` counts completed sweeps (it steps when pair 7 is written) and
``stamp_ms`` is when pair 0 of the sweep in progress was pinged.
"""

from __future__ import annotations

import logging

from modules.description.robot import SONAR_COUNT, SONAR_SLOT_MS
from modules.sensors.sonar import (
    NO_CONTACT,
    contact_method,
    distance_area,
    make_classifier,
    seed_distance_area,
)
from modules.variants import algorithm
from tokenring import UserProgram

log = logging.getLogger("tokenring.sonar")
PING_SAMPLES = 60  # the transmitter's burst: 1.2 ms


class Program(UserProgram):
    module = "sonar"

    def setup(self) -> None:
        self.out = self.os.publish()
        self.os.set_own_input_id()
        self.clock = self.hw.clock
        self.seed = algorithm("sonar") == "seed"
        self.tangent = True
        self.seed_classifier = self.seed
        self._reset_classifiers()
        self.areas = [seed_distance_area(255) if self.seed else NO_CONTACT] * SONAR_COUNT
        self.distances = [255] * SONAR_COUNT
        self.behaviours = [0] * SONAR_COUNT
        self.sweep = 0
        self.sweep_period_ms = SONAR_COUNT * SONAR_SLOT_MS
        self.last_stamp: float | None = None
        self.intervals: list[float] = []

    def _reset_classifiers(self) -> None:
        self.classifiers = [make_classifier(self.seed_classifier) for _ in range(SONAR_COUNT)]

    def run(self) -> None:
        if self.seed:
            self._run_seed()
            return
        next_ms = self.clock.now_ms()
        while self.running:
            self._measure()
            next_ms = self._wait_until(next_ms + self.sweep_period_ms)

    def _run_seed(self) -> None:
        """Seed §4.3.2's main loop: for pair 0..7 measure, area, classify, write the channel."""
        next_ms = self.clock.now_ms()
        while self.running:
            for pair in range(SONAR_COUNT):
                if not self.running:
                    return
                self._measure_pair(pair)
                next_ms = self._wait_until(next_ms + SONAR_SLOT_MS)

    def _wait_until(self, next_ms: float) -> float:
        """Take commands until simulated ``next_ms``; returns when the next measurement is due."""
        now = self.clock.now_ms()
        if next_ms < now:  # running late (a slow machine at a high speed-up): no catch-up burst
            next_ms = now
        while self.running:
            remaining = self.clock.to_real((next_ms - self.clock.now_ms()) / 1000.0)
            command = self.os.receive_command(timeout=max(0.0, remaining))
            if command is None:
                break
            self._handle(command)
        return next_ms

    def _handle(self, cmd) -> None:
        if cmd.name == "SET_METHOD":
            self.tangent = bool(cmd.args["tangent"])
            seed = bool(cmd.args["seed_classifier"])
            if seed != self.seed_classifier:
                self.seed_classifier = seed
                self._reset_classifiers()
            log.info(
                "sonar: %s contact, %s classifier",
                "tangent" if self.tangent else "threshold",
                "seed" if seed else "trend",
            )
        else:
            log.info("sonar: ignoring %s from node %d", cmd.name, cmd.sender)

    def _measure(self) -> None:
        envelopes, stamps = self.hw.ping(list(range(SONAR_COUNT)), PING_SAMPLES, SONAR_SLOT_MS)
        contact = contact_method(self.tangent, seed=False)
        for i, samples in enumerate(envelopes):
            cm = contact(samples)
            self.distances[i] = cm
            self.areas[i] = distance_area(cm, self.areas[i])
            self.behaviours[i] = self.classifiers[i].observe(cm)
        self.sweep = (self.sweep + 1) & 0xFFFF
        if self.last_stamp is not None:
            self.intervals = [*self.intervals[-49:], stamps[0] - self.last_stamp]
        self.last_stamp = stamps[0]
        self.out.write(
            distances=self.distances,
            behaviours=self.behaviours,
            areas=self.areas,
            sweep=self.sweep,
            stamp_ms=int(stamps[0]) & 0xFFFFFFFF,
        )

    def _measure_pair(self, pair: int) -> None:
        """One pair as the seed measured it, then its values into the data channel (seed §4.3.2:
        "Struktur sperren; Messwert, Abstandsbereich, Verhalten eintragen; Struktur freigeben")."""
        envelopes, stamps = self.hw.ping([pair], PING_SAMPLES, SONAR_SLOT_MS)
        cm = contact_method(self.tangent, seed=True)(envelopes[0])
        self.distances[pair] = cm
        self.areas[pair] = seed_distance_area(cm)
        self.behaviours[pair] = self.classifiers[pair].observe(cm)
        if pair == 0:
            if self.last_stamp is not None:
                self.intervals = [*self.intervals[-49:], stamps[0] - self.last_stamp]
            self.last_stamp = stamps[0]
        if pair == SONAR_COUNT - 1:
            self.sweep = (self.sweep + 1) & 0xFFFF
        self.out.write(
            distances=self.distances,
            behaviours=self.behaviours,
            areas=self.areas,
            sweep=self.sweep,
            stamp_ms=int(self.last_stamp or 0) & 0xFFFFFFFF,
        )

    def report(self) -> dict:
        intervals = sorted(self.intervals)
        return {
            "distances": list(self.distances),
            "behaviours": list(self.behaviours),
            "areas": list(self.areas),
            "sweeps": self.sweep,
            "algorithm": "seed" if self.seed else "ours",
            "tangent": self.tangent,
            "seed_classifier": self.seed_classifier,
            "sweep_interval_ms": intervals[len(intervals) // 2] if intervals else None,
        }
