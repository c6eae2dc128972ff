"""Log analysis like the seed's logfileanalyser (000, §9.2): PNG plots and a summary.

Plots (one PNG each, like the seed's per-module gnuplot directories):

- ``paths.png`` — the path of every position source against the ground truth (and the known
  walls of the configured room);
- ``errors.png`` — each source's position and heading error against the truth over time;
- ``steps.png`` — synchronised step increments of both motors (the seed's encoder module);
- ``heading.png`` — compass heading, the filter's, dead reckoning's and the gyroscope's summed
  heading and the truth;
- ``sonar.png`` — sonar distances over time (no contact is not drawn);
- a sensor's own plot, drawn by its file in :mod:`modules.localization.sensors` (its
  ``analysis``): ``gyro.png`` — the gyroscope's raw rates over time and its synchronised mean
  rates (the seed's gyroscope module, table B.9 ``Gyroskop``); ``lops.png`` — LOPS's three
  distances over time, one per receiver (the seed's LOPS module, table B.9 ``LOPS/Empfaenger
  n``; nothing heard is not drawn), and which packets gave no position; each only for a log
  with that sensor's raw records;
- ``time.png`` — the **time module**: each sensor's cycle time (between its own time stamps) and
  the synchronisation's period, with missed samples marked.

The summary gives, per position source, the end-point error and RMSE against the truth
(position and heading), per sensor the sample count, missed and late samples, and the
synchronisation's period: median, p99, extremes and the shares of cycles within 2 % of the
median and within the seed's windows (98-102 ms and 95-105 ms); and each sensor's own entry
(``gyro``: its rates' mean and spread; ``lops``: the packets without a position, each receiver's
share heard). Position sources are named and coloured as their sensors say.

The seed's own output — its per-module data files (table B.9) and gnuplot control files — is
:mod:`modules.pc.seedplots` (``tokenring analyze --seed-out``).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from modules.localization.logs import LogError, LogFile, read_log
from modules.localization.sensors import Sensor, registered, sensor_of_letter

#: the filter's position: not a sensor's
FILTER_NAME, FILTER_COLOUR = "filter (EKF)", "tab:blue"


def position_names() -> dict[str, str]:
    """What the plots and the summary call each position source: the filter, then the sensors'."""
    named = {s.letter: s.position_name for s in registered() if s.position_name is not None}
    return {"K": FILTER_NAME, **named}


def colours() -> dict[str, str]:
    """Each position source's colour in the plots: the filter's, then the sensors'."""
    return {"K": FILTER_COLOUR, **{s.letter: s.colour for s in registered() if s.colour is not None}}


def analysed() -> list[Sensor]:
    """The sensors with an analyser module of their own, in synchronisation order."""
    return [s for s in registered() if s.analysis is not None]


def __getattr__(name: str) -> Any:
    """The tables the sensor registry makes, worked out when read (PEP 562):
    :data:`POSITION_NAMES`, :data:`COLOURS` and :data:`PLOTS`."""
    if name == "POSITION_NAMES":
        return position_names()
    if name == "COLOURS":
        return colours()
    if name == "PLOTS":
        return plots()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


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
        self.sonar: list[tuple[int, list[int]]] = []
        #: per sensor with an analyser module: its R and C records (stamp, kind, payload)
        modules = analysed()
        records: dict[str, list[tuple[int, str, dict[str, Any]]]] = {s.name: [] for s in modules}
        self.walls_fitted = 0
        self.sigmas: dict[str, list[tuple[int, float, float, float]]] = {}  # (stamp, σx, σy, σψ)
        for stamp, source, kind, payload in log.records:
            if kind == "P":
                valid = payload.get("valid", [True, True, True])
                row = (stamp, payload["x"], payload["y"], payload["psi"], *map(bool, valid))
                self.positions.setdefault(source, []).append(row)
                if "sigma" in payload:
                    self.sigmas.setdefault(source, []).append((stamp, *map(float, payload["sigma"])))
                continue
            sensor_of = sensor_of_letter(source)
            if kind in ("R", "C") and sensor_of is not None and sensor_of.name in records:
                records[sensor_of.name].append((stamp, kind, payload))
            if kind == "R" and sensor_of is not None:
                sensor = sensor_of.name
                self.raw_stamps.setdefault(sensor, []).append(stamp)
                if "seq" in payload:
                    self.raw_seq.setdefault(sensor, []).append(payload["seq"])
                values = payload.get("v", {})
                if sensor == "truth" and all(k in values for k in ("x", "y", "theta")):
                    self.truth_raw.append((stamp, values["x"], values["y"], values["theta"]))
                if sensor == "compass" and "heading_cdeg" in values:
                    self.compass_raw.append((stamp, values["heading_cdeg"] / 100.0))
                elif sensor == "sonar" and "distances" in values:
                    self.sonar.append((stamp, list(values["distances"])))
            elif kind == "C" and source == "O":
                self.steps.append((stamp, payload["dl"], payload["dr"]))
            elif kind == "C" and source == "W":
                self.walls_fitted += len(payload.get("walls", []))
            elif source == "S" and kind == "S":
                self.sync_stamps.append(stamp)
        #: what each sensor's analyser module made of its records (None: nothing to show)
        self.sensors: dict[str, Any] = {
            s.name: s.analysis.collect(records[s.name]) for s in modules if s.analysis is not None
        }

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
    names = position_names()
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
            entry: dict[str, Any] = {"name": names.get(source, source), "records": len(rows)}
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
    for module in analysed():  # each sensor's own entry (the gyroscope's rates, LOPS's packets)
        data = series.sensors.get(module.name)
        if data is not None and module.analysis is not None and module.analysis.summary is not None:
            out[module.name] = module.analysis.summary(data)
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


def plots() -> tuple[str, ...]:
    """The files :func:`plot_all` may write (those the log has data for): the analyser's own and
    each sensor's (after ``sonar.png``, in synchronisation order)."""
    own = tuple(s.analysis.plot_file for s in analysed() if s.analysis is not None and s.analysis.plot)
    return ("paths.png", "errors.png", "steps.png", "heading.png", "sonar.png", *own, "time.png")


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
    names, colour = position_names(), colours()

    # paths
    fig, ax = plt.subplots(figsize=(7, 7))
    for x1, y1, x2, y2 in _known_walls(series.log):
        ax.plot([x1, x2], [y1, y2], color="0.75", lw=2)
    for source in ("T", "O", "K"):
        a = series.array(source)
        if len(a) and a[:, 4].any():
            ax.plot(a[:, 1], a[:, 2], color=colour[source], lw=1.0 if source != "T" else 1.6,
                    label=names[source])  # fmt: skip
            ax.plot(a[-1, 1], a[-1, 2], "o", color=colour[source], ms=4)
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
            ax1.plot(t, np.hypot(a[:, 1] - tx, a[:, 2] - ty), color=colour[source], label=names[source])
            dh = _wrap_deg(np.degrees(a[:, 3] - np.interp(a[:, 0], truth[:, 0], tpsi)))
            ax2.plot(t, dh, color=colour[source], label=names[source])
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
            color=colour["M"],
            label="compass (raw, from north cw)",
        )
    for source in ("T", "O", "G", "K"):
        a = series.array(source)
        if len(a):
            ax.plot((a[:, 0] - t0) / 1000.0, np.degrees(a[:, 3]) % 360.0, lw=0.8, color=colour[source],
                    label=f"{names[source]} (ccw from +X)")  # fmt: skip
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

    # each sensor's own (the gyroscope's rates, LOPS's receivers)
    for module in analysed():
        analysis, data = module.analysis, series.sensors.get(module.name)
        if analysis is None or analysis.plot is None or data is None:
            continue
        fig, ax = plt.subplots(figsize=analysis.figsize)
        analysis.plot(data, ax, t0)
        save(fig, analysis.plot_file)

    # the time module
    sensors = [s.name for s in registered() if len(series.raw_stamps.get(s.name, [])) > 1]
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
    return analyse_log(read_log(path, expect="data", salvage=salvage), out, progress)


def analyse_log(
    log: LogFile, out: str | Path | None = None, progress: Callable[[str], None] | None = None
) -> tuple[dict[str, Any], list[Path]]:
    """:func:`analyse` of a log already read (``tokenring analyze`` also writes the seed's
    logfileanalyser files of it, :mod:`modules.pc.seedplots`)."""
    series = Series(log)
    if not series.positions and not series.raw_stamps:
        raise LogError(f"{log.path}: the log holds no samples and no positions")
    files = plot_all(series, Path(out), progress) if out is not None else []
    return summarise(series), files
