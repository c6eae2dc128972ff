"""Offline mode (seed 000, §5.6): run the synchronisation and the filter again on a recorded log.

From **raw** data, every raw record goes back into the buffer generation it was filed in online,
and every synchronisation the log records runs again on exactly that half — so the same
configuration gives the same positions, bit for bit. ``retrigger`` instead feeds the raw samples
in their original order through a (possibly different) trigger. From **synchronised** data the
logged synchronised records go straight to the filter (other filter settings on the same run).
Events (a pose set, walls added to the map) are re-applied at the synchronisation they preceded.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from modules.localization.config import load_config
from modules.localization.localizer import LocalizationCore
from modules.localization.logs import DataLog, ErrorLog, LogError, LogFile, read_log
from modules.localization.sensors import sensor_of_letter
from modules.localization.sync import Sample
from tokenring import message_error, replacing

EVENT_KINDS = {("S", "E"), ("W", "W")}


@dataclass
class ReplayResult:
    """What a replay did: syncs run, positions written, and the comparison with the input log."""

    output: Path
    syncs: int
    positions: int
    compared: int
    identical: bool
    first_difference: str | None
    report: dict[str, Any]


def replay(
    source: str | Path,
    output: str | Path,
    config: str | Path | dict | None = None,
    *,
    mode: str = "raw",
    errors: str | Path | None = None,
    progress: Callable[[int, int], None] | None = None,
    salvage: bool = False,
) -> ReplayResult:
    """Replay ``source`` into a new data log ``output``; ``mode`` is raw, sync or retrigger."""
    if mode not in ("raw", "sync", "retrigger"):
        raise LogError(f"replay mode {mode!r} is not one of raw, sync, retrigger")
    log = read_log(source, expect="data", salvage=salvage)
    settings = load_config(config if config is not None else log.header.get("config") or None)
    if Path(output).resolve() == Path(source).resolve():
        raise LogError(f"{output}: the replay must write a new log, not overwrite its input")
    start = time.strftime("%Y%m%d-%H%M%S")
    meta = {"replay_of": str(source), "mode": mode, "original_start": log.header.get("start")}
    # both logs are written beside their targets and renamed once whole: a failed write (a full
    # disk) is one line naming the target, and leaves what was there
    fail = message_error(LogError)
    with contextlib.ExitStack() as files:
        data_path = files.enter_context(replacing(output, fail))
        error_path = files.enter_context(replacing(errors, fail)) if errors else None
        data_log = DataLog(data_path, start, settings, meta, on_failure=_refuse, name=output)
        error_log = None
        if error_path is not None:
            level = settings["logs"]["debug_level"]
            error_log = ErrorLog(error_path, start, level=level, on_failure=_refuse, name=errors)
        core = LocalizationCore(settings, data_log=data_log, error_log=error_log)
        try:
            if mode == "sync":
                _from_synchronised(core, log, progress)
            elif mode == "retrigger":
                if settings["sync"]["trigger"]["rounds"] > 0:
                    raise LogError("retrigger needs a sensor trigger: token rounds are not in the log")
                _retrigger(core, log, progress)
            else:
                _from_raw(core, log, progress)
            report = core.report()
        finally:
            core.close()
        replayed = read_log(data_path)
    return _compare(log, replayed, Path(output), core.syncs, report)


def _refuse(line: str) -> None:
    """A replayed log that cannot be written (a full disk) ends the replay, naming that log (its
    temporary file is removed: what the stream kept of it is not said)."""
    raise LogError(line.partition("; ")[0])


def _raw_sample(record: list[Any]) -> tuple[int, int, Sample] | None:
    stamp, source, kind, payload = record
    sensor = sensor_of_letter(source)
    if kind != "R" or sensor is None:
        return None
    return payload["gen"], payload["n"], Sample(sensor.name, int(stamp), payload["v"], payload.get("seq"))


def _from_raw(core: LocalizationCore, log: LogFile, progress: Callable[[int, int], None] | None) -> None:
    halves: dict[int, list[tuple[int, Sample]]] = {}
    for record in log.records:
        raw = _raw_sample(record)
        if raw is not None:
            generation, number, sample = raw
            halves.setdefault(generation, []).append((number, sample))
    total = len(log.records)
    for i, (stamp, source, kind, payload) in enumerate(log.records):
        sensor = sensor_of_letter(source)
        if kind == "R" and sensor is not None:
            if core.data_log is not None and core.sensors.get(sensor.name, {}).get("log_raw"):
                core.data_log.write(stamp, source, kind, payload)
        elif (source, kind) in EVENT_KINDS:
            _requeue(core, payload)
        elif source == "S" and kind == "S":
            generation = payload["gen"]
            half: dict[str, list[Sample]] = {}
            for _, sample in sorted(halves.pop(generation, []), key=lambda item: item[0]):
                if sample.sensor in core.sensors:
                    half.setdefault(sample.sensor, []).append(sample)
            core.synchronise_half(generation, half)
        if progress is not None and i % 2000 == 0:
            progress(i, total)


def _retrigger(core: LocalizationCore, log: LogFile, progress: Callable[[int, int], None] | None) -> None:
    raws = sorted((r for r in map(_raw_sample, log.records) if r is not None), key=lambda item: item[1])
    for i, (_, _, sample) in enumerate(raws):
        core.feed(sample)
        core.maybe_sync()
        if progress is not None and i % 2000 == 0:
            progress(i, len(raws))


def _from_synchronised(
    core: LocalizationCore, log: LogFile, progress: Callable[[int, int], None] | None
) -> None:
    pending: dict[str, dict[str, Any]] = {}
    total = len(log.records)
    for i, (stamp, source, kind, payload) in enumerate(log.records):
        sensor = sensor_of_letter(source)
        if kind == "C" and sensor is not None:
            record = {k: v for k, v in payload.items() if k != "gen"}
            pending[sensor.name] = record
            if core.data_log is not None:
                core.data_log.write(stamp, source, kind, payload)
        elif (source, kind) in EVENT_KINDS:
            _requeue(core, payload)
        elif source == "S" and kind == "S":
            data = {name: rec for name, rec in pending.items() if name in core.sensors}
            core.process_synchronised(payload["gen"], stamp, data, payload.get("counts"))
            pending = {}
        if progress is not None and i % 2000 == 0:
            progress(i, total)


def _requeue(core: LocalizationCore, payload: dict[str, Any]) -> None:
    event = {k: v for k, v in payload.items() if k not in ("gen", "event")}
    core.queue_event(payload["gen"], payload["event"], event)


def _compare(
    original: LogFile, replayed: LogFile, output: Path, syncs: int, report: dict[str, Any]
) -> ReplayResult:
    """Compare the filter's and dead reckoning's positions of the two logs, record by record."""

    def positions(log: LogFile) -> list[tuple[int, str, Any]]:
        return [(r[0], r[1], r[3]) for r in log.records if r[2] == "P" and r[1] in ("K", "O")]

    def same(a: tuple[int, str, Any], b: tuple[int, str, Any]) -> bool:
        # on every field the input log has: a log written before a field was added replays as equal
        if a[:2] != b[:2] or not (isinstance(a[2], dict) and isinstance(b[2], dict)):
            return a == b
        return all(key in b[2] and b[2][key] == value for key, value in a[2].items())

    before, after = positions(original), positions(replayed)
    difference = None
    for a, b in zip(before, after, strict=False):
        if not same(a, b):
            difference = f"at {a[0]} ms ({a[1]} P): online {a[2]} != replay {b[2]}"
            break
    if difference is None and len(before) != len(after):
        difference = f"online log has {len(before)} positions, the replay {len(after)}"
    return ReplayResult(
        output, syncs, len(after), min(len(before), len(after)), difference is None, difference, report
    )
