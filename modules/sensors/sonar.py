"""The sonar module's algorithms (seed §4.3.2): contact on the echo envelope, distance areas,
behaviour classification.

Contact: the seed's threshold + tangent method — find the first sample above the threshold, lay a
tangent through it and the sample before (two consecutive samples on the rising edge), intersect
it with the time axis, divide by 3 (three samples per cm) — and, for comparison, plain
thresholding, which reads late because the edge is flat (25 cm reads as about 28 cm).

Each step comes twice: the seed's as it was (:func:`contact_seed_tangent`,
:func:`seed_distance_area`, :class:`SeedClassifier`; ``--algorithms sonar=seed``) and ours
(:func:`contact_tangent`, :func:`distance_area`, :class:`TrendClassifier`);
:func:`contact_method` and :func:`make_classifier` pick one.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from modules.description.robot import SONAR_NO_CONTACT

DEFAULT_THRESHOLD = 40  # envelope counts (8-bit ADC)
SAMPLES_PER_CM = 3  # the seed's "divide by 3"
MAX_CONTACT_CM = 254  # 255 means no contact
SMOOTH = 5  # running mean over 5 samples before the tangent
SPAN = 2  # the tangent's two samples are this far apart
QUIET_MARGIN = 4.0  # counts above the envelope's floor that still count as "no echo yet"
QUIET_SLACK = 9  # samples (3 cm) the seed's tangent may land before the last quiet sample

# -- contact ----------------------------------------------------------------------------------------


def _first_above(samples: np.ndarray, threshold: int) -> int | None:
    above = np.flatnonzero(samples > threshold)
    return int(above[0]) if len(above) else None


def contact_threshold(samples: Sequence[int] | np.ndarray, threshold: int = DEFAULT_THRESHOLD) -> int:
    """Plain thresholding: the first sample above ``threshold``, ÷3 -> cm; 255 if none."""
    n = _first_above(np.asarray(samples, dtype=float), threshold)
    if n is None:
        return SONAR_NO_CONTACT
    return min(n // SAMPLES_PER_CM, MAX_CONTACT_CM)


def contact_tangent(samples: Sequence[int] | np.ndarray, threshold: int = DEFAULT_THRESHOLD) -> int:
    """Threshold + tangent: the tangent through the first sample above the threshold and a sample
    just before it, intersected with the time axis, ÷3 -> cm (rounded); 255 if no sample is above.

    The seed took two consecutive raw samples; on a noisy edge their difference is mostly noise, so
    the envelope is first smoothed (running mean of 5) and the two samples are 2 apart. A weak echo
    (an oblique post at the beam's edge) can peak just above the threshold: the slope there is
    nearly flat and the tangent lands far before the echo, down to 0 cm — a false ALERT. The echo
    cannot have begun while the envelope still sat at its noise floor, so when the tangent lands
    more than 3 cm before the last quiet sample, that sample is the contact (on the square hall's
    post it reads within 2 cm of the echo's start, where the tangent read 0-30 cm short)."""
    raw = np.asarray(samples, dtype=float)
    n = _first_above(raw, threshold)
    if n is None:
        return SONAR_NO_CONTACT
    smooth = np.convolve(raw, np.ones(SMOOTH) / SMOOTH, mode="same")
    k = max(n, SPAN)
    slope = (smooth[k] - smooth[k - SPAN]) / SPAN
    start = float(n) if slope <= 0 else max(0.0, min(float(n), k - smooth[k] / slope))
    quiet = _last_quiet(smooth, n)
    if quiet is not None and start < quiet - QUIET_SLACK:
        start = float(quiet)
    return min(round(start / SAMPLES_PER_CM), MAX_CONTACT_CM)


def contact_seed_tangent(samples: Sequence[int] | np.ndarray, threshold: int = DEFAULT_THRESHOLD) -> int:
    """The seed's ``calc_contact`` (seed §4.3.2) as it was: the first sample ``n`` above the
    threshold, the tangent through the raw samples ``n - 1`` and ``n`` ("zweier
    aufeinanderfolgender Meßwerte"), its zero crossing ``n - s[n] / (s[n] - s[n-1])``, ÷3 -> cm
    (truncated, as the plain threshold's ÷3); 255 if no sample is above.

    Noise on the edge goes straight into the slope: a couple of counts on ``s[n-1]`` move the
    reading by centimetres. The seed leaves two cases open, read here as a byte distance must: a
    tangent landing before the ping reads 0 cm, and an envelope above the threshold from its
    first sample on (no sample before it) reads 0 cm. ``s[n-1] <= threshold < s[n]``, so the
    slope is never zero."""
    raw = np.asarray(samples, dtype=float)
    n = _first_above(raw, threshold)
    if n is None:
        return SONAR_NO_CONTACT
    if n == 0:
        return 0
    start = n - raw[n] / (raw[n] - raw[n - 1])
    return min(int(max(0.0, start)) // SAMPLES_PER_CM, MAX_CONTACT_CM)


class ContactMethod(Protocol):
    """A contact function: echo envelope (and threshold) -> cm, 255 = no contact."""

    def __call__(self, samples: Sequence[int] | np.ndarray, threshold: int = DEFAULT_THRESHOLD) -> int: ...


def contact_method(tangent: bool, seed: bool) -> ContactMethod:
    """The contact function: plain thresholding (``tangent=False``, the same in both modes), the
    seed's two-sample tangent (``seed=True``) or ours."""
    if not tangent:
        return contact_threshold
    return contact_seed_tangent if seed else contact_tangent


def _last_quiet(smooth: np.ndarray, n: int) -> int | None:
    """The last sample before ``n`` at which the smoothed envelope was still at its noise floor."""
    lead = smooth[SMOOTH // 2 : n + 1]  # the running mean's first samples are padded with zeros
    if len(lead) == 0:
        return None
    quiet = np.flatnonzero(lead <= float(np.min(lead)) + QUIET_MARGIN)
    return int(quiet[-1]) + SMOOTH // 2


# -- distance areas ---------------------------------------------------------------------------------

ALERT, CLOSE, NEAR, MIDDLE, FAR, NO_CONTACT = range(6)
#: the seed's areas (cm, inclusive); they overlap: CLOSE 4-12 and NEAR 10-30, NEAR and MIDDLE 25-65 ...
SEED_AREAS = ((ALERT, 0, 4), (CLOSE, 4, 12), (NEAR, 10, 30), (MIDDLE, 25, 65), (FAR, 60, 254))
#: our rule without history: an area ends where the next one begins (ALERT < 4 <= CLOSE < 10 ...)
AREA_UPPER = ((ALERT, 4), (CLOSE, 10), (NEAR, 25), (MIDDLE, 60), (FAR, 255))


def distance_area(cm: int, previous: int | None = None) -> int:
    """The distance area of a reading. The seed's areas overlap; we read the overlaps as hysteresis:
    a reading stays in the ``previous`` area as long as it is inside that area's seed range;
    otherwise (and without history) the nearest area takes it (boundaries 4, 10, 25, 60 cm)."""
    if cm >= SONAR_NO_CONTACT:
        return NO_CONTACT
    if previous is not None and previous != NO_CONTACT:
        _, lo, hi = SEED_AREAS[previous]
        if lo <= cm <= hi:
            return previous
    for area, upper in AREA_UPPER:
        if cm < upper:
            return area
    return FAR


def seed_distance_area(cm: int) -> int:
    """The seed's ``calc_distance_area(distance)`` (seed §4.3.2): the areas in the seed's order,
    the first whose range holds the reading takes it (bounds inclusive: ALERT 0-4, CLOSE 5-12,
    NEAR 13-30, MIDDLE 31-65, FAR 66-255). The seed's function sees only the distance, so the
    overlaps cannot be hysteresis; FAR runs to 255, so no contact reads FAR (the seed has no
    NO_CONTACT area)."""
    for area, _lo, hi in SEED_AREAS[:-1]:
        if cm <= hi:
            return area
    return FAR


# -- behaviour --------------------------------------------------------------------------------------

NONE, LINEAR, PROGRESSIVE, DEGRESSIVE = range(4)
BEHAVIOUR_NAMES = ("NONE", "LINEAR", "PROGRESSIVE", "DEGRESSIVE")


@dataclass
class SeedClassifier:
    """The seed's ``observe_sensor`` (seed §4.3.2): first and second differences of consecutive
    readings.

    LINEAR if the second difference is 0 within ``tolerance``, DEGRESSIVE if it is larger,
    PROGRESSIVE if smaller; NONE without contact or history. It reproduces the seed's flaw: after
    a jump the next steady reading has a large negative second difference and reads PROGRESSIVE.
    The seed names no tolerance ("ein gewisser Fehler") and does not say whether a reading without
    contact ends the history; here it does (the differences restart after it)."""

    tolerance: int = 3
    history: list[int] = field(default_factory=list)

    def observe(self, cm: int) -> int:
        if cm >= SONAR_NO_CONTACT:
            self.history.clear()
            return NONE
        self.history = [*self.history[-2:], cm]
        if len(self.history) < 3:
            return NONE
        a, b, c = self.history
        second = (c - b) - (b - a)
        if abs(second) <= self.tolerance:
            return LINEAR
        return DEGRESSIVE if second > 0 else PROGRESSIVE


@dataclass
class TrendClassifier:
    """Ours: a jump is judged against the trend of the readings since the last jump, and a jump
    starts a new segment — so the readings after a jump are compared with each other, never with
    the jump itself (the seed's PROGRESSIVE/DEGRESSIVE flip cannot happen).

    LINEAR when the newest difference matches the segment's trend within ``tolerance`` (needs two
    differences), PROGRESSIVE on a drop beyond it (an object appears), DEGRESSIVE on a rise beyond
    it or when the contact is lost (an object disappears), NONE without contact or while a new
    segment is too short."""

    tolerance: int = 5
    segment: list[int] = field(default_factory=list)

    def observe(self, cm: int) -> int:
        if cm >= SONAR_NO_CONTACT:
            lost = bool(self.segment)
            self.segment.clear()
            return DEGRESSIVE if lost else NONE
        if not self.segment:
            self.segment.append(cm)
            return NONE
        step = cm - self.segment[-1]
        diffs = np.diff(self.segment[-4:]) if len(self.segment) >= 2 else np.zeros(0)
        trend = float(np.mean(diffs)) if len(diffs) else 0.0
        if abs(step - trend) > self.tolerance and (len(diffs) or abs(step) > self.tolerance):
            self.segment = [cm]
            return PROGRESSIVE if step - trend < 0 else DEGRESSIVE
        self.segment = [*self.segment[-7:], cm]
        return LINEAR if len(self.segment) >= 3 else NONE


def make_classifier(seed: bool) -> SeedClassifier | TrendClassifier:
    """The seed's classifier (``seed=True``, with its flaw) or ours."""
    return SeedClassifier() if seed else TrendClassifier()
