"""``--json`` output is JSON a script can read: a figure with nothing to give it is null, not NaN."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from tokenring.cli.output import write_json


def refuse_constant(name: str) -> None:
    raise AssertionError(f"{name} is not JSON")


def test_figures_with_nothing_to_give_them_are_null(tmp_path):
    out = tmp_path / "report.json"
    record = {
        "one_pair": {"mean": 13.7, "lo": math.nan, "hi": math.nan, "n": 1},
        "medians": [1.5, np.float64("nan"), float("inf")],
        "pairs": [(2.0, -math.inf)],
        "kept": np.float64(0.25),
    }
    write_json(str(out), record)
    read = json.loads(out.read_text(), parse_constant=refuse_constant)  # strict: NaN would raise
    assert read == {
        "one_pair": {"mean": 13.7, "lo": None, "hi": None, "n": 1},
        "medians": [1.5, None, None],
        "pairs": [[2.0, None]],
        "kept": 0.25,
    }


def test_printed_json_is_as_strict(capsys):
    write_json("-", {"p99": math.nan})
    assert json.loads(capsys.readouterr().out, parse_constant=refuse_constant) == {"p99": None}


@pytest.mark.parametrize("value", [0.0, -0.0, 1e308, -5])
def test_finite_figures_are_written_as_they_are(tmp_path, value):
    out = tmp_path / "v.json"
    write_json(str(out), {"v": value})
    assert json.loads(out.read_text())["v"] == value
