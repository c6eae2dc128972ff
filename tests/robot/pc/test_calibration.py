"""Odometry calibration: the floor's step scale pooled over drives (``tokenring calibrate``), and a
filter that starts from it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from modules.localization.config import ConfigError, load_config, parse_config
from modules.localization.ekf import EkfParams, PoseEKF
from modules.localization.logs import DataLog
from modules.pc.calibration import CalibrationError, FloorEstimate, pool
from tokenring.cli.main import main as cli_main

DRAW_SD, NOISE_SD, PRIOR_SD = 0.005, 0.002, 0.02


def measured_drive(readings: list[float]) -> PoseEKF:
    """A filter that drove one straight move per reading and had each move's scale measured."""
    params = EkfParams(
        estimate=("glide", "step_scale", "step_scale_mean"),
        step_scale_per_move=DRAW_SD,
        step_scale_mean_walk_per_move=0.0,
        step_scale_walk_per_m=0.0,
        initial_step_scale_sigma=PRIOR_SD,
    )
    ekf = PoseEKF(params, (0.0, 0.0, 0.0))
    for reading in readings:
        ekf.predict(200, 200)
        assert ekf.correct_step_scale(reading, NOISE_SD)
        ekf.predict(-100, 100)  # a turn ends the move
    ekf.predict(400, 400)  # a last leg nothing measured
    return ekf


def test_drives_that_measured_the_floor_are_pooled_by_their_sigma_the_others_left_out() -> None:
    """Three filters that had moves measured around a floor of 1.01, and one that had none: the
    pool is the σ-weighted mean of the three ends (by hand here), within its σ of the floor."""
    rng = np.random.default_rng(3)
    spread = np.hypot(DRAW_SD, NOISE_SD)  # (within 2σ: the filter's gate keeps each reading)
    batches = [list(1.01 + np.clip(rng.normal(0, spread, n), -2 * spread, 2 * spread)) for n in (12, 20, 7)]
    drives = [measured_drive(batch) for batch in batches] + [measured_drive([])]
    ends = [(ekf.step_scale_mean, ekf.step_scale_mean_sigma) for ekf in drives]
    found = pool(FloorEstimate(f"drive{i}", m, s, PRIOR_SD) for i, (m, s) in enumerate(ends))
    weights = [1 / s**2 for _, s in ends[:3]]
    assert found.step_scale == pytest.approx(
        sum(w * m for w, (m, _) in zip(weights, ends, strict=False)) / sum(weights)
    )
    assert found.sigma == pytest.approx(max(1.0, found.birge_ratio) / np.sqrt(sum(weights)))
    assert found.used == ["drive0", "drive1", "drive2"] and list(found.skipped) == ["drive3"]
    assert abs(found.step_scale - 1.01) < 3 * found.sigma


def test_drives_that_disagree_more_than_they_claim_widen_the_pooled_sigma() -> None:
    tight = [FloorEstimate(f"d{i}", m, 0.001, 0.02) for i, m in enumerate((1.000, 1.010, 1.020))]
    found = pool(tight)
    assert found.birge_ratio > 5
    assert found.sigma > 0.005  # near the spread (0.01), not 0.001 / √3


def test_nothing_measured_is_an_error_not_a_calibration() -> None:
    with pytest.raises(CalibrationError, match="none of 2 drive"):
        pool([FloorEstimate("a", 1.0, 0.02, 0.02), FloorEstimate("b", 1.001, 0.0199, 0.02)])


def test_a_filter_started_from_a_calibration_drives_the_calibrated_step() -> None:
    params = EkfParams(estimate=("step_scale", "step_scale_mean"), initial_step_scale=1.01)
    ekf = PoseEKF(params, (0.0, 0.0, 0.0))
    assert ekf.step_scale_mean_sigma == pytest.approx(params.initial_step_scale_sigma)
    ekf.predict(1000, 1000)
    assert ekf.pose[0] == pytest.approx(1000 * params.odometry.mm_per_step * 1.01, rel=1e-9)
    assert PoseEKF(
        EkfParams(estimate=("step_scale", "step_scale_mean"), initial_step_scale_mean_sigma=0.002), (0, 0, 0)
    ).step_scale_mean_sigma == pytest.approx(0.002)


def test_a_step_scale_far_from_one_is_refused_with_its_key() -> None:
    with pytest.raises(
        ConfigError, match=r"x.yaml:2: filter.initial.step_scale: must lie between 0.5 and 1.5"
    ):
        parse_config("filter:\n  initial: {step_scale: 0.1}\n", "x.yaml")


def write_log(path: Path, ends: list[tuple[float, float]], mm_per_step: float = 0.5419) -> Path:
    """A data log whose filter positions end with these (floor mean, σ) values."""
    config = load_config()
    config["filter"]["estimate"] = ["glide", "compass_offset", "step_scale", "step_scale_mean"]
    config["robot"]["mm_per_step"] = mm_per_step
    log = DataLog(path, "test", config)
    for stamp, (mean, sigma) in enumerate(ends):
        log.write(
            100 * stamp,
            "K",
            "P",
            {
                "x": 0.0,
                "y": 0.0,
                "psi": 0.0,
                "sigma": [5, 5, 0.01],
                "step_scale_mean": mean,
                "step_scale_mean_sigma": sigma,
            },
        )
    log.close()
    return path


def test_calibrate_pools_the_logs_last_estimates(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    a = write_log(tmp_path / "a.trlog", [(1.0, 0.02), (1.009, 0.004)])
    b = write_log(tmp_path / "b.trlog", [(1.011, 0.003)])
    flat = write_log(tmp_path / "flat.trlog", [(1.0, 0.0201)])
    assert cli_main(["calibrate", str(a), str(b), str(flat), "--json"]) == 0
    found = json.loads(capsys.readouterr().out)
    weight_a, weight_b = 1 / 0.004**2, 1 / 0.003**2  # each log's last estimate, by its σ
    assert found["step_scale"] == pytest.approx((weight_a * 1.009 + weight_b * 1.011) / (weight_a + weight_b))
    assert found["used"] == ["a.trlog", "b.trlog"] and list(found["skipped"]) == ["flat.trlog"]
    assert found["mm_per_step"] == pytest.approx(0.5419)
    assert cli_main(["calibrate", str(a), str(b)]) == 0
    out = capsys.readouterr().out
    assert "from 2 of 2 logs" in out and "step_scale_mean_sigma" in out


@pytest.mark.parametrize(
    ("logs", "message"),
    [
        (["flat"], "none of 1 drive(s) learnt the floor"),
        (["a", "other_step"], "the logs' filters used different nominal steps"),
        (["no_mean"], "filter.estimate lacks step_scale_mean"),
        (["missing"], "no such log file"),
    ],
)
def test_calibrate_refuses_what_it_cannot_pool_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], logs: list[str], message: str
) -> None:
    write_log(tmp_path / "flat.trlog", [(1.0, 0.0201)])
    write_log(tmp_path / "a.trlog", [(1.009, 0.004)])
    write_log(tmp_path / "other_step.trlog", [(1.009, 0.004)], mm_per_step=0.55)
    DataLog(tmp_path / "no_mean.trlog", "test", load_config()).close()
    assert cli_main(["calibrate", *(str(tmp_path / f"{name}.trlog") for name in logs)]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
