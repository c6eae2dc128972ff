"""Data and error logs of the localisation (seed 000, §6.8.1, §6.8.3, appendix B.2), as msgpack streams.

A **data log** starts with a header map (``tokenring_log: data``, the start time and the whole
configuration), followed by one msgpack array per record::

    [stamp_ms, source, kind, payload]

``stamp_ms`` is the sensor's own time (ms of simulated time); ``source`` and ``kind`` are the
seed's letters (table B.6) plus ours:

=======  ============================  =====  =====================================
source   meaning                       kind   meaning
=======  ============================  =====  =====================================
S        system                        R      raw data
O        odometry (motor steps)        C      synchronised data
G        gyroscope                     P      position
W        sonar and wall detection      S      synchronisation finished
B        battery (ours)                T      program start time
L        LOPS                          W      wall data (known walls, map walls)
K        Kalman filter                 E      event (ours: pose set, walls loaded)
C        floor correlator
M        magnetic compass (ours)
T        the world's truth (ours)
=======  ============================  =====  =====================================

The sensors' letters, their payloads and their line formats come from the sensor registry
(:mod:`modules.localization.sensors`, one file a sensor): :data:`SOURCES`, :data:`SENSOR_SOURCE`,
:data:`SOURCE_SENSOR` and :data:`PAYLOADS` are worked out from it when read.

``T`` is the simulator's ground truth, for scoring and plots only, never fused. Logs of format
version 1 carried it under ``L`` (LOPS's letter, while there was no LOPS): the reader takes their
``L`` records as ``T``. Logs of versions 1 and 2 carried the compass under ``G`` (the gyroscope's
letter, while there was no gyroscope): the reader takes them as ``M``.

An **error log** has a header map (``tokenring_log: errors``) and records ``[stamp_ms, class,
text]`` with the seed's classes I (information), W (warning: no data lost), E (error: data
lost), F (fatal), D (debug).

Crash safety: every record is one ``write()`` on an unbuffered descriptor, so a killed process
leaves every record written before the kill; a reader stops cleanly at a torn last record and
says so. A full disk costs only the log: the writer cuts the file back to its last whole record,
says so in one line and writes nothing more (never after a torn record).

``convert_*`` produce the seed's line-per-entry text (:func:`convert_seed_text`: exactly
appendix B's line formats), the seed's logfileconverter's ``data.dat`` and ``sonar.dat``
(:func:`convert_seed_dat`: exactly table B.8, one line per synchronisation) and CSV with our own
columns (:func:`convert_csv`, one line per synchronisation); :func:`sort_log` is the seed's
logfilesorter.
"""

from __future__ import annotations

import contextlib
import csv
import io
import os
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgpack

from modules.localization.records import (
    Check,
    SeedContext,
    fields,
    integer,
    mapping,
    num,
    number,
    seed_int,
    seed_obstacles,
    seed_position,
    sonar_mounts,
)
from modules.localization.records import flags as valid_flags
from modules.localization.records import text as is_text
from modules.localization.sensors import Sensor, registered, sensor_named, sensor_of_letter
from tokenring import UsageError

FORMAT_VERSION = 3
#: what a log of an older format version called a source that has another letter now
RENAMED_SOURCES: dict[int, dict[str, str]] = {1: {"L": "T", "G": "M"}, 2: {"G": "M"}}
#: the sources that are not sensors (appendix B: the system, the Kalman filter)
OTHER_SOURCES = {"S": "system", "K": "filter"}
KINDS = {
    "R": "raw",
    "C": "synchronised",
    "P": "position",
    "S": "sync finished",
    "T": "start time",
    "W": "wall data",
    "E": "event",
}
ERROR_CLASSES = {"I": "information", "W": "warning", "E": "error", "F": "fatal", "D": "debug"}
#: the seed's Debuglevel (table B.1): the least level at which a class is written — 0 fatal
#: only, 1 also errors, 2 warnings, 3 information (the default), 4 debug messages too
CLASS_LEVELS = {"F": 0, "E": 1, "W": 2, "I": 3, "D": 4}
DEFAULT_DEBUG_LEVEL = 3
#: where the logs go, relative to the hosting node's working directory (``logs.directory``)
DEFAULT_LOG_DIRECTORY = "logs"


def sources() -> dict[str, str]:
    """Every source letter and what it is: the system, each registered sensor, the filter."""
    return {"S": "system", **{sensor.letter: sensor.title for sensor in registered()}, "K": "filter"}


def __getattr__(name: str) -> Any:
    """The tables the registry makes, worked out when read (PEP 562): :data:`SOURCES` (letter:
    title), :data:`SENSOR_SOURCE` (sensor: letter), :data:`SOURCE_SENSOR` (letter: sensor) and
    :data:`PAYLOADS` ((source, kind): check), :data:`DATA_COLUMNS` (``data.csv``'s)."""
    if name == "SOURCES":
        return sources()
    if name == "SENSOR_SOURCE":
        return {sensor.name: sensor.letter for sensor in registered()}
    if name == "SOURCE_SENSOR":
        return {sensor.letter: sensor.name for sensor in registered()}
    if name == "PAYLOADS":
        checks = {(s.letter, kind): _sensor_check(s, kind) for s in registered() for kind in "RC"}
        return {**checks, **OTHER_PAYLOADS}
    if name == "DATA_COLUMNS":
        return data_columns()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


class LogError(UsageError):
    """A log file that cannot be read as asked; the message names the file."""


class _Stream:
    """An append-only msgpack stream: one unbuffered write per record, thread-safe.

    A write that fails (a full disk, a quota, an I/O error) cuts the file back to its last whole
    record and ends the stream: nothing is ever appended after a torn record, even once there is
    room again. With ``on_failure`` the stream tells it once, in one line naming the file, and
    drops every later record (the writer goes on without its log); without it the
    :class:`OSError` is raised. ``name``: what messages call the file (the target of a
    temporary file that is renamed once whole)."""

    def __init__(
        self,
        path: str | Path,
        header: dict[str, Any],
        on_failure: Callable[[str], None] | None = None,
        name: str | Path | None = None,
    ) -> None:
        self.path = Path(path)
        self.name = Path(name) if name is not None else self.path  # the file's name in messages
        self.on_failure = on_failure
        #: why the stream ended early (one line naming the file), or None
        self.failure: str | None = None
        self._lock = threading.Lock()
        self._packer = msgpack.Packer(use_bin_type=True)
        self.records = 0  # entries written whole, the header included
        self._size = 0  # bytes of those entries: where a torn write is cut back to
        self._fd = -1
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            flags = os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_APPEND | getattr(os, "O_CLOEXEC", 0)
            self._fd = os.open(self.path, flags, 0o644)
        except OSError as exc:
            with self._lock:
                self._fail(exc, opened=False)
            return
        self._write(header)

    def _write(self, obj: Any) -> None:
        data = self._packer.pack(obj)
        with self._lock:
            if self._fd < 0:
                return
            view = memoryview(data)
            try:
                while view:
                    written = os.write(self._fd, view)
                    view = view[written:]
            except OSError as exc:
                self._fail(exc)
                return
            self.records += 1
            self._size += len(data)

    def _fail(self, exc: OSError, opened: bool = True) -> None:
        """End the stream at its last whole record (called with the lock held)."""
        if self._fd >= 0:
            with contextlib.suppress(OSError):
                os.ftruncate(self._fd, self._size)  # shrinking needs no space
            with contextlib.suppress(OSError):
                os.close(self._fd)
            self._fd = -1
        if opened and self._size == 0:  # not even the header is whole: no empty file is left
            with contextlib.suppress(OSError):
                self.path.unlink()
        kept = (
            f"it ends at its last whole record ({self.records - 1} records)"
            if self.records
            else "no log kept"
        )
        self.failure = f"{self.name}: cannot write: {exc.strerror or exc}; {kept}"
        if self.on_failure is None:
            raise exc
        self.on_failure(self.failure)

    def close(self) -> None:
        with self._lock:
            if self._fd >= 0:
                os.close(self._fd)
                self._fd = -1

    def __enter__(self) -> _Stream:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class DataLog(_Stream):
    """The data log: raw, synchronised and position records per source."""

    def __init__(
        self,
        path: str | Path,
        start: str,
        config: dict[str, Any],
        meta: dict[str, Any] | None = None,
        on_failure: Callable[[str], None] | None = None,
        name: str | Path | None = None,
    ):
        header = {
            "tokenring_log": "data",
            "version": FORMAT_VERSION,
            "start": start,
            "config": config,
            "meta": meta or {},
        }
        super().__init__(path, header, on_failure, name)

    def write(self, stamp_ms: int, source: str, kind: str, payload: Any) -> None:
        self._write([int(stamp_ms), source, kind, payload])


class ErrorLog(_Stream):
    """The error log: class, time stamp, text; the classes above ``level`` (the seed's
    Debuglevel, :data:`CLASS_LEVELS`) are not written. Without a level, ``debug`` says 4 or 3."""

    def __init__(
        self,
        path: str | Path,
        start: str,
        debug: bool = False,
        on_failure: Callable[[str], None] | None = None,
        name: str | Path | None = None,
        *,
        level: int | None = None,
    ) -> None:
        if level is None:
            level = 4 if debug else DEFAULT_DEBUG_LEVEL
        if not 0 <= level <= 4:
            raise ValueError(f"debug level {level} is not within 0-4")
        self.level = level
        self.debug = level >= CLASS_LEVELS["D"]
        header = {"tokenring_log": "errors", "version": FORMAT_VERSION, "start": start}
        super().__init__(path, header, on_failure, name)

    def message(self, cls: str, stamp_ms: int, text: str) -> None:
        if cls not in ERROR_CLASSES:
            raise ValueError(f"error class {cls!r} is not one of {''.join(ERROR_CLASSES)}")
        if CLASS_LEVELS[cls] > self.level:
            return
        self._write([int(stamp_ms), cls, text])


# =============================================================================================
# reading


@dataclass
class LogFile:
    """A log read back: header, records, and whether the last record was torn (a crash)."""

    path: Path
    header: dict[str, Any]
    records: list[list[Any]] = field(default_factory=list)
    truncated: bool = False
    #: byte ranges inside the log that could not be read (damage, not a torn tail)
    damaged: list[tuple[int, int]] = field(default_factory=list)

    @property
    def kind(self) -> str:
        return str(self.header.get("tokenring_log"))


#: a log read whole is at most this big (the localisation writes ~1 MB per simulated hour)
MAX_LOG_BYTES = 1 << 30


_RAW = {"gen": integer, "n": integer}
#: what the readers (convert, analyse, replay) take from each kind of record that is not a
#: sensor's ``R`` or ``C`` (a sensor's say its ``raw`` and ``synchronised``): a record whose
#: payload lacks it is damage, reported like unreadable bytes, never a crash later
OTHER_PAYLOADS: dict[tuple[str, str], Check] = {
    ("S", "S"): fields(gen=integer, period_ms=number, counts=mapping),
    ("S", "E"): fields(gen=integer, event=is_text),
    ("W", "W"): fields(gen=integer, event=is_text),
    ("S", "T"): fields(start=is_text),
}


def _sensor_check(sensor: Sensor, kind: str) -> Check:
    """A sensor's ``R`` record: its number in the buffer generation and values its ``raw``
    check takes; its ``C`` record: what its ``synchronised`` check takes."""
    return fields(**_RAW, v=sensor.raw) if kind == "R" else sensor.synchronised


#: optional fields, checked when present
OPTIONAL: dict[str, Check] = {"valid": valid_flags, "seq": integer, "gen": integer}
_POSITION = fields(x=number, y=number, psi=number)


def payload_ok(source: str, kind: str, payload: Any) -> bool:
    """Whether a data record's payload has what the readers take from it (:data:`PAYLOADS`;
    positions ``P`` of any source need x, y and psi)."""
    sensor = sensor_of_letter(source) if kind in ("R", "C") else None
    if kind == "P":
        check: Check | None = _POSITION
    elif sensor is not None:
        check = _sensor_check(sensor, kind)
    else:
        check = OTHER_PAYLOADS.get((source, kind))
    if check is None:
        return True  # shown as it is (``key=value``), never read field by field
    if not check(payload):
        return False
    return all(check(payload[name]) for name, check in OPTIONAL.items() if name in payload)


def _is_record(obj: Any, kind: str) -> bool:
    """Whether ``obj`` is a record: ``[stamp, source, kind, payload]`` with the letters of the
    tables and a payload the readers can take (:func:`payload_ok`) for a data log,
    ``[stamp, class, text]`` for an error log."""
    if not isinstance(obj, list) or not obj or isinstance(obj[0], bool) or not isinstance(obj[0], int):
        return False
    if kind == "data":
        return (
            len(obj) == 4 and isinstance(obj[1], str) and isinstance(obj[2], str)
            and (obj[1] in OTHER_SOURCES or sensor_of_letter(obj[1]) is not None)
            and obj[2] in KINDS and payload_ok(obj[1], obj[2], obj[3])
        )  # fmt: skip
    return len(obj) == 3 and isinstance(obj[1], str) and obj[1] in ERROR_CLASSES and isinstance(obj[2], str)


#: a record is decoded from a window this big first (records are bytes to kilobytes; a window
#: keeps the resynchronising scan linear in the damage, not in the file)
RECORD_WINDOW = 1 << 18


_TORN = "torn"  # what _entry_at says when the data ends inside an entry


def _entry_at(data: bytes, offset: int) -> tuple[Any, int] | str | None:
    """The msgpack entry that starts at ``offset`` and where it ends; :data:`_TORN` when the
    data ends inside it (a writer killed in the middle), None for garbage."""
    window = RECORD_WINDOW
    while True:
        unpacker = msgpack.Unpacker(raw=False, strict_map_key=False, max_buffer_size=window + 1)
        unpacker.feed(data[offset : offset + window])
        try:
            return next(unpacker), offset + unpacker.tell()
        except (StopIteration, msgpack.OutOfData):
            if offset + window >= len(data):
                return _TORN
            window *= 4  # an entry longer than the window: look further
        except Exception:  # garbage: msgpack raises ValueError, FormatError, UnicodeDecodeError ...
            return None


def _record_at(
    data: bytes, offset: int, kind: str, renamed: dict[str, str] | None = None
) -> tuple[Any, int] | None:
    """The record that starts at ``offset`` and where it ends, or None; a data record's source
    letter as ``renamed`` says (an older format's)."""
    entry = _entry_at(data, offset)
    if not isinstance(entry, tuple):
        return None
    record = entry[0]
    if renamed and isinstance(record, list) and len(record) == 4 and isinstance(record[1], str):
        record[1] = renamed.get(record[1], record[1])
    if not _is_record(record, kind):
        return None
    return entry


def _resync(data: bytes, start: int, kind: str, renamed: dict[str, str] | None = None) -> int | None:
    """The first offset after ``start`` where two records in a row (or one at the very end)
    decode: where reading goes on after damage. None: nothing readable follows."""
    for offset in range(start + 1, len(data)):
        first = _record_at(data, offset, kind, renamed)
        if first is None:
            continue
        end = first[1]
        if end == len(data) or _record_at(data, end, kind, renamed) is not None:
            return offset
    return None


def read_log(path: str | Path, expect: str | None = None, salvage: bool = False) -> LogFile:
    """Read a whole log; ``expect`` (``data``/``errors``) refuses the other kind.

    A torn last record (the writer was killed) is normal: reading stops before it and
    ``truncated`` says so. Damage *inside* the log is not: every readable record is kept (reading
    resynchronises past it: two records in a row decode again), ``damaged`` lists the byte
    ranges skipped, and without ``salvage`` the read fails with one line saying where and how
    much; with it the readable records are returned."""
    from tokenring import message_error, read_bytes

    file = Path(path)
    data = read_bytes(file, "log file", message_error(LogError), limit=MAX_LOG_BYTES)
    unpacker = msgpack.Unpacker(raw=False, strict_map_key=False, max_buffer_size=len(data) + 1)
    unpacker.feed(data)
    try:
        header = next(unpacker)
    except (StopIteration, msgpack.OutOfData):
        raise LogError(f"{file}: empty or torn before its header; not a tokenring log") from None
    except Exception:
        raise LogError(f"{file}: not a tokenring log (no msgpack header)") from None
    if not isinstance(header, dict) or header.get("tokenring_log") not in ("data", "errors"):
        raise LogError(f"{file}: not a tokenring log (its first entry is not a log header)")
    kind = str(header["tokenring_log"])
    if expect is not None and kind != expect:
        raise LogError(f"{path}: this is a {kind} log, not a {expect} log")
    version = header.get("version", FORMAT_VERSION)
    renamed = RENAMED_SOURCES.get(version) if kind == "data" and isinstance(version, int) else None
    records: list[list[Any]] = []
    damaged: list[tuple[int, int]] = []
    offset = unpacker.tell()
    truncated = False
    while offset < len(data):
        found = _record_at(data, offset, kind, renamed)
        if found is not None:
            records.append(found[0])
            offset = found[1]
            continue
        resume = _resync(data, offset, kind, renamed)
        if resume is None:
            if _entry_at(data, offset) == _TORN:
                truncated = True  # the writer was killed in the middle of its last record
            else:
                damaged.append((offset, len(data)))  # a whole entry there, but no record
            break
        damaged.append((offset, resume))
        offset = resume
    out = LogFile(file, header, records)
    out.truncated = truncated
    out.damaged = damaged
    if damaged and not salvage:
        skipped = sum(b - a for a, b in damaged)
        first = ", ".join(f"{a}..{b}" for a, b in damaged[:3]) + (" ..." if len(damaged) > 3 else "")
        raise LogError(
            f"{file}: damaged inside: {skipped} bytes unreadable in {len(damaged)} place(s) at bytes "
            f"{first}; {len(records)} records readable around them (--salvage reads those)"
        )
    return out


# =============================================================================================
# converting and sorting


def _position_text(p: dict[str, Any]) -> str:
    valid = p.get("valid", [True, True, True])
    return f"{num(p.get('x'))} {num(p.get('y'))} {num(p.get('psi'), 8, 5)} " + " ".join(
        "1" if v else "0" for v in valid
    )


def _values(kind: str, p: dict[str, Any]) -> dict[str, Any]:
    """What a sensor's text hooks are handed: an ``R`` record's values, a ``C`` record's payload."""
    return p.get("v", p) if kind == "R" else p


def record_text(record: list[Any]) -> str:
    """One data-log record in the seed's line format (tables B.6/B.7): ``S K   stamp data``."""
    stamp, source, kind, payload = record
    head = f"{source} {kind} {stamp:>8d}"
    body = _record_body(source, kind, payload)
    return f"{head} {body}".rstrip()


def _record_body(source: str, kind: str, p: Any) -> str:
    if kind == "P" or (source == "S" and kind == "S" and isinstance(p, dict) and "x" in p):
        return _position_text(p)
    if not isinstance(p, dict):
        return str(p)
    sensor = sensor_of_letter(source) if kind in ("R", "C") else None
    if sensor is not None and sensor.text is not None:
        return sensor.text(kind, _values(kind, p))
    if source == "S" and kind == "T":
        return str(p.get("start", ""))
    if source == "S" and kind == "S":
        counts = p.get("counts", {})
        return f"{p.get('gen', 0):>6} {p.get('period_ms', 0):>5} " + " ".join(
            f"{_letter(k)}{n}" for k, n in counts.items()
        )
    flat = " ".join(f"{k}={val}" for k, val in p.items() if k not in ("gen", "n"))
    return flat


def _letter(name: str) -> str:
    """A sensor's letter (its name when no sensor of that name is registered)."""
    sensor = sensor_named(name)
    return sensor.letter if sensor is not None else name


def convert_text(log: LogFile) -> str:
    """The whole log in the seed's text format (the data log's or the error log's)."""
    out = io.StringIO()
    if log.kind == "errors":
        for stamp, cls, text in log.records:
            out.write(f"{cls} {stamp:>8d} {text}\n")
        return out.getvalue()
    out.write(f"S T {0:>8d} {log.header.get('start', '')}\n")
    for record in log.records:
        out.write(record_text(record) + "\n")
    return out.getvalue()


# ---------------------------------------------------------------------------------------------
# the seed's exact text (seed 000, appendix B: figure B.3 for the widths, table B.7 for the fields)


def seed_start_time(start: str, path: str | Path = "") -> str:
    """The header's start (``YYYYmmdd-HHMMSS``) as the seed's 19-character ``TT.MM.JJJJ
    HH:MM:SS``, padded with blanks as figure B.3 shows it (``20. 1.2004 13: 5:35``)."""
    from datetime import datetime

    try:
        t = datetime.strptime(start, "%Y%m%d-%H%M%S")
    except (TypeError, ValueError):
        raise LogError(f"{path}: start time {start!r} is not YYYYmmdd-HHMMSS; no seed S T line") from None
    return f"{t.day:2d}.{t.month:2d}.{t.year:4d} {t.hour:2d}:{t.minute:2d}:{t.second:2d}"


def convert_seed_text(log: LogFile) -> str:
    """The whole log exactly in the seed's line formats (seed 000, appendix B): the error log
    as figure B.2, the data log as figure B.3 where it shows a line (``S T``, ``x P``, ``S S``,
    ``G R/C``, ``O R/C``) and as table B.7 where it does not (the sonar's new flags, obstacle
    points and wall blocks). ``S S`` carries the filter's position as the synchronisation began
    (the ``K P`` of the one before; all unknown at the first, as in figure B.3)."""
    if log.kind == "errors":
        return convert_text(log)
    out = io.StringIO()
    out.write(f"S T {0:6d} {seed_start_time(log.header.get('start', ''), log.path)}\n")
    context = SeedContext(log.header.get("config"), log.records)
    filter_now: dict[str, Any] | None = None
    filter_at_sync: dict[str, Any] | None = None
    for i, (stamp, source, kind, p) in enumerate(log.records):
        if source == "S" and kind == "T":
            out.write(f"S T {stamp:6d} {seed_start_time(p['start'], log.path)}\n")
            continue
        head = f"{source} {kind} {stamp:7d}"
        sensor = sensor_of_letter(source) if kind in ("R", "C") else None
        if kind == "P":
            body = seed_position(p)
            if source == "K":
                filter_now = p
        elif source == "S" and kind == "S":
            body = seed_position(filter_at_sync)
            filter_at_sync = filter_now
        elif sensor is not None and sensor.seed_text is not None:
            context.index = i
            body = sensor.seed_text(kind, _values(kind, p), context)
        else:
            # ours alone (events, battery): no seed format; one line whatever text it holds
            body = _record_body(source, kind, p).replace("\r", "\\r").replace("\n", "\\n")
        out.write(f"{head} {body}".rstrip() + "\n")
    return out.getvalue()


#: ``data.csv``'s columns of the positions: the truth, dead reckoning and the filter
POSITION_COLUMNS = [
    "truth_x", "truth_y", "truth_psi", "truth_valid",
    "odo_x", "odo_y", "odo_psi",
    "x", "y", "psi", "x_valid", "y_valid", "psi_valid",
]  # fmt: skip


def data_columns() -> list[str]:
    """``data.csv``'s columns: the time, each sensor's synchronised values (its ``csv_columns``,
    in synchronisation order), then the positions (:data:`POSITION_COLUMNS`)."""
    sensors = [column for sensor in registered() for column in sensor.csv_columns]
    return ["stamp_ms", "period_ms", *sensors, *POSITION_COLUMNS]


def convert_csv(log: LogFile) -> tuple[str, str]:
    """The seed's logfileconverter: ``data.csv`` (one line per sync) and ``sonar.csv``."""
    if log.kind != "data":
        raise LogError(f"{log.path}: CSV conversion needs a data log")
    data, sonar = io.StringIO(), io.StringIO()
    dw, sw = csv.writer(data, lineterminator="\n"), csv.writer(sonar, lineterminator="\n")
    columns = data_columns()
    dw.writerow(columns)
    sonar_header_written = False
    row: dict[str, Any] = {}
    distances: list[Any] = []
    last_stamp: int | None = None
    for stamp, source, kind, p in log.records:
        sensor = sensor_of_letter(source) if kind == "C" else None
        if sensor is not None and sensor.csv is not None:
            row.update(sensor.csv(p))
        if kind == "C" and source == "W":
            distances = p["distances_mm"]
        elif kind == "P" and source == "T":
            row.update(truth_x=p["x"], truth_y=p["y"], truth_psi=p["psi"], truth_valid=1)
        elif kind == "P" and source == "O":
            row.update(odo_x=p["x"], odo_y=p["y"], odo_psi=p["psi"])
        elif kind == "P" and source == "K":
            valid = p.get("valid", [1, 1, 1])
            row.update(
                x=p["x"],
                y=p["y"],
                psi=p["psi"],
                x_valid=int(valid[0]),
                y_valid=int(valid[1]),
                psi_valid=int(valid[2]),
            )
        elif source == "S" and kind == "S":
            row["stamp_ms"] = stamp
            row["period_ms"] = stamp - last_stamp if last_stamp is not None else 0
            last_stamp = stamp
            dw.writerow([row.get(c, "") for c in columns])
            if not sonar_header_written and distances:
                sw.writerow(["stamp_ms", *[f"sonar{i}_mm" for i in range(len(distances))]])
                sonar_header_written = True
            sw.writerow([stamp, *["" if d is None else d for d in distances]])
            row = {}
    return data.getvalue(), sonar.getvalue()


#: the width of each of ``sonar.dat``'s obstacle coordinates (table B.8)
SEED_SONAR_DAT_WIDTH = 6
#: table B.8's sonar.dat: an obstacle's x and y "für alle 16 Empfänger" (the seed's two rings of
#: eight); a robot with fewer fills the rest as the seed writes a sonar that saw nothing
SEED_DAT_SONARS = 16


def convert_seed_dat(log: LogFile) -> tuple[str, str]:
    """The seed's logfileconverter exactly as table B.8 (seed 000, appendix B.3) defines its
    output: ``data.dat`` and ``sonar.dat``, one line per synchronisation in each (an ``S S``
    ends one; the records of a synchronisation come before it), fields separated by blanks.

    ``data.dat``, each field right-aligned in table B.8's width (in characters: 8 4 8 8 15 8 8 8
    8 8 1 8 8 8 1 1 1): Zeitpunkt, the ``S S`` stamp in ms since program
    start, counted as :func:`convert_seed_text` counts it (its ``S T`` line is at 0: the log's
    stamps as they are, ms of simulated time since the world started, no shift to the first
    synchronisation); Takt, the ms since the synchronisation before (the ``S S``'s
    ``period_ms``, 0 at the first); the encoder increments (``O C``'s ``dl``, ``dr``); Gyroskop,
    ``G C``'s ``turn``, the angle over the period in rad as :func:`convert_seed_text` writes the
    seed's ``G C``; LOPS's three distances, its position and its valid flag (``L C``); the
    filter's position as this synchronisation left it (its ``K P``) with the three valid flags.
    ``sonar.dat``: per sonar the obstacle's x and y (robot coordinates, mm; ``W C``'s distances
    from the mounts of the log's configuration), the table's sixteen sonars on every line (more if
    the robot has more, or a ``W C`` carried more).

    What the log lacks (no gyroscope or LOPS in a Hamburg run, no filter, no sonar) is written
    ``0`` as the seed writes unknown values, its valid flags 0. Records after the last ``S S``
    (a synchronisation the log ends inside) are not written; nor are the compass, the floor
    correlator and the truth, which table B.8 has no columns for. The sensors' columns are
    theirs (each one's ``dat``, in synchronisation order: odometry, gyroscope, LOPS): a sensor
    added brings its own, before the filter's."""
    if log.kind != "data":
        raise LogError(f"{log.path}: data.dat and sonar.dat (table B.8) need a data log")
    mounts = sonar_mounts(log.header.get("config"))
    sonars = max(
        [SEED_DAT_SONARS, len(mounts)]
        + [len(p["distances_mm"]) for _, source, kind, p in log.records if (source, kind) == ("W", "C")]
    )
    columns = [sensor for sensor in registered() if sensor.dat is not None]
    data, sonar = io.StringIO(), io.StringIO()
    sync: dict[str, Any] = {}
    for stamp, source, kind, p in log.records:
        if kind == "C" and (source == "W" or any(source == sensor.letter for sensor in columns)):
            sync[source] = p
        elif kind == "P" and source == "K":
            sync["K"] = p
        elif source == "S" and kind == "S":
            fields_ = [f"{stamp:8d}", seed_int(p["period_ms"], 4)]
            fields_ += [sensor.dat(sync.get(sensor.letter)) for sensor in columns if sensor.dat is not None]
            data.write(" ".join([*fields_, seed_position(sync.get("K"), 8, 8)]) + "\n")
            distances: list[float | None] = list(sync["W"]["distances_mm"]) if "W" in sync else []
            distances += [None] * (sonars - len(distances))
            sonar.write(" ".join(seed_obstacles(distances, mounts, SEED_SONAR_DAT_WIDTH)) + "\n")
            sync = {}
    return data.getvalue(), sonar.getvalue()


def sort_log(source: str | Path, target: str | Path, salvage: bool = False) -> int:
    """Write ``source`` sorted by time stamp (stable) to ``target``; returns the record count."""
    if Path(source).resolve() == Path(target).resolve():
        raise LogError(f"{target}: the sorted log must go to a new file (the seed's logfilesorter)")
    log = read_log(source, salvage=salvage)
    key = (lambda r: r[0]) if log.kind in ("data", "errors") else None
    records = sorted(log.records, key=key)
    from tokenring import replacing

    with replacing(target) as temp, _Stream(temp, log.header) as stream:
        for record in records:
            stream._write(record)
    return len(records)


def summary(log: LogFile) -> dict[str, Any]:
    """Counts per source and kind, time range, and whether the log was torn."""
    counts: dict[str, int] = {}
    first = last = None
    for record in log.records:
        stamp = record[0]
        key = f"{record[1]} {record[2]}" if log.kind == "data" else str(record[1])
        counts[key] = counts.get(key, 0) + 1
        first = stamp if first is None else min(first, stamp)
        last = stamp if last is None else max(last, stamp)
    return {
        "file": str(log.path),
        "kind": log.kind,
        "start": log.header.get("start"),
        "records": len(log.records),
        "first_ms": first,
        "last_ms": last,
        "truncated": log.truncated,
        "counts": dict(sorted(counts.items())),
    }
