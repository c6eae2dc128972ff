"""Log analysis like the seed's logfileanalyser (000, §9.2): PNG plots and a summary.

Plots (one PNG each, like the seed's per-module gnuplot directories):

- ``paths.png`` — the path of every position source against the ground truth (and the known
  walls of the configured room);
- ``errors.png`` — each source's position and heading error against the truth over time;
- ``steps.png`` — synchronised step increments of both motors (the seed's encoder module);
- ``heading.png`` — compass heading, the filter's, dead reckoning's and the gyroscope's summed
  heading and the truth;
- ``gyro.png`` — the gyroscope's raw rates over time and its synchronised mean rates (the seed's
  gyroscope module, table B.9 ``Gyroskop``); only for a log with the gyroscope's ``G R`` records;
- ``sonar.png`` — sonar distances over time (no contact is not drawn);
- ``lops.png`` — LOPS's three distances over time, one per receiver (the seed's LOPS module,
  table B.9 ``LOPS/Empfaenger n``; nothing heard is not drawn), and which packets gave no
  position; only for a log with LOPS's ``L R`` records;
- ``time.png`` — the **time module**: each sensor's cycle time (between its own time stamps) and
  the synchronisation's period, with missed samples marked.

The summary gives, per position source, the end-point error and RMSE against the truth
(position and heading), per sensor the sample count, missed and late samples, and the
synchronisation's period: median, p99, extremes and the shares of cycles within 2 % of the
median and within the seed's windows (98-102 ms and 95-105 ms).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from modules.localization.logs import SOURCE_SENSOR, LogError, LogFile, read_log
from modules.localization.sync import SENSORS

POSITION_NAMES = {
    "K": "filter (EKF)",
    "O": "dead reckoning",
    "M": "compass",
    "G": "gyroscope",
    "T": "truth",
    "W": "walls",
    "L": "LOPS",
}
COLOURS = {
    "K": "tab:blue",
    "O": "tab:red",
    "M": "tab:green",
    "G": "tab:olive",
    "T": "black",
    "W": "tab:purple",
    "L": "tab:orange",
}


class Series:
    """The columns of a data log that the plots and the summary need."""

    def __init__(self, log: LogFile) -> None:
        self.log = log
        self.positions: dict[str, list[tuple[int, float, float, float, bool, bool, bool]]] = {}
        self.raw_stamps: dict[str, list[int]] = {}
        self.raw_seq: dict[str, list[int]] = {}
        self.sync_stamps: list[int] = []
        self.steps: list[tuple[int, int, int]] = []
        self.compass_raw: list[tuple[int, float]] = []
        #: the world's truth as it was sampled (T R): the judge between the synchronisations
        self.truth_raw: list[tuple[int, float, float, float]] = []
        #: the gyroscope's raw rates and its synchronised mean rates: (stamp, rad/s)
        self.gyro_raw: list[tuple[int, float]] = []
        self.gyro_sync: list[tuple[int, float]] = []
        self.sonar: list[tuple[int, list[int]]] = []
        #: LOPS's packets: (stamp, d1, d2, d3, has a position), NaN where nothing was heard
        self.lops: list[tuple[int, float, float, float, bool]] = []
        self.walls_fitted = 0
        self.sigmas: dict[str, list[tuple[int, float, float, float]]] = {}  # (stamp, σx, σy, σψ)
        for stamp, source, kind, payload in log.records:
            if kind == "P":
                valid = payload.get("valid", [True, True, True])
                row = (stamp, payload["x"], payload["y"], payload["psi"], *map(bool, valid))
                self.positions.setdefault(source, []).append(row)
                if "sigma" in payload:
                    self.sigmas.setdefault(source, []).append((stamp, *map(float, payload["sigma"])))
            elif kind == "R" and source in SOURCE_SENSOR:
                sensor = SOURCE_SENSOR[source]
                self.raw_stamps.setdefault(sensor, []).append(stamp)
                if "seq" in payload:
                    self.raw_seq.setdefault(sensor, []).append(payload["seq"])
                values = payload.get("v", {})
                if sensor == "truth" and all(k in values for k in ("x", "y", "theta")):
                    self.truth_raw.append((stamp, values["x"], values["y"], values["theta"]))
                if sensor == "compass" and "heading_cdeg" in values:
                    self.compass_raw.append((stamp, values["heading_cdeg"] / 100.0))
                elif sensor == "gyro" and "rate_urad_s" in values:
                    self.gyro_raw.append((stamp, float(values["rate_urad_s"]) / 1e6))
                elif sensor == "sonar" and "distances" in values:
                    self.sonar.append((stamp, list(values["distances"])))
                elif sensor == "lops" and "counter" in values:
                    d = [math.nan if values.get(k) is None else float(values[k]) for k in ("d1", "d2", "d3")]
                    self.lops.append((stamp, *d, values.get("x") is not None))
            elif kind == "C" and source == "O":
                self.steps.append((stamp, payload["dl"], payload["dr"]))
            elif kind == "C" and source == "G":
                self.gyro_sync.append((stamp, float(payload["rate"])))
            elif kind == "C" and source == "W":
                self.walls_fitted += len(payload.get("walls", []))
            elif source == "S" and kind == "S":
                self.sync_stamps.append(stamp)

    def truth(self) -> np.ndarray:
        """The truth to judge the sources by: its raw samples (stamp, x, y, ψ) where the log has
        them — a ``T P`` at a synchronisation is the newest sample that had arrived by then,
        up to a token round stale — else the ``T`` positions."""
        if len(self.truth_raw) > 1:
            return np.array(sorted(self.truth_raw), dtype=float)
        return self.array("T")[:, :4]

    def array(self, source: str) -> np.ndarray:
        rows = self.positions.get(source, [])
        return np.array(rows, dtype=float) if rows else np.zeros((0, 7))


def _wrap_deg(values: np.ndarray) -> np.ndarray:
    return (values + 180.0) % 360.0 - 180.0


def summarise(series: Series) -> dict[str, Any]:
    """End-point error and RMSE of every position source against the truth, and the timing."""
    truth = series.truth()
    sources: dict[str, Any] = {}
    if len(truth):
        t_truth = truth[:, 0]
        for source, rows in series.positions.items():
            if source == "T":
                continue
            a = series.array(source)
            tx = np.interp(a[:, 0], t_truth, truth[:, 1])
            ty = np.interp(a[:, 0], t_truth, truth[:, 2])
            tpsi = np.unwrap(truth[:, 3])
            tp = np.interp(a[:, 0], t_truth, tpsi)
            entry: dict[str, Any] = {"name": POSITION_NAMES.get(source, source), "records": len(rows)}
            has_xy = bool(a[:, 4].any() and a[:, 5].any())
            if has_xy:
                dist = np.hypot(a[:, 1] - tx, a[:, 2] - ty)
                entry.update(
                    end_error_mm=float(dist[-1]),
                    rmse_mm=float(np.sqrt(np.mean(dist**2))),
                    max_error_mm=float(dist.max()),
                    end_pose=[float(a[-1, 1]), float(a[-1, 2]), math.degrees(a[-1, 3])],
                )
                sig = np.array(series.sigmas.get(source, []), dtype=float)
                if len(sig) == len(a):  # the filter's own uncertainty: is it honest?
                    inside = (np.abs(a[:, 1] - tx) <= 3 * sig[:, 1]) & (np.abs(a[:, 2] - ty) <= 3 * sig[:, 2])
                    entry.update(within_3sigma=float(np.mean(inside)), samples_3sigma=len(inside))
            if a[:, 6].any():
                dh = _wrap_deg(np.degrees(a[:, 3] - tp))
                entry.update(
                    end_heading_error_deg=float(dh[-1]), heading_rmse_deg=float(np.sqrt(np.mean(dh**2)))
                )
            sources[source] = entry
    timing = {}
    for sensor, stamps in series.raw_stamps.items():
        periods = np.diff(stamps) if len(stamps) > 1 else np.zeros(0)
        seqs = series.raw_seq.get(sensor, [])
        missed = int(sum(max(0, ((b - a) % 65536) - 1) for a, b in itertools.pairwise(seqs)))
        timing[sensor] = {
            "samples": len(stamps),
            "missed": missed,
            "late": int(np.sum(periods < 0)),
            "median_period_ms": float(np.median(periods)) if len(periods) else None,
        }
    sync_periods = np.diff(series.sync_stamps) if len(series.sync_stamps) > 1 else np.zeros(0)
    sync: dict[str, Any] = {"count": len(series.sync_stamps)}
    if len(sync_periods):
        median = float(np.median(sync_periods))
        sync.update(
            median_period_ms=median,
            p99_period_ms=float(np.percentile(sync_periods, 99)),
            min_period_ms=float(sync_periods.min()),
            max_period_ms=float(sync_periods.max()),
            within_2pct=float(np.mean(np.abs(sync_periods - median) <= 0.02 * median)),
            # the seed's own figures (000, §10): 85 % of its cycles in 98-102 ms, all in 95-105 ms
            within_98_102ms=float(np.mean((sync_periods >= 98) & (sync_periods <= 102))),
            within_95_105ms=float(np.mean((sync_periods >= 95) & (sync_periods <= 105))),
        )
    out: dict[str, Any] = {
        "log": str(series.log.path),
        "start": series.log.header.get("start"),
        "truncated": series.log.truncated,
        "sources": sources,
        "timing": timing,
        "sync": sync,
        "walls_fitted": series.walls_fitted,
    }
    if series.gyro_raw:  # at rest the seed's figure 10.2: one bit of noise around the zero point
        rates = np.degrees(np.array([r for _, r in series.gyro_raw], dtype=float))
        out["gyro"] = {
            "samples": len(rates),
            "mean_rate_deg_s": float(rates.mean()),
            "sd_rate_deg_s": float(rates.std()),
        }
    if series.lops:  # the seed's 404 of 2024 without a position, and its receivers' share heard
        lops = np.array(series.lops, dtype=float)
        out["lops"] = {
            "packets": len(lops),
            "without_position": float(np.mean(lops[:, 4] == 0)),
            "heard": [float(np.mean(~np.isnan(lops[:, i]))) for i in (1, 2, 3)],
        }
    if "K" in sources and "O" in sources and "end_error_mm" in sources["K"]:
        dr = sources["O"]["end_error_mm"]
        out["filter_to_dead_reckoning"] = sources["K"]["end_error_mm"] / dr if dr > 0 else None
    return out


def _known_walls(log: LogFile) -> np.ndarray:
    config = log.header.get("config") or {}
    name = (config.get("walls") or {}).get("file")
    if not name:
        return np.zeros((0, 4))
    try:
        from modules.description import load_world

        return load_world(name).segments()
    except Exception:  # the room is a decoration of the plot: a missing file must not stop it
        return np.zeros((0, 4))


#: the files :func:`plot_all` may write (those the log has data for)
PLOTS = (
    "paths.png",
    "errors.png",
    "steps.png",
    "heading.png",
    "sonar.png",
    "gyro.png",
    "lops.png",
    "time.png",
)


def plot_all(series: Series, out: Path, progress: Callable[[str], None] | None = None) -> list[Path]:
    """Write every plot into ``out``; returns the files written. Each is written beside its
    name and renamed once whole: a full disk is one line naming the plot (``--out DIR/NAME``),
    and a plot that was there before stays as it was."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tokenring import option_error, replacing, write_failed

    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise write_failed(out, exc, option_error("--out")) from None
    written: list[Path] = []

    def save(fig: Any, name: str) -> None:
        path = out / name
        try:
            fig.tight_layout()
            with replacing(path, option_error("--out")) as temp:
                fig.savefig(temp, dpi=110, format="png")  # the format said: the temporary name has none
        finally:
            plt.close(fig)
        written.append(path)
        if progress is not None:
            progress(name)

    t0 = min((rows[0][0] for rows in series.positions.values() if rows), default=0)

    # paths
    fig, ax = plt.subplots(figsize=(7, 7))
    for x1, y1, x2, y2 in _known_walls(series.log):
        ax.plot([x1, x2], [y1, y2], color="0.75", lw=2)
    for source in ("T", "O", "K"):
        a = series.array(source)
        if len(a) and a[:, 4].any():
            ax.plot(a[:, 1], a[:, 2], color=COLOURS[source], lw=1.0 if source != "T" else 1.6,
                    label=POSITION_NAMES[source])  # fmt: skip
            ax.plot(a[-1, 1], a[-1, 2], "o", color=COLOURS[source], ms=4)
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_title("paths of the position sources")
    ax.legend(loc="best")
    save(fig, "paths.png")

    # errors against the truth
    truth = series.truth()
    if len(truth):
        fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
        tpsi = np.unwrap(truth[:, 3])
        for source in ("O", "K"):
            a = series.array(source)
            if not len(a):
                continue
            t = (a[:, 0] - t0) / 1000.0
            tx = np.interp(a[:, 0], truth[:, 0], truth[:, 1])
            ty = np.interp(a[:, 0], truth[:, 0], truth[:, 2])
            ax1.plot(
                t, np.hypot(a[:, 1] - tx, a[:, 2] - ty), color=COLOURS[source], label=POSITION_NAMES[source]
            )
            dh = _wrap_deg(np.degrees(a[:, 3] - np.interp(a[:, 0], truth[:, 0], tpsi)))
            ax2.plot(t, dh, color=COLOURS[source], label=POSITION_NAMES[source])
        ax1.set_ylabel("position error [mm]")
        ax1.set_yscale("symlog", linthresh=10)
        ax1.legend(loc="upper left")
        ax2.set_ylabel("heading error [°]")
        ax2.set_xlabel("time [s]")
        ax1.set_title("errors against the ground truth")
        save(fig, "errors.png")

    # steps
    if series.steps:
        s = np.array(series.steps, dtype=float)
        fig, ax = plt.subplots(figsize=(9, 4))
        ax.plot((s[:, 0] - t0) / 1000.0, s[:, 1], label="left", lw=0.8)
        ax.plot((s[:, 0] - t0) / 1000.0, s[:, 2], label="right", lw=0.8)
        ax.set_xlabel("time [s]")
        ax.set_ylabel("half-steps per synchronisation")
        ax.set_title("step increments (synchronised)")
        ax.legend()
        save(fig, "steps.png")

    # heading
    fig, ax = plt.subplots(figsize=(9, 4))
    if series.compass_raw:
        c = np.array(series.compass_raw)
        ax.plot(
            (c[:, 0] - t0) / 1000.0,
            c[:, 1],
            ".",
            ms=1,
            color=COLOURS["M"],
            label="compass (raw, from north cw)",
        )
    for source in ("T", "O", "G", "K"):
        a = series.array(source)
        if len(a):
            ax.plot((a[:, 0] - t0) / 1000.0, np.degrees(a[:, 3]) % 360.0, lw=0.8, color=COLOURS[source],
                    label=f"{POSITION_NAMES[source]} (ccw from +X)")  # fmt: skip
    ax.set_xlabel("time [s]")
    ax.set_ylabel("[°]")
    ax.set_title("heading")
    ax.legend(loc="best", fontsize=8)
    save(fig, "heading.png")

    # sonar
    if series.sonar:
        fig, ax = plt.subplots(figsize=(9, 5))
        times = (np.array([s[0] for s in series.sonar]) - t0) / 1000.0
        values = np.array([s[1] for s in series.sonar], dtype=float)
        values[values >= 255] = np.nan
        for i in range(values.shape[1]):
            ax.plot(times, values[:, i] * 10.0, ".", ms=1.5, label=f"sonar {i}")
        ax.set_xlabel("time [s]")
        ax.set_ylabel("distance [mm]")
        ax.set_title("sonar distances (no contact not drawn)")
        ax.legend(loc="upper right", fontsize=7, ncol=4, markerscale=4)
        save(fig, "sonar.png")

    # the gyroscope's rates
    if series.gyro_raw:
        fig, ax = plt.subplots(figsize=(9, 4))
        raw = np.array(series.gyro_raw, dtype=float)
        ax.plot((raw[:, 0] - t0) / 1000.0, np.degrees(raw[:, 1]), ".", ms=1.5, color=COLOURS["G"],
                label="raw (the newest sample a token visit carried)")  # fmt: skip
        if series.gyro_sync:
            synced = np.array(series.gyro_sync, dtype=float)
            ax.plot((synced[:, 0] - t0) / 1000.0, np.degrees(synced[:, 1]), lw=0.8, color="black",
                    label="synchronised (mean of every rate since the last synchronisation)")  # fmt: skip
        ax.set_xlabel("time [s]")
        ax.set_ylabel("rate [°/s, ccw]")
        ax.set_title("gyroscope: rates")
        ax.legend(loc="best", fontsize=8)
        save(fig, "gyro.png")

    # LOPS's receivers
    if series.lops:
        fig, ax = plt.subplots(figsize=(9, 5))
        lops = np.array(series.lops, dtype=float)
        times = (lops[:, 0] - t0) / 1000.0
        for i in range(3):
            ax.plot(times, lops[:, i + 1], ".", ms=2, label=f"receiver {i + 1}")
        lost = lops[:, 4] == 0
        if lost.any():
            ax.plot(times[lost], np.zeros(int(lost.sum())), "|", color="tab:red", ms=8,
                    label=f"no position ({lost.mean():.0%} of {len(lops)} packets)")  # fmt: skip
        ax.set_xlabel("time [s] (on arrival)")
        ax.set_ylabel("distance [mm]")
        ax.set_title("LOPS: distances to the three receivers (nothing heard not drawn)")
        ax.legend(loc="upper right", fontsize=7, markerscale=3)
        save(fig, "lops.png")

    # the time module
    sensors = [s for s in SENSORS if len(series.raw_stamps.get(s, [])) > 1]
    rows = len(sensors) + 1
    fig, axes = plt.subplots(rows, 1, figsize=(9, 1.8 * rows + 0.6), sharex=True)
    axes = np.atleast_1d(axes)
    for ax, sensor in zip(axes, sensors, strict=False):
        stamps = np.array(series.raw_stamps[sensor], dtype=float)
        ax.plot((stamps[1:] - t0) / 1000.0, np.diff(stamps), ".", ms=1.5)
        seqs = series.raw_seq.get(sensor, [])
        lost = [i + 1 for i, (a, b) in enumerate(itertools.pairwise(seqs)) if (b - a) % 65536 > 1]
        if lost:
            ax.plot((stamps[lost] - t0) / 1000.0, np.diff(stamps)[np.array(lost) - 1], "x", color="tab:red",
                    label=f"{len(lost)} gaps with missed samples")  # fmt: skip
            ax.legend(loc="upper right", fontsize=7)
        ax.set_ylabel(f"{sensor}\n[ms]")
    ax = axes[-1]
    if len(series.sync_stamps) > 1:
        sync = np.array(series.sync_stamps, dtype=float)
        ax.plot((sync[1:] - t0) / 1000.0, np.diff(sync), ".", ms=1.5, color="black")
    ax.set_ylabel("sync\n[ms]")
    ax.set_xlabel("time [s] (sensor time stamps)")
    axes[0].set_title("time module: cycle times of the sensors and of the synchronisation")
    save(fig, "time.png")
    return written


def analyse(
    path: str | Path,
    out: str | Path | None = None,
    progress: Callable[[str], None] | None = None,
    salvage: bool = False,
):
    """Read a data log; write the plots into ``out`` (if given); return (summary, files)."""
    log = read_log(path, expect="data", salvage=salvage)
    series = Series(log)
    if not series.positions and not series.raw_stamps:
        raise LogError(f"{path}: the log holds no samples and no positions")
    files = plot_all(series, Path(out), progress) if out is not None else []
    return summarise(series), files
