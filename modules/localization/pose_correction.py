"""main's self-localisation corrects the motor: SET_GLOBAL_POSITION with the filtered pose.

Seed §4.3 item 5: "Während die aktuelle und fortlaufende Positionsschätzung Aufgabe der
Motorsteuerung ist, wird die Selbstlokalisierung dem Hauptrechner zufallen", and §4.3.3 gives the
motor SET_GLOBAL_POSITION for it ("eine Korrektur der geschätzten Position"). Today the best pose
is copro's filter (``copro.data``: ``pose_*``, ``sigma_*``); :class:`PoseCorrector` decides, from
``motor.data`` and ``copro.data`` as main reads them, when main hands that pose to the motor:

* only between moves — the motor at rest (IDLE, STOPPED) and main's pilot idle: the seed's motor
  aborts a move on any other command (§4.3.3), so a correction never goes out mid-move;
* only when the filter is confident (EKF source, all coordinates valid, its standard deviations
  known and small) and the motor's dead reckoning is off by more than a threshold;
* the filter's pose is carried from its own time stamp to the motor's newest sample by the
  dead-reckoned motion in between (the filter lags the motor by a synchronisation), as copro
  carries it for its sweeps.

The jump in ``motor.data`` is never read as motion: the filter and the compass integrate the
cumulative step counters, which SET_GLOBAL_POSITION leaves alone; only ``x_mm``/``y_mm``/``angle``
jump. Copro does carry its filter pose over motor.data's pose history, so after a correction the
corrector *holds* (main plans no move) until the motor shows the new pose and copro's filter has
synchronised past that sample — no sweep is then carried across the jump.

``$TOKENRING_SETPOS=off`` switches the corrections off (both modes).
"""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from modules.mapping.vectorgen import PoseHistory
from modules.units import pose_from_wire, pose_to_wire
from tokenring import default_protocol

log = logging.getLogger("tokenring.main")

_E = default_protocol().enums
MOTOR_IDLE = _E["motor_state"]["IDLE"]
DIRECTION_STOPPED = _E["direction"]["STOPPED"]
POSE_EKF = 2  # copro.data pose_source: 0 none, 1 dead reckoning, 2 EKF
ALL_VALID = 0b111  # copro.data pose_valid: x, y and angle
ENV = "TOKENRING_SETPOS"


@dataclass(frozen=True)
class CorrectionSettings:
    """When the filter is confident enough, and the motor far enough off, to correct it."""

    enabled: bool = True
    max_sigma_mm: float = 60.0  # each of the filter's x and y standard deviations at most this
    max_sigma_deg: float = 3.0  # and its heading's
    min_offset_mm: float = 40.0  # correct when the motor is further off than this ...
    min_offset_deg: float = 3.0  # ... or its heading is
    timeout_ms: int = 3000  # motor time to wait for the motor, then the filter, to show it

    @classmethod
    def from_env(cls) -> CorrectionSettings:
        """The defaults; ``$TOKENRING_SETPOS=off`` (or 0, no) disables the corrections."""
        off = os.environ.get(ENV, "").strip().lower() in ("off", "0", "no", "false")
        return cls(enabled=not off)


def _angle_cdeg_diff(a: int, b: int) -> int:
    """|a - b| of two wire angles (1/100 degree) along the shorter arc."""
    d = (int(a) - int(b)) % 36000
    return min(d, 36000 - d)


class PoseCorrector:
    """Decides main's SET_GLOBAL_POSITION commands (see the module docstring); no ring inside.

    Every token visit: :meth:`observe` with the two channels; between moves :meth:`correction`
    (the arguments of one SET_GLOBAL_POSITION, or None). While :attr:`holding`, main plans no move.
    """

    def __init__(self, settings: CorrectionSettings | None = None) -> None:
        self.settings = settings or CorrectionSettings()
        self.history = PoseHistory()
        self.target: dict[str, int] | None = None  # the pose sent, until motor and filter show it
        self.sent_ms = 0
        self.applied_ms: int | None = None  # motor stamp of the first sample at the new pose
        self.sent = 0
        self.gave_up = 0

    @property
    def holding(self) -> bool:
        """A correction is under way: the motor or the filter has not caught up with it yet."""
        return self.target is not None

    def observe(self, motor: Mapping[str, Any], copro: Mapping[str, Any]) -> None:
        """Record motor.data's pose; follow a correction under way."""
        stamp = int(motor["stamp_ms"])
        pose = pose_from_wire(motor["x_mm"], motor["y_mm"], motor["angle_cdeg"])
        target = self.target
        if target is not None and self.applied_ms is None and self._shows(motor, target):
            self.applied_ms = stamp
            self.history = PoseHistory()  # nothing carried across the jump
        self.history.add(stamp, pose)
        if target is None:
            return
        if self.applied_ms is not None and int(copro["pose_stamp_ms"]) >= self.applied_ms:
            self.target, self.applied_ms = None, None
        elif stamp - self.sent_ms > self.settings.timeout_ms:
            self.gave_up += 1
            log.warning(
                "SET_GLOBAL_POSITION %s not %s within %d ms",
                target,
                "taken by the motor" if self.applied_ms is None else "seen by the filter",
                self.settings.timeout_ms,
            )
            self.target, self.applied_ms = None, None

    @staticmethod
    def _shows(motor: Mapping[str, Any], target: Mapping[str, int]) -> bool:
        return (
            abs(int(motor["x_mm"]) - target["x_mm"]) <= 1
            and abs(int(motor["y_mm"]) - target["y_mm"]) <= 1
            and _angle_cdeg_diff(motor["angle_cdeg"], target["angle_cdeg"]) <= 1
        )

    def confident(self, copro: Mapping[str, Any]) -> bool:
        """The filter's pose is the EKF's, valid in all three coordinates, its sigmas small."""
        s = self.settings
        sigmas = (int(copro["sigma_x_mm"]), int(copro["sigma_y_mm"]), int(copro["sigma_angle_cdeg"]))
        return (
            int(copro["pose_source"]) == POSE_EKF
            and int(copro["pose_valid"]) & ALL_VALID == ALL_VALID
            and all(v > 0 for v in sigmas)  # 0 = not known
            and sigmas[0] <= s.max_sigma_mm
            and sigmas[1] <= s.max_sigma_mm
            and sigmas[2] <= s.max_sigma_deg * 100.0
        )

    def correction(self, motor: Mapping[str, Any], copro: Mapping[str, Any]) -> dict[str, int] | None:
        """SET_GLOBAL_POSITION's arguments (x_mm, y_mm, angle_cdeg) if the motor should be
        corrected now, else None. Call with the pilot idle; a returned correction holds."""
        s = self.settings
        if not s.enabled or self.target is not None:
            return None
        if int(motor["state"]) != MOTOR_IDLE or int(motor["direction"]) != DIRECTION_STOPPED:
            return None  # never mid-move: the seed's motor would abort the move
        if not self.confident(copro):
            return None
        samples = self.history.samples
        if not samples or int(copro["pose_stamp_ms"]) < samples[0][0]:
            return None  # the filter's pose is older than the motion main can carry it over
        filtered = pose_from_wire(copro["pose_x_mm"], copro["pose_y_mm"], copro["pose_angle_cdeg"])
        now = self.history.carry(filtered, int(copro["pose_stamp_ms"]), int(motor["stamp_ms"]))
        target = pose_to_wire(*now)
        off_mm = math.hypot(target["x_mm"] - int(motor["x_mm"]), target["y_mm"] - int(motor["y_mm"]))
        off_cdeg = _angle_cdeg_diff(target["angle_cdeg"], motor["angle_cdeg"])
        if off_mm <= s.min_offset_mm and off_cdeg <= s.min_offset_deg * 100.0:
            return None
        self.target, self.sent_ms, self.applied_ms = target, int(motor["stamp_ms"]), None
        self.sent += 1
        log.info(
            "self-localisation: motor off by %.0f mm, %.1f°: SET_GLOBAL_POSITION %s",
            off_mm,
            off_cdeg / 100.0,
            target,
        )
        return target
