"""bench.seedtable: the seed-vs-ours figures it computes and the RESULTS.md section it renders."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from bench.seedreport import latest, section_md
from bench.seedtable import part_classifier


def test_the_classifier_part_reproduces_the_seeds_table_and_ours_does_not_jump() -> None:
    # seed 001 §4.3.2, the table under "Springen zwischen progressivem und degressivem Verhalten"
    documented = ["NONE", "NONE", "LINEAR", "DEGRESSIVE", "PROGRESSIVE", "LINEAR"]
    part = part_classifier(argparse.Namespace(), lambda _m: None)
    assert part["readings_cm"] == [30, 32, 34, 50, 50, 50]
    assert part["seed"] == documented
    assert part["ours"][4] != "PROGRESSIVE" and part["ours"][:4] == documented[:4]


def test_each_part_comes_from_the_latest_file_that_has_it(tmp_path: Path) -> None:
    def write(name: str, parts: dict) -> None:
        (tmp_path / name).write_text(json.dumps({"parts": parts}))

    roundtrip = {"nodes": 7, "runs": [{"algorithms": "seed", "median_ms": 31.04, "p10_ms": 27.5, "p90_ms": 36.0,
                                       "p99_ms": 44.2, "load": [1.5, 1.0, 0.5]}]}  # fmt: skip
    write("seedmode-2026-11-20.json", {"roundtrip": roundtrip, "classifier": {"old": True}})
    darmstadt = {
        "runs": [
            {"algorithms": "ours", "seed": s, "dead_reckoning_mm": dr, "filter_mm": f,
             "sync": {"median_ms": 100.0, "p99_ms": 104.0, "within_98_102": w, "within_95_105": 1.0}}
            for s, dr, f, w in ((1, 1500.0, 14.0, 0.9), (2, 540.0, 4.5, 0.8), (3, 430.0, 4.3, 0.7))
        ]
    }  # fmt: skip
    classifier = {
        "readings_cm": [30, 50],
        "seed_documented": ["NONE", "X"],
        "seed": ["NONE", "X"],
        "ours": ["NONE", "Y"],
    }
    write("seedmode-2026-11-25.json", {"darmstadt": darmstadt, "classifier": classifier})
    parts = latest(tmp_path)
    assert parts["roundtrip"]["file"] == "seedmode-2026-11-20.json"
    assert parts["classifier"]["file"] == "seedmode-2026-11-25.json" and "old" not in parts["classifier"]
    text = section_md(parts)
    assert "| seed | 31.0 | 27.5-36.0 | 44.2 | 1.5 |" in text
    assert "| ours | 3 | 540 | 4.5 | 100.0 | 104.0 | 80 % | 100 % |" in text  # medians over the seeds
    assert "| ours | NONE | Y |" in text
    assert "seedmode-2026-11-20.json" in text and "seedmode-2026-11-25.json" in text


def test_what_each_part_buys_is_ours_minus_that_part_the_seeds() -> None:
    def row(config: str, coverage: float, precision: float, end: float | None) -> dict:
        return {"algorithms": config, "runs": 3, "failed": 0, "coverage": coverage, "precision": precision,
                "orientation_error_deg": 1.0, "corners_closed": 4, "corners_total": 8,
                "angle_early_deg": 0.1, "angle_late_deg": 0.2, "end_error_mm": end}  # fmt: skip

    maps = {
        "minutes": 20, "speed": "10", "bitrate": "max", "seeds": [1, 2, 3],
        "tables": {"square": [row("ours", 0.90, 0.95, 20.0), row("copro=seed", 0.30, 0.40, 250.0),
                              row("body=seed", 0.93, 0.94, None)]},
    }  # fmt: skip
    text = section_md({"maps": maps})
    assert "| body=seed | 3 | 93 % | 94 % | 1.0 | 4/8 | 0.1 → 0.2 | – |" in text
    assert "| copro | square | +60 | +55 | +230 |" in text  # ours better everywhere
    assert "| body | square | -3 | +1 | – |" in text  # the seed's body maps 3 points more here
    maps["tables"]["square"][1] = row("copro=seed", 0.899, 0.95, 20.2)
    assert "| copro | square | 0 | 0 | 0 |" in section_md({"maps": maps})  # no "-0"
