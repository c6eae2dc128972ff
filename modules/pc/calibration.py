"""Odometry calibration: the floor's mean step scale pooled over earlier drives.

The floor's straight step is off its nominal length by a systematic factor (SPEC §5: +1 %) plus a
draw per move. The filter estimates the factor (``step_scale_mean``) only while a sonar measures
the distance driven — a wall ahead or behind within 1.5 m. A drive that keeps 1–2 m from every
wall never sees it, and its error then grows by the factor's whole error times the distance. A
real robot is calibrated once for its floor (UMBmark's square, the Darmstadt square): this pools
what earlier drives learnt, so a later drive can start from it (``filter.initial.step_scale``,
``step_scale_mean_sigma``).

Each drive's end estimate counts as one measurement of the floor, weighted by its σ. It still
holds some of the prior the drive began from (the nominal 1.0, or an earlier calibration), so
the pool errs toward that prior, never away from it; the prior cannot be taken out exactly, because the filter lets the
floor's mean walk a little per move and how much of the prior is left at the end is not known.
Drives that learnt next to nothing (σ still near the prior's) are left out — also every drive
that began from a calibration already, whose σ the floor's walk only widens: calibrate from drives
that began from the nominal step. Where the drives
disagree more than their σ say (the Birge ratio R > 1: floors that differ, a model error), the
pooled σ is widened by R.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tokenring import UsageError

#: a drive counts as having measured the floor when its σ at the end is at most this share of the
#: prior's (on the tuning drives: 0.75 kept 22 of 30, which had had a wall ahead on straight legs)
MAX_SIGMA_SHARE = 0.75


@dataclass(frozen=True)
class FloorEstimate:
    """One drive's end state: the floor's mean step scale and its σ, and the σ it began with."""

    name: str
    mean: float
    sigma: float
    prior_sigma: float


@dataclass
class FloorCalibration:
    """The pooled floor step scale; ``sigma`` is widened by ``birge_ratio`` where that exceeds 1."""

    step_scale: float
    sigma: float
    birge_ratio: float
    used: list[str] = field(default_factory=list)
    #: drives left out, with why (no wall measured the distance driven, a bad value)
    skipped: dict[str, str] = field(default_factory=dict)

    def as_dict(self) -> dict[str, object]:
        return {
            "step_scale": self.step_scale,
            "sigma": self.sigma,
            "birge_ratio": self.birge_ratio,
            "used": list(self.used),
            "skipped": dict(self.skipped),
        }


class CalibrationError(UsageError):
    """Nothing to calibrate from: no drive measured the distance it drove, or the logs cannot be
    pooled (a filter without the floor's mean, different nominal steps)."""


def measured(estimate: FloorEstimate) -> bool:
    """Whether the drive learnt the floor: finite values, its σ well under the prior's."""
    values = (estimate.mean, estimate.sigma, estimate.prior_sigma)
    if not all(math.isfinite(v) for v in values) or estimate.sigma <= 0 or estimate.prior_sigma <= 0:
        return False
    return estimate.sigma <= MAX_SIGMA_SHARE * estimate.prior_sigma


def pool(estimates: Iterable[FloorEstimate]) -> FloorCalibration:
    """The floor's step scale from the drives that measured it (see the module's docstring)."""
    used: list[FloorEstimate] = []
    skipped: dict[str, str] = {}
    for estimate in estimates:
        if measured(estimate):
            used.append(estimate)
        else:
            skipped[estimate.name] = (
                f"its σ ended at {estimate.sigma:.4f}, not under {MAX_SIGMA_SHARE} of the "
                f"{estimate.prior_sigma:.4f} it began with: it learnt too little of the floor"
            )
    if not used:
        raise CalibrationError(
            f"none of {len(skipped)} drive(s) learnt the floor: each one's σ stayed above "
            f"{MAX_SIGMA_SHARE} of the σ it began with (no wall ahead or behind in sonar range on a "
            "straight leg, or it began from a calibration already): nothing to calibrate from"
        )
    weights = [1.0 / e.sigma**2 for e in used]
    total = sum(weights)
    mean = sum(w * e.mean for w, e in zip(weights, used, strict=True)) / total
    birge = 1.0
    if len(used) > 1:
        chi2 = sum(w * (e.mean - mean) ** 2 for w, e in zip(weights, used, strict=True))
        birge = math.sqrt(chi2 / (len(used) - 1))
    return FloorCalibration(
        step_scale=mean,
        sigma=max(1.0, birge) / math.sqrt(total),
        birge_ratio=birge,
        used=[e.name for e in used],
        skipped=skipped,
    )


def estimate_from_log(path: str | Path) -> tuple[FloorEstimate, float]:
    """The floor estimate a localisation data log ends with, and the nominal step (mm) it is
    relative to. Raises :class:`CalibrationError` for a log whose filter had no such state."""
    from modules.localization.logs import read_log

    log = read_log(path, expect="data")
    config: Any = log.header.get("config")
    filter_config = config.get("filter") if isinstance(config, dict) else None
    if not isinstance(filter_config, dict) or "step_scale_mean" not in filter_config.get("estimate", []):
        raise CalibrationError(
            f"{path}: its filter did not estimate the floor's mean step scale "
            "(filter.estimate lacks step_scale_mean)"
        )
    initial = filter_config.get("initial", {})
    prior_sigma = float(initial.get("step_scale_mean_sigma", initial.get("step_scale_sigma", 0.02)))
    last = None
    for record in log.records:
        payload = record[3] if len(record) == 4 and record[1] == "K" and record[2] == "P" else None
        if isinstance(payload, dict) and "step_scale_mean_sigma" in payload:
            last = payload
    if last is None:
        raise CalibrationError(f"{path}: no filter position with the floor's step scale in it")
    mm_per_step = float(config.get("robot", {}).get("mm_per_step", 0.0))
    estimate = FloorEstimate(
        Path(path).name,
        float(last["step_scale_mean"]),
        float(last["step_scale_mean_sigma"]),
        prior_sigma,
    )
    return estimate, mm_per_step


def calibrate_logs(paths: Iterable[str | Path]) -> tuple[FloorCalibration, float]:
    """The floor's step scale pooled over data logs, and the nominal step (mm) it multiplies."""
    estimates: list[FloorEstimate] = []
    steps: dict[float, str] = {}
    for path in paths:
        estimate, mm_per_step = estimate_from_log(path)
        estimates.append(estimate)
        steps.setdefault(mm_per_step, str(path))
    if len(steps) > 1:
        named = ", ".join(f"{step} mm ({where})" for step, where in steps.items())
        raise CalibrationError(f"the logs' filters used different nominal steps: {named}")
    return pool(estimates), next(iter(steps))
