"""tokenring analyze: the seed's logfileanalyser plots and the error summary of a data log."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from modules.localization.config import load_config
from modules.localization.localizer import LocalizationCore
from modules.localization.logs import DataLog, LogError
from modules.pc.analysis import analyse
from tests.support.locsim import drive
from tokenring.cli.main import main as cli_main


@pytest.fixture(scope="module")
def log_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("analysis") / "run.trlog"
    config = load_config()
    core = LocalizationCore(config, data_log=DataLog(path, "test", config))
    for sample in drive([("s", 800.0), ("r", 90.0), ("s", 400.0)], seed=1, heading=lambda: core.ekf.pose[2]):
        if sample.sensor == "compass" and sample.seq == 40:
            continue  # one lost compass sample: the time module must show it
        core.feed(sample)
        core.maybe_sync()
    core.close()
    return path


@pytest.mark.slow
def test_plots_and_summary(log_path: Path, tmp_path: Path) -> None:
    summary, files = analyse(log_path, tmp_path / "plots")
    names = {f.name for f in files}
    assert names == {"paths.png", "errors.png", "steps.png", "heading.png", "sonar.png", "time.png"}
    for f in files:
        assert f.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and f.stat().st_size > 10_000
    k, o = summary["sources"]["K"], summary["sources"]["O"]
    assert k["end_error_mm"] < 40.0 and k["rmse_mm"] < 40.0
    assert abs(k["end_heading_error_deg"]) < 2.0
    assert "end_error_mm" in o and "end_error_mm" not in summary["sources"]["M"]  # compass: heading only
    assert summary["timing"]["compass"]["missed"] == 1
    assert summary["sync"]["median_period_ms"] == pytest.approx(100.0)
    assert summary["filter_to_dead_reckoning"] == pytest.approx(k["end_error_mm"] / o["end_error_mm"])


def test_analyze_command_line(log_path: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli_main(["analyze", str(log_path), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["files"] == [] and summary["sources"]["K"]["records"] > 100
    assert cli_main(["analyze", str(log_path)]) == 0
    out = capsys.readouterr().out
    assert "filter (EKF)" in out and "end error" in out
    share = summary["sync"]["within_98_102ms"]  # the seed's figure, in the text too
    assert f"{100 * share:.0f} % within 98-102 ms" in out
    empty = tmp_path / "empty.trlog"
    DataLog(empty, "now", {}).close()
    with pytest.raises(LogError, match="no samples"):
        analyse(empty)
    assert cli_main(["analyze", str(empty)]) == 2


def test_the_filter_is_judged_by_its_own_three_sigma(log_path: Path, tmp_path: Path) -> None:
    """``within_3sigma``: the share of filter positions within 3σ of the truth on both axes,
    counted here straight from the log's records: the world's truth samples (``T R``; a ``T P``
    holds the newest that had arrived by the sync, which may be a round stale) interpolated at
    each filter position's stamp."""
    import numpy as np

    from modules.localization.logs import read_log

    records = read_log(log_path).records
    raw = sorted(
        (stamp, p["v"]["x"], p["v"]["y"])
        for stamp, source, kind, p in records
        if (source, kind) == ("T", "R")
    )
    t = np.array(raw, dtype=float)
    filtered = [(stamp, p) for stamp, source, kind, p in records if kind == "P" and source == "K"]
    inside = [
        abs(p["x"] - np.interp(stamp, t[:, 0], t[:, 1])) <= 3 * p["sigma"][0]
        and abs(p["y"] - np.interp(stamp, t[:, 0], t[:, 2])) <= 3 * p["sigma"][1]
        for stamp, p in filtered
    ]
    assert len(inside) == len(filtered) > 50
    summary, _ = analyse(log_path, tmp_path / "plots")
    k = summary["sources"]["K"]
    assert k["samples_3sigma"] == len(inside)
    assert k["within_3sigma"] == pytest.approx(sum(inside) / len(inside))
    assert k["within_3sigma"] > 0.9  # an honest filter on this short drive


def test_a_log_with_the_gyroscope_plots_its_rates_and_sums_its_heading(tmp_path: Path) -> None:
    """The seed's analyser had a gyroscope module: ``gyro.png`` of the raw and synchronised rates,
    the gyro's summed heading (``G P``) among the position sources, the rates' spread at rest."""
    from tests.support.locsim import with_gyro

    path = tmp_path / "gyro.trlog"
    config = load_config({"sensors": {"gyro": {"use": True}}})
    core = LocalizationCore(config, data_log=DataLog(path, "test", config))
    for sample in with_gyro(drive([("s", 400.0), ("r", 90.0), ("s", 400.0)], seed=2)):
        if sample.sensor == "gyro":  # a rate of its own too: the test's gyro sums only angles
            sample.values["rate_urad_s"] = 1000 + sample.stamp_ms % 7
        core.feed(sample)
        core.maybe_sync()
    core.close()
    summary, files = analyse(path, tmp_path / "plots")
    assert tmp_path / "plots" / "gyro.png" in files
    assert (tmp_path / "plots" / "gyro.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    gyro = summary["gyro"]
    assert gyro["samples"] > 100 and gyro["mean_rate_deg_s"] > 0.057 and gyro["sd_rate_deg_s"] > 0
    g = summary["sources"]["G"]
    assert "end_error_mm" not in g and abs(g["end_heading_error_deg"]) < 0.5  # from the true turns
