"""lopscpp, the LOPS PC's program (seed 000 §6.2.5): times → distances → position → filter → packet.

* ``Entfernung = Laufzeit · Signalgeschwindigkeit + Offset`` per receiver (:func:`distances`);
* the position RP_mess by trilateration (:func:`trilaterate`, after Kleinschmidt 2002): the
  closed form from three circles. Subtracting the first circle's equation from the other two
  leaves two linear equations in x and y, whose one solution is the circles' radical centre:
  exact for consistent distances, no start value, no iteration. Three distances in the plane are
  one more than two unknowns need; that one redundancy tells whether they agree (the residuals),
  and a measurement whose residual is too large has no position (the seed: "dass keine Position
  berechnet werden kann"). With ``Gewichten`` a weighted least-squares refinement follows;
* the outlier filter (:class:`PositionFilter`) with RP_alt, RP_neu and dist_ok;
* the packet (:class:`~modules.lops.packets.DataPacket`) and lopscpp's messages.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from modules.lops.config import LopsConfig, Point
from modules.lops.packets import DataPacket, MessagePacket

#: why a measurement has no position
POSITION, NO_SIGNAL, INCONSISTENT, FILTERED, NO_GEOMETRY = (
    "position",
    "no-signal",
    "inconsistent",
    "filtered",
    "no-geometry",
)
#: a receiver that hears nothing this many triggers in a row gets a message (and one when back)
SILENT_TRIGGERS = 10


def distances(
    times_us: tuple[float | None, ...], slopes: tuple[float, ...], offsets: tuple[float, ...]
) -> tuple[float | None, ...]:
    """``Entfernung = Laufzeit · Signalgeschwindigkeit + Offset`` per receiver, mm (None: no time)."""
    return tuple(None if t is None else t * s + o for t, s, o in zip(times_us, slopes, offsets, strict=True))


def trilaterate(receivers: tuple[Point, Point, Point], dist: tuple[float, float, float]) -> Point | None:
    """RP_mess: the radical centre of the circles of radius ``dist`` around the receivers (the
    closed form); None when the receivers stand (nearly) in a line."""
    (x1, y1), (x2, y2), (x3, y3) = receivers
    d1, d2, d3 = dist
    # |p − r_i|² − |p − r_1|² = d_i² − d_1²  →  2 (r_1 − r_i) · p = d_i² − d_1² − |r_i|² + |r_1|²
    a = np.array([[x1 - x2, y1 - y2], [x1 - x3, y1 - y3]], dtype=float) * 2.0
    k1 = x1 * x1 + y1 * y1
    b = np.array([d2 * d2 - d1 * d1 - (x2 * x2 + y2 * y2) + k1, d3 * d3 - d1 * d1 - (x3 * x3 + y3 * y3) + k1])
    det = float(np.linalg.det(a))
    scale = float(np.abs(a).max()) ** 2
    if scale == 0.0 or abs(det) < 1e-9 * scale:
        return None
    x, y = np.linalg.solve(a, b)
    return (float(x), float(y))


def residuals(receivers: tuple[Point, ...], dist: tuple[float, ...], p: Point) -> np.ndarray:
    """Per receiver: the distance from ``p`` minus the measured one, mm."""
    r = np.asarray(receivers, dtype=float)
    return np.hypot(r[:, 0] - p[0], r[:, 1] - p[1]) - np.asarray(dist, dtype=float)


def refine_weighted(
    receivers: tuple[Point, ...], dist: tuple[float, ...], start: Point, iterations: int = 5
) -> Point:
    """``Gewichten``: Gauss–Newton on the three ranges from ``start``, each weighted by 1/d²
    (ours: the seed does not say how it weighted; a far receiver's weaker sound is trusted less)."""
    r = np.asarray(receivers, dtype=float)
    d = np.asarray(dist, dtype=float)
    w = 1.0 / np.maximum(d, 1.0) ** 2
    p = np.array(start, dtype=float)
    for _ in range(iterations):
        diff = p[None, :] - r
        rng = np.maximum(np.hypot(diff[:, 0], diff[:, 1]), 1e-9)
        jac = diff / rng[:, None]
        res = rng - d
        jw = jac * w[:, None]
        try:
            step = np.linalg.solve(jac.T @ jw, -(jw.T @ res))
        except np.linalg.LinAlgError:
            break
        p = p + step
        if float(np.hypot(*step)) < 1e-6:
            break
    return (float(p[0]), float(p[1]))


@dataclass(frozen=True)
class Verdict:
    """The filter's judgement of one RP_mess: the estimate RP̂_akt and dist_ok (None while the
    history is still filling: then every position is taken)."""

    accepted: bool
    estimate: Point | None = None
    distance: float = 0.0
    dist_ok: float | None = None


class PositionFilter:
    """lopscpp's outlier filter (§6.2.5), exactly as the seed describes it.

    The last ``Historienlänge`` accepted positions are kept with their times. RP_alt is the mean
    of the older half, RP_neu the mean of the newer half, t_alt and t_neu their mean times. The
    robot is assumed to move uniformly in a straight line:
    ``RP̂_akt = RP_alt + (t_akt − t_alt) / (t_neu − t_alt) · (RP_neu − RP_alt)``; a measured
    RP_mess farther from RP̂_akt than the Vertrauensabstand ``dist_ok = (t_akt − t_alt) · Grundwert``
    is rejected. The older the history, the larger dist_ok: after a run of rejections the filter
    widens — but only while the extrapolated track moves slower than ``Grundwert``: a history
    holding an outlier extrapolates a fast track that outruns dist_ok for ever. A rejected
    position does not enter the history. How the filter starts and recovers the seed does not
    say; here, until the history is full, positions are taken unjudged, and when as many
    positions in a row as the history is long were rejected while the track it extrapolates runs
    at ``Grundwert`` or faster (so that widening can never catch up), the history starts again
    from the newest one (:attr:`restarts`). With an odd length the older half is the smaller.
    """

    def __init__(self, history_length: int, grundwert: float) -> None:
        if history_length < 2:
            raise ValueError("the filter needs a history of at least two positions")
        self.history: deque[tuple[float, float, float]] = deque(maxlen=history_length)
        self.grundwert = grundwert
        self.rejected_in_row = 0
        self.restarts = 0

    def estimate(self, t_akt: float) -> tuple[Point, float] | None:
        """RP̂_akt at ``t_akt`` and t_alt, or None while the history is not full."""
        if len(self.history) < (self.history.maxlen or 0):
            return None
        h = np.asarray(self.history, dtype=float)
        half = len(h) // 2
        alt, neu = h[:half].mean(axis=0), h[half:].mean(axis=0)
        t_alt, t_neu = float(alt[0]), float(neu[0])
        f = (t_akt - t_alt) / (t_neu - t_alt)
        return (float(alt[1] + f * (neu[1] - alt[1])), float(alt[2] + f * (neu[2] - alt[2]))), t_alt

    def track_speed(self) -> float:
        """How fast RP̂_akt moves (mm/ms): RP_alt to RP_neu over t_alt to t_neu (0 while filling)."""
        if len(self.history) < (self.history.maxlen or 0):
            return 0.0
        h = np.asarray(self.history, dtype=float)
        half = len(h) // 2
        alt, neu = h[:half].mean(axis=0), h[half:].mean(axis=0)
        span = float(neu[0] - alt[0])
        return math.hypot(neu[1] - alt[1], neu[2] - alt[2]) / span if span > 0 else math.inf

    def judge(self, t_akt: float, rp_mess: Point) -> Verdict:
        """Take or reject RP_mess measured at ``t_akt`` (ms); a taken one joins the history."""
        found = self.estimate(t_akt)
        if found is None:
            self.history.append((t_akt, *rp_mess))
            return Verdict(True)
        estimate, t_alt = found
        dist_ok = (t_akt - t_alt) * self.grundwert
        distance = math.hypot(rp_mess[0] - estimate[0], rp_mess[1] - estimate[1])
        accepted = distance <= dist_ok
        if accepted:
            self.history.append((t_akt, *rp_mess))
            self.rejected_in_row = 0
        else:
            self.rejected_in_row += 1
            if self.rejected_in_row >= (self.history.maxlen or 0) and self.track_speed() >= self.grundwert:
                self.history.clear()  # the track was wrong: start again from what is measured now
                self.history.append((t_akt, *rp_mess))
                self.rejected_in_row = 0
                self.restarts += 1
        return Verdict(accepted, estimate, distance, dist_ok)


@dataclass(frozen=True)
class Measurement:
    """One trigger processed: what goes into the packet, and why there is no position."""

    counter: int
    t_ms: float
    distances: tuple[float | None, float | None, float | None]
    rp_mess: Point | None  # the trilaterated position, before the filter
    position: Point | None  # what the packet carries: RP_mess if it passed
    reason: str
    verdict: Verdict | None = None

    def packet(self) -> DataPacket:
        x, y = self.position if self.position is not None else (None, None)
        return DataPacket(self.counter, self.distances, x, y)


class Lopscpp:
    """The LOPS PC's program: one :meth:`process` per MCU reading, counting the packets."""

    def __init__(self, config: LopsConfig) -> None:
        self.config = config
        self.filter = PositionFilter(config.history_length, config.grundwert)
        self.counter = 0
        self._silent = [0, 0, 0]
        self.messages: list[MessagePacket] = []  # waiting to be sent, oldest first

    def process(self, t_ms: float, times_us: tuple[float | None, float | None, float | None]) -> Measurement:
        """Distances, RP_mess, the filter; the measurement's packet has a position or none."""
        c = self.config
        d = distances(times_us, c.slopes, c.offsets)
        dist = (d[0], d[1], d[2])
        self._watch_receivers(dist)
        counter, self.counter = self.counter, self.counter + 1
        if any(v is None for v in dist):
            return Measurement(counter, t_ms, dist, None, None, NO_SIGNAL)
        known = (float(dist[0] or 0.0), float(dist[1] or 0.0), float(dist[2] or 0.0))
        rp = trilaterate(c.receivers, known)
        if rp is None:
            return Measurement(counter, t_ms, dist, None, None, NO_GEOMETRY)
        if c.weighting:
            rp = refine_weighted(c.receivers, known, rp)
        if float(np.abs(residuals(c.receivers, known, rp)).max()) > c.residual_tolerance_mm:
            return Measurement(counter, t_ms, dist, rp, None, INCONSISTENT)
        if not c.position_filter:
            return Measurement(counter, t_ms, dist, rp, rp, POSITION)
        restarts = self.filter.restarts
        verdict = self.filter.judge(t_ms, rp)
        if self.filter.restarts != restarts:
            self.messages.append(
                MessagePacket(
                    f"W position filter restarted: {c.history_length} positions in a row off its track"
                )
            )
        if not verdict.accepted:
            return Measurement(counter, t_ms, dist, rp, None, FILTERED, verdict)
        return Measurement(counter, t_ms, dist, rp, rp, POSITION, verdict)

    def take_messages(self) -> list[MessagePacket]:
        """The messages since the last call (the seed forwards lopscpp's errors to the robot)."""
        out, self.messages = self.messages, []
        return out

    def _watch_receivers(self, dist: tuple[float | None, ...]) -> None:
        for i, value in enumerate(dist):
            if value is None:
                self._silent[i] += 1
                if self._silent[i] == SILENT_TRIGGERS:
                    self.messages.append(
                        MessagePacket(f"W receiver {i + 1}: no signal for {SILENT_TRIGGERS} triggers")
                    )
            else:
                if self._silent[i] >= SILENT_TRIGGERS:
                    self.messages.append(MessagePacket(f"I receiver {i + 1}: signal again"))
                self._silent[i] = 0
