"""The sonar module (seed §4.3.2): sweeps the eight transmitter/receiver pairs and publishes
distances, behaviours and distance areas.

Each sweep pings pair 0..7 one after another, 15 simulated ms apart (120 ms per sweep, 8.3 Hz),
reads each pair's 510-sample echo envelope from the hardware and finds the contact with the
threshold + tangent method (SET_METHOD tangent=0: plain thresholding, for comparison), ÷3 -> cm,
255 = no contact. Then the distance area (overlaps read as hysteresis) and the behaviour per
pair: ours by default, the seed's classifier (with its PROGRESSIVE/DEGRESSIVE jump) with
SET_METHOD seed_classifier=1. ``stamp_ms`` is when pair 0 was pinged; pair i was pinged
``15 i`` ms later.
"""

from __future__ import annotations

import logging

from modules.common.sonar import (
    NO_CONTACT,
    contact_tangent,
    contact_threshold,
    distance_area,
    make_classifier,
)
from modules.description.robot import SONAR_COUNT, SONAR_SLOT_MS
from tokenring.program import UserProgram

log = logging.getLogger("tokenring.sonar")
PING_SAMPLES = 60  # the transmitter's burst: 1.2 ms


class Program(UserProgram):
    module = "sonar"

    def setup(self) -> None:
        self.out = self.os.publish()
        self.os.set_own_input_id()
        self.clock = self.hw.clock
        self.tangent = True
        self.seed_classifier = False
        self._reset_classifiers()
        self.areas = [NO_CONTACT] * SONAR_COUNT
        self.distances = [255] * SONAR_COUNT
        self.behaviours = [0] * SONAR_COUNT
        self.sweep = 0
        self.sweep_period_ms = SONAR_COUNT * SONAR_SLOT_MS
        self.last_stamp: float | None = None
        self.intervals: list[float] = []

    def _reset_classifiers(self) -> None:
        self.classifiers = [make_classifier(self.seed_classifier) for _ in range(SONAR_COUNT)]

    def run(self) -> None:
        next_ms = self.clock.now_ms()
        while self.running:
            self._measure()
            next_ms += self.sweep_period_ms
            now = self.clock.now_ms()
            if next_ms < now:  # running late (a slow machine at a high speed-up): no catch-up burst
                next_ms = now
            while self.running:
                remaining = self.clock.to_real((next_ms - self.clock.now_ms()) / 1000.0)
                command = self.os.receive_command(timeout=max(0.0, remaining))
                if command is None:
                    break
                self._handle(command)

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
        contact = contact_tangent if self.tangent else contact_threshold
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

    def report(self) -> dict:
        intervals = sorted(self.intervals)
        return {
            "distances": list(self.distances),
            "behaviours": list(self.behaviours),
            "areas": list(self.areas),
            "sweeps": self.sweep,
            "tangent": self.tangent,
            "seed_classifier": self.seed_classifier,
            "sweep_interval_ms": intervals[len(intervals) // 2] if intervals else None,
        }
