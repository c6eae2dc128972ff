"""The compass's calibration turn as main's navigator drives it (seed 001 §4.3: the compass's turn
goes through main's pilot; the compass only listens).

:class:`CompassCalibration` tells the compass to listen (its CALIBRATE_LISTEN with the number of
stops), waits until compass.data says CALIBRATING, then has the pilot turn the robot on the spot
in 45° turns. After each turn it waits at rest until the compass has published
:data:`DWELL_SAMPLES` more samples (the compass takes its readings at rest at each stop it sees on
motor.data; it needs three proven at rest, and motor.data and compass.data each reach main a
token round late), then turns on. The compass counts the stops itself: once it leaves
CALIBRATING (OK: calibrated, after its eighth stop) the run is over; still CALIBRATING
:data:`PATIENCE` dwells after the eighth turn, it missed a stop (a turn that never ran), and the
robot turns on, at most :data:`EXTRA_TURNS` more times. A turn stopped for ALERT, a collision or
a stall ends the run (one stopped for taking too long is a stop like any other), as does a wait
longer than ``timeout_ms`` of simulated time; the compass is then told to stop listening.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from modules.mapping.vectorgen import SonarLayout
from modules.navigation.navigator import NAV, Navigator
from modules.navigation.pilot import REASON, TURN_LEFT, TURN_RIGHT, Move, Outcome, Sensors
from tokenring import default_protocol

COMPASS_STATE = default_protocol().enums["compass_state"]
COMPASS_STATE_NAMES = {v: k for k, v in COMPASS_STATE.items()}
STOPS = 8
DWELL_SAMPLES = 8  # compass samples (100 ms each) at rest after main saw a turn end
PATIENCE = 3  # after the last turn, dwells before the compass is taken to have missed a stop
EXTRA_TURNS = 4  # turns beyond ``stops`` for the stops the compass missed
TIMEOUT_MS = 120_000  # simulated ms any one wait may last


class CompassCalibration(Navigator):
    """Eight 45° turns on the spot with a wait at rest after each, for the listening compass."""

    mode = 4

    def __init__(
        self,
        layout: SonarLayout,
        stops: int = STOPS,
        speed_pct: int = 50,
        dwell_samples: int = DWELL_SAMPLES,
        timeout_ms: int = TIMEOUT_MS,
    ) -> None:
        super().__init__(layout)
        self.state = NAV["CALIBRATE"]
        self.stops = stops
        self.speed_pct = speed_pct
        self.dwell_samples = dwell_samples
        self.timeout_ms = timeout_ms
        self.phase = "ask"
        self.turns = 0
        self.direction = TURN_LEFT
        self.compass_state: int | None = None  # compass.data as main last copied it
        self.compass_sample: int | None = None
        self.mark_sample = 0
        self.since_ms = 0
        self.result: dict[str, Any] | None = None

    @property
    def listening(self) -> bool:
        """The compass was told to listen and not yet told to stop (nor seen done)."""
        return self.phase not in ("ask", "over")

    def observe_compass(self, data: Mapping[str, Any] | None) -> None:
        """compass.data as main copied it this visit (None: the compass has not spoken yet). A copy
        whose sample counter is behind the last one's (serial arithmetic: a token regenerated from
        an old copy) is left out: its state and count are the past."""
        if data is None:
            return
        sample = int(data["sample"]) & 0xFFFF
        if self.compass_sample is not None and (sample - self.compass_sample) & 0xFFFF >= 0x8000:
            return
        self.compass_state, self.compass_sample = int(data["state"]), sample

    def cancel(self) -> list[tuple[str, str, dict[str, int]]]:
        """What to send when main ends the run early: the compass stops listening."""
        if not self.listening:
            return []
        self.phase = "over"
        return [("compass", "CALIBRATE_LISTEN", {"stops": 0})]

    def plan(self, last: Outcome | None, sensors: Sensors, alert_lock: int) -> list[Move] | None:
        self.steps += 1
        calibrating = self.compass_state == COMPASS_STATE["CALIBRATING"]
        if self.phase == "ask":
            self.commands.append(("compass", "CALIBRATE_LISTEN", {"stops": self.stops}))
            self._wait_for("listening", sensors)
            return []
        if self.phase == "listening":
            if not calibrating:
                return self._waiting(sensors, "the compass did not start listening")
            if alert_lock in (TURN_LEFT, TURN_RIGHT):  # the only turn the pilot's ALERT lock allows
                self.direction = alert_lock
            return self._turn(sensors)
        if self.phase == "turning":
            if last is None or last.move is None:  # (not the turn's outcome)
                return self._waiting(sensors, "the calibration turn did not end")
            if not last.done and last.reason != REASON["TIMEOUT"]:  # something in the way
                return self._fail(f"calibration turn {self.turns + 1} ended {last.reason_name}")
            self.turns += 1  # (a turn stopped for taking too long is a stop too: the compass sees it)
            self._wait_for("dwell", sensors)
            self.mark_sample = self.compass_sample or 0
            return []
        if self.phase == "dwell":
            if not calibrating:  # seen CALIBRATING before: the compass has ended
                return self._finish()
            over = self.turns >= self.stops  # it still wants a stop: wait longer, then turn on
            wanted = self.dwell_samples * (PATIENCE if over else 1)
            if ((self.compass_sample or 0) - self.mark_sample) & 0xFFFF < wanted:
                return self._waiting(sensors, f"the compass sent no samples at stop {self.turns}")
            if self.turns >= self.stops + EXTRA_TURNS:
                return self._fail(f"the compass did not finish after {self.turns} turns")
            return self._turn(sensors)
        return None

    def _finish(self) -> list[Move] | None:
        name = COMPASS_STATE_NAMES.get(self.compass_state or 0, str(self.compass_state))
        self.phase = "over"
        self.state = NAV["DONE"]
        self.result = {"turns": self.turns, "compass_state": name}
        calibrated = self.compass_state in (COMPASS_STATE["OK"], COMPASS_STATE["DISTURBED"])
        if calibrated and self.turns >= self.stops:
            self.note = "compass calibrated"
        else:
            turns = f"{self.turns} turn{'' if self.turns == 1 else 's'}"
            self.note = f"the compass ended the turn {name} after {turns}"
        return None

    def _turn(self, sensors: Sensors) -> list[Move]:
        self._wait_for("turning", sensors)
        degrees = 360 // self.stops
        return [Move(self.direction, degrees, self.speed_pct, label=f"compass stop {self.turns + 1}")]

    def _wait_for(self, phase: str, sensors: Sensors) -> None:
        self.phase, self.since_ms = phase, sensors.stamp_ms

    def _waiting(self, sensors: Sensors, why: str) -> list[Move] | None:
        """An empty plan (wait at rest), or the end of the run once the wait took too long."""
        if sensors.stamp_ms - self.since_ms > self.timeout_ms:
            return self._fail(why)
        return []

    def _fail(self, why: str) -> list[Move] | None:
        self.commands += self.cancel()
        self.phase = "over"
        self.state = NAV["DONE"]
        self.result = {"turns": self.turns, "error": why}
        self.note = why
        return None
