"""The suite's sections, in the order they run and appear in bench/RESULTS.md, and what of each
is a sample (kept in the raw record only) and what its summary keeps.

The suite (bench/suite.py) writes both files of a run, the report (bench/report.py) reads both:
the functions here, shared by the two, import neither."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

SECTIONS = (
    "scaling",
    "transports",
    "runtime",
    "load",
    "commands",
    "profile",
    "recovery",
    "download",
    "spurious",
)
#: run only when named in ``--sections`` (RESULTS.md takes them from their latest run otherwise)
SLOW_SECTIONS = ("spurious",)
QUICK_SECTIONS = ("scaling", "transports", "commands", "profile")

#: per section, the keys of its records (``runs`` or ``scenarios``) that hold samples: one value
#: per round (round trips, in s) or per command; kept in the raw file only
RAW_KEYS: dict[str, tuple[str, ...]] = {
    "scaling": ("rounds_s", "bare_rounds_s"),
    "transports": ("rounds_s",),
    "load": ("rounds_s",),
    "commands": ("samples",),
    "profile": ("rounds_s",),
}
RECORD_LISTS = ("runs", "scenarios")
#: the per-window lists of a scaling record's ``interleaved`` windows (tokenring/perf/interleaved_pairs.py): its
#: summary keeps the pairs' shares and steal only
INTERLEAVED_RAW_KEYS = ("ring_medians_ms", "bare_medians_ms", "ring_rounds", "bare_rounds", "ring_measured_s")
RAW_DIR = "raw"  # under the results directory, git-ignored


def raw_path(path: Path) -> Path:
    """Where the raw record of the summary at ``path`` is: ``<dir>/raw/<name>``."""
    return path.parent / RAW_DIR / path.name


def sample_stats(rounds_s: list[float]) -> dict[str, float]:
    """The quantiles of stored round trips (ms) that the report shows besides ``rtt_ms``: computed
    from the samples as stored (rounded to 0.1 µs), p10 included."""
    values = np.asarray(rounds_s, float) * 1e3
    if not len(values):
        return {"median": float("nan"), "p10": float("nan"), "p90": float("nan"), "max": float("nan"), "n": 0}
    return {
        "median": float(np.median(values)),
        "p10": float(np.percentile(values, 10)),
        "p90": float(np.percentile(values, 90)),
        "max": float(np.max(values)),
        "n": len(values),
    }


def summary_section(name: str, section: dict[str, Any]) -> dict[str, Any]:
    """``section`` without its samples (see ``RAW_KEYS``); a record that had round trips gets
    their ``rounds_ms`` quantiles instead. A summary is returned unchanged."""
    keys = RAW_KEYS.get(name, ())
    if not keys or not isinstance(section, dict):
        return section
    out = dict(section)
    for field in RECORD_LISTS:
        records = section.get(field)
        if not isinstance(records, list):
            continue
        compact = []
        for record in records:
            if not isinstance(record, dict):
                compact.append(record)
                continue
            slim = {k: v for k, v in record.items() if k not in keys}
            if isinstance(record.get("interleaved"), dict):
                slim["interleaved"] = {
                    k: v for k, v in record["interleaved"].items() if k not in INTERLEAVED_RAW_KEYS
                }
            if "rounds_s" in keys and "rounds_s" in record:
                slim["rounds_ms"] = sample_stats(record["rounds_s"])
            compact.append(slim)
        out[field] = compact
    return out


def summary_of(results: dict[str, Any]) -> dict[str, Any]:
    """A suite run's summary: everything RESULTS.md's tables need (medians, percentiles, the bare
    rings' baselines, ratios, counts, the machine and its load), no per-round samples."""
    out = {k: v for k, v in results.items() if k != "sections"}
    out["sections"] = {name: summary_section(name, s) for name, s in results.get("sections", {}).items()}
    return out


def has_samples(name: str, section: Any) -> bool:
    """Whether ``section`` still carries the samples a summary drops (a raw record's section)."""
    keys = RAW_KEYS.get(name, ())
    return isinstance(section, dict) and any(
        isinstance(r, dict) and any(k in r for k in keys)
        for field in RECORD_LISTS
        for r in (section.get(field) if isinstance(section.get(field), list) else [])
    )
