"""Map scoring against true walls, and the map/score commands' files and errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from modules.pc.mapfiles import load_map_file, write_map
from modules.pc.mapscore import score_map, true_corners
from tests.support.processes import run_tokenring

SQUARE = np.array([[0, 0, 4000, 0], [4000, 0, 4000, 3000], [4000, 3000, 0, 3000], [0, 3000, 0, 0]], float)


def test_a_perfect_map_scores_full_marks_and_closes_every_corner():
    score = score_map(SQUARE, SQUARE)
    assert score["coverage"] == pytest.approx(1.0)
    assert score["precision"] == pytest.approx(1.0)
    assert score["orientation_error_deg"] == pytest.approx(0.0)
    assert (score["corners_closed"], score["corners_total"]) == (4, 4)
    assert len(true_corners(SQUARE)) == 4


def test_offsets_angles_gaps_and_stray_vectors_count_as_they_should():
    shifted = SQUARE + np.array([0, 40, 0, 40])  # 4 cm off: still within 5 cm
    assert score_map(shifted, SQUARE)["precision"] > 0.95
    far = SQUARE + np.array([0, 80, 0, 80])  # 8 cm off: the horizontal walls are no longer covered
    assert score_map(far, SQUARE)["coverage"] < 0.6
    half = np.array([[0, 0, 2000, 0]], float)  # one half wall
    s = score_map(half, SQUARE)
    assert s["coverage"] == pytest.approx(2000 / 14000, abs=0.01) and s["precision"] == pytest.approx(1.0)
    assert s["corners_closed"] == 0
    skew = np.array([[0, 0, 2000, 2000 * np.tan(np.radians(8))]], float)  # 8° off: not aligned
    s = score_map(skew, SQUARE)
    assert s["orientation_error_deg"] == pytest.approx(8.0, abs=0.1)
    stray = np.vstack([SQUARE, [[1000, 1000, 2000, 1000]]])  # 1 m of nothing
    assert score_map(stray, SQUARE)["precision"] == pytest.approx(14 / 15, abs=0.01)
    assert score_map(np.zeros((0, 4)), SQUARE)["coverage"] == 0.0


@pytest.mark.slow
def test_map_files_round_trip_and_score_from_the_command_line(tmp_path):
    vectors = SQUARE + np.array([0, 20, 0, 20])
    for ext in ("json", "dxf", "png"):
        path = tmp_path / f"map.{ext}"
        score = write_map(vectors, str(path), SQUARE, "square-ish")
        assert score is not None and score["corners_total"] == 4
        assert path.stat().st_size > 100
    assert (tmp_path / "map.png").read_bytes()[:4] == b"\x89PNG"
    assert np.allclose(load_map_file(str(tmp_path / "map.json")), vectors)
    assert np.allclose(load_map_file(str(tmp_path / "map.dxf")), vectors)  # the TRUTH layer is left out

    out = run_tokenring("score", str(tmp_path / "map.json"), "--world", "empty", "--json")
    assert out.returncode == 0, out.stderr
    score = json.loads(out.stdout)
    assert score["world"] == "empty" and score["vectors"] == 4
    text = run_tokenring("score", str(tmp_path / "map.dxf"), "--world", "empty")
    assert text.returncode == 0 and "coverage" in text.stdout

    converted = tmp_path / "again.png"
    out = run_tokenring(
        "map", "--from", str(tmp_path / "map.json"), "--out", str(converted), "--world", "empty"
    )
    assert out.returncode == 0 and converted.exists(), out.stderr


@pytest.mark.slow
def test_bad_map_files_and_options_are_clear_errors(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{"vectors": [[1, 2, 3]]}')
    out = run_tokenring("score", str(bad), "--world", "empty")
    assert out.returncode == 2 and "vectors[0]" in out.stderr and "Traceback" not in out.stderr
    broken = tmp_path / "broken.json"
    broken.write_text('{"vectors": [\n  [1, 2, 3, 4],,\n]}')
    out = run_tokenring("score", str(broken), "--world", "empty")
    assert out.returncode == 2 and "broken.json:2" in out.stderr
    out = run_tokenring("score", str(tmp_path / "missing.json"), "--world", "empty")
    assert out.returncode == 2 and "no such map file" in out.stderr
    out = run_tokenring("score", str(bad), "--world", "atlantis")
    assert out.returncode == 2 and "atlantis" in out.stderr
    out = run_tokenring("map", "--out", str(tmp_path / "map.svg"), "--from", str(bad))
    assert out.returncode == 2 and ".svg" in out.stderr
