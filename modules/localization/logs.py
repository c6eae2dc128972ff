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
import math
import os
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgpack

from tokenring import UsageError

FORMAT_VERSION = 3
#: what a log of an older format version called a source that has another letter now
RENAMED_SOURCES: dict[int, dict[str, str]] = {1: {"L": "T", "G": "M"}, 2: {"G": "M"}}
#: the gyroscope's sample period (seed §3.2): the seed logged a rate as the angle of one sample
GYRO_SAMPLE_S = 0.02048
SOURCES = {
    "S": "system",
    "O": "odometry",
    "G": "gyroscope",
    "M": "compass",
    "W": "sonar",
    "B": "battery",
    "L": "LOPS",
    "T": "truth",
    "K": "filter",
    "C": "correlator",
}
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
SENSOR_SOURCE = {
    "odometry": "O",
    "compass": "M",
    "gyro": "G",
    "correlator": "C",
    "sonar": "W",
    "battery": "B",
    "truth": "T",
    "lops": "L",
}
SOURCE_SENSOR = {v: k for k, v in SENSOR_SOURCE.items()}


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
    """The error log: class, time stamp, text."""

    def __init__(
        self,
        path: str | Path,
        start: str,
        debug: bool = False,
        on_failure: Callable[[str], None] | None = None,
        name: str | Path | None = None,
    ) -> None:
        self.debug = debug
        header = {"tokenring_log": "errors", "version": FORMAT_VERSION, "start": start}
        super().__init__(path, header, on_failure, name)

    def message(self, cls: str, stamp_ms: int, text: str) -> None:
        if cls not in ERROR_CLASSES:
            raise ValueError(f"error class {cls!r} is not one of {''.join(ERROR_CLASSES)}")
        if cls == "D" and not self.debug:
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


Check = Callable[[Any], bool]


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _integer(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _text(value: Any) -> bool:
    return isinstance(value, str)


def _mapping(value: Any) -> bool:
    return isinstance(value, dict)


def _integers(value: Any) -> bool:
    return isinstance(value, list) and all(_integer(v) for v in value)


def _numbers_or_none(value: Any) -> bool:
    return isinstance(value, list) and all(v is None or _number(v) for v in value)


def _flags(value: Any) -> bool:
    return isinstance(value, list) and len(value) == 3 and all(isinstance(v, (bool, int)) for v in value)


def _walls(value: Any) -> bool:
    return isinstance(value, list) and all(
        isinstance(w, dict) and _number(w.get("alpha")) and _number(w.get("d")) for w in value
    )


def _fields(**checks: Check) -> Check:
    """A mapping with at least these fields, each passing its check (more fields may follow)."""
    return lambda value: (
        isinstance(value, dict)
        and all(name in value and check(value[name]) for name, check in checks.items())
    )


def _odometry(values: Any) -> bool:
    """Steps, and the motor's dead-reckoned pose with all three fields when it is there."""
    steps = _fields(steps_left=_integer, steps_right=_integer)(values)
    pose = _fields(x_mm=_integer, y_mm=_integer, angle_cdeg=_integer)
    return steps and ("x_mm" not in values or pose(values))


def _lops(values: Any) -> bool:
    """LOPS's counter, its three distances and its position (mm; None where it has none)."""
    if not _fields(counter=_integer)(values):
        return False
    return all(
        values.get(k) is None
        or (isinstance(values.get(k), int | float) and not isinstance(values.get(k), bool))
        for k in ("d1", "d2", "d3", "x", "y")
    )


_RAW = {"gen": _integer, "n": _integer}
#: what the readers (convert, analyse, replay) take from each kind of data record: a record
#: whose payload lacks it is damage, reported like unreadable bytes, never a crash later
PAYLOADS: dict[tuple[str, str], Check] = {
    ("O", "R"): _fields(**_RAW, v=_odometry),
    ("M", "R"): _fields(**_RAW, v=_fields(heading_cdeg=_number)),
    ("G", "R"): _fields(**_RAW, v=_fields(rate_urad_s=_number, angle_mrad=_number)),
    ("C", "R"): _fields(**_RAW, v=_fields(forward_um=_number, increment_um=_number)),
    ("W", "R"): _fields(**_RAW, v=_fields(distances=_integers)),
    ("T", "R"): _fields(**_RAW, v=_fields(x=_number, y=_number, theta=_number)),
    ("L", "R"): _fields(**_RAW, v=_lops),
    ("B", "R"): _fields(**_RAW, v=_mapping),
    ("O", "C"): _fields(dl=_number, dr=_number, count=_integer),
    ("M", "C"): _fields(heading=_number, count=_integer),
    ("G", "C"): _fields(rate=_number, turn=_number, count=_integer),
    ("C", "C"): _fields(distance=_number, speed=_number, count=_integer),
    ("W", "C"): lambda p: (
        _fields(distances_mm=_numbers_or_none, count=_integer)(p) and _walls(p.get("walls", []))
    ),
    ("T", "C"): _fields(x=_number, y=_number, theta=_number, count=_integer),
    ("L", "C"): lambda p: _lops(p) and _fields(count=_integer)(p),
    ("B", "C"): _mapping,
    ("S", "S"): _fields(gen=_integer, period_ms=_number, counts=_mapping),
    ("S", "E"): _fields(gen=_integer, event=_text),
    ("W", "W"): _fields(gen=_integer, event=_text),
    ("S", "T"): _fields(start=_text),
}
#: optional fields, checked when present
OPTIONAL: dict[str, Check] = {"valid": _flags, "seq": _integer, "gen": _integer}
_POSITION = _fields(x=_number, y=_number, psi=_number)


def payload_ok(source: str, kind: str, payload: Any) -> bool:
    """Whether a data record's payload has what the readers take from it (:data:`PAYLOADS`;
    positions ``P`` of any source need x, y and psi)."""
    check = _POSITION if kind == "P" else PAYLOADS.get((source, kind))
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
            and obj[1] in SOURCES and obj[2] in KINDS and payload_ok(obj[1], obj[2], obj[3])
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


def _num(value: Any, width: int = 8, digits: int = 0) -> str:
    if value is None:
        return f"{0:>{width}}"
    if isinstance(value, bool):
        return "1" if value else "0"
    if digits:
        return f"{float(value):>{width}.{digits}f}"
    return f"{round(float(value)):>{width}d}" if math.isfinite(float(value)) else f"{'nan':>{width}}"


def _lops_text(v: dict[str, Any]) -> str:
    """LOPS's three distances (mm; 0 where nothing was heard) and its counter, appendix B's order."""
    return " ".join(_num(v.get(k)) for k in ("d1", "d2", "d3")) + f" {v.get('counter', 0):>8}"


def _position_text(p: dict[str, Any]) -> str:
    valid = p.get("valid", [True, True, True])
    return f"{_num(p.get('x'))} {_num(p.get('y'))} {_num(p.get('psi'), 8, 5)} " + " ".join(
        "1" if v else "0" for v in valid
    )


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
    v = p.get("v", p)
    if source == "O" and kind == "R":
        return f"{_num(v['steps_left'])} {_num(v['steps_right'])}"
    if source == "O" and kind == "C":
        return f"{_num(p['dl'])} {_num(p['dr'])} {p['count']}"
    if source == "M" and kind == "R":
        return f"{_num(v['heading_cdeg'], 6)} {v.get('state', 1)}"
    if source == "M" and kind == "C":
        return f"{_num(p['heading'], 15, 12)} {p['count']}"
    if source == "G" and kind == "R":
        return f"{float(v['rate_urad_s']) / 1e6:15.12f} {v.get('state', 2)}"
    if source == "G" and kind == "C":
        return f"{float(p['rate']):15.12f} {float(p['turn']):15.12f} {p['count']}"
    if source == "C" and kind == "R":
        return (
            f"{_num(float(v['increment_um']) / 1000.0, 8, 3)} {_num(float(v['forward_um']) / 1000.0, 10, 3)}"
        )
    if source == "C" and kind == "C":
        return f"{_num(p['distance'], 8, 3)} {p['count']}"
    if source == "W" and kind == "R":
        return " ".join(_num(d * 10 if d != 255 else 0, 5) for d in v["distances"])
    if source == "W" and kind == "C":
        parts = [_num(d, 5) for d in p["distances_mm"]]
        for w in p.get("walls", []):
            parts.append(f"1 {w['alpha']:.5f} {w['d']:.1f} {w.get('assoc', -1):>2}")
        return " ".join(parts) + f" {p['count']}"
    if source == "L" and kind in "RC":
        return _lops_text(v if kind == "R" else p) + (f" {p['count']}" if kind == "C" else "")
    if source == "T" and kind in "RC":
        return f"{_num(v['x'])} {_num(v['y'])} {_num(v['theta'], 8, 5)}" + (
            f" {p['count']}" if kind == "C" else ""
        )
    if source == "S" and kind == "T":
        return str(p.get("start", ""))
    if source == "S" and kind == "S":
        counts = p.get("counts", {})
        return f"{p.get('gen', 0):>6} {p.get('period_ms', 0):>5} " + " ".join(
            f"{SENSOR_SOURCE.get(k, k)}{n}" for k, n in counts.items()
        )
    flat = " ".join(f"{k}={val}" for k, val in p.items() if k not in ("gen", "n"))
    return flat


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

#: the wall blocks every sonar line carries (table B.7: "für alle 9 Wände")
SEED_WALL_BLOCKS = 9
#: an empty wall block: no wall (flag 0), no angle, no distance, no global wall
SEED_NO_WALL = {"alpha": 0.0, "d": 0.0, "assoc": -1}


def seed_start_time(start: str, path: str | Path = "") -> str:
    """The header's start (``YYYYmmdd-HHMMSS``) as the seed's 19-character ``TT.MM.JJJJ
    HH:MM:SS``, padded with blanks as figure B.3 shows it (``20. 1.2004 13: 5:35``)."""
    from datetime import datetime

    try:
        t = datetime.strptime(start, "%Y%m%d-%H%M%S")
    except (TypeError, ValueError):
        raise LogError(f"{path}: start time {start!r} is not YYYYmmdd-HHMMSS; no seed S T line") from None
    return f"{t.day:2d}.{t.month:2d}.{t.year:4d} {t.hour:2d}:{t.minute:2d}:{t.second:2d}"


def _seed_int(value: Any, width: int) -> str:
    """An integer field right-aligned in ``width`` (the seed's ``%6d``), rounded from mm floats."""
    number = float(value)
    return f"{round(number):{width}d}" if math.isfinite(number) else f"{'nan':>{width}}"


def seed_position(p: dict[str, Any] | None, width: int = 6, angle_width: int = 7) -> str:
    """X, Y, rotation and the three valid flags (table B.7, ``x P`` and ``S S``); an unknown
    value is written as ``0`` (figure B.3: ``      0      0      0 0 0 0``). ``width``: X, Y and
    an unknown rotation's field, ``angle_width``: a known rotation's (figure B.3's 6 and 7 by
    default; table B.8's ``data.dat`` has 8 and 8)."""
    if p is None:
        return f"{0:{width}d} {0:{width}d} {0:{width}d} 0 0 0"
    vx, vy, vpsi = (bool(v) for v in p.get("valid", [True, True, True]))
    x = _seed_int(p["x"], width) if vx else f"{0:{width}d}"
    y = _seed_int(p["y"], width) if vy else f"{0:{width}d}"
    psi = f"{float(p['psi']):{angle_width}.5f}" if vpsi else f"{0:{width}d}"
    return f"{x} {y} {psi} {int(vx)} {int(vy)} {int(vpsi)}"


def _sonar_mounts(config: Any) -> list[tuple[float, float, float]]:
    """Each sonar's (x mm, y mm, angle rad) on the robot: the log's config, else the robot's."""
    robot = config.get("robot") if isinstance(config, dict) else None
    sonars = robot.get("sonars") if isinstance(robot, dict) else None
    if isinstance(sonars, list) and all(
        isinstance(m, list) and len(m) == 3 and all(_number(v) for v in m) for m in sonars
    ):
        return [(float(x), float(y), math.radians(float(a))) for x, y, a in sonars]
    from modules.description.robot import SONAR_MOUNTS

    return [(m.x, m.y, m.angle) for m in SONAR_MOUNTS]


def seed_obstacles(
    distances_mm: list[float | None], mounts: list[tuple[float, float, float]], width: int
) -> list[str]:
    """Per sonar the obstacle's x and y (robot coordinates, mm) right-aligned in ``width``: the
    mount plus the distance along the sonar's axis; ``0 0`` without contact or without a mount
    (table B.7's ``W R``/``W C`` with 5 characters, table B.8's ``sonar.dat`` with 6)."""
    points: list[str] = []
    for i, d in enumerate(distances_mm):
        if d is None or i >= len(mounts):
            points += [f"{0:{width}d}", f"{0:{width}d}"]
            continue
        mx, my, angle = mounts[i]
        points += [_seed_int(mx + d * math.cos(angle), width), _seed_int(my + d * math.sin(angle), width)]
    return points


def seed_sonar(
    distances_mm: list[float | None],
    previous: list[float | None] | None,
    mounts: list[tuple[float, float, float]],
    walls: list[dict[str, Any]],
) -> str:
    """A ``W R``/``W C`` body (table B.7): per sonar the new flag, then per sonar the obstacle's
    x and y (robot coordinates, mm), then per sonar the distance (mm, ``0`` without contact),
    then nine wall blocks ``flag α d association``. A value is new when it differs from the
    previous line's (our sonar channel has no per-sensor flag; the first line is all new)."""
    new = [
        int(previous is None or i >= len(previous) or previous[i] != d) for i, d in enumerate(distances_mm)
    ]
    points = seed_obstacles(distances_mm, mounts, 5)
    ranges = [f"{0:5d}" if d is None else _seed_int(d, 5) for d in distances_mm]
    blocks = []
    for k, wall in enumerate(walls + [SEED_NO_WALL] * max(0, SEED_WALL_BLOCKS - len(walls))):
        found = int(k < len(walls))
        assoc = wall.get("assoc", -1)
        assoc = assoc if _integer(assoc) else -1
        blocks.append(f"{found} {float(wall['alpha']):.5f} {float(wall['d']):.1f} {assoc:2d}")
    return " ".join([*(str(n) for n in new), *points, *ranges, *blocks])


def _wall_associations(records: list[list[Any]]) -> dict[int, list[int]]:
    """For each ``W C`` record (by index) the global wall each of its walls was matched to:
    the ``K P`` of the same synchronisation lists them in order (``[wall, accepted]``)."""
    out: dict[int, list[int]] = {}
    matched: list[int] | None = None
    for i in range(len(records) - 1, -1, -1):
        _, source, kind, p = records[i]
        if source == "S" and kind == "S":
            matched = None  # going back: a synchronisation ends here, the one before starts
        elif source == "K" and kind == "P":
            walls = p.get("walls") if isinstance(p, dict) else None
            matched = [
                w[0] if isinstance(w, list) and w and _integer(w[0]) else -1
                for w in (walls if isinstance(walls, list) else [])
            ]
        elif source == "W" and kind == "C":
            out[i] = matched or []
    return out


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
    mounts = _sonar_mounts(log.header.get("config"))
    associations = _wall_associations(log.records)
    previous: dict[str, list[float | None]] = {}
    filter_now: dict[str, Any] | None = None
    filter_at_sync: dict[str, Any] | None = None
    for i, (stamp, source, kind, p) in enumerate(log.records):
        if source == "S" and kind == "T":
            out.write(f"S T {stamp:6d} {seed_start_time(p['start'], log.path)}\n")
            continue
        head = f"{source} {kind} {stamp:7d}"
        if kind == "P":
            body = seed_position(p)
            if source == "K":
                filter_now = p
        elif source == "S" and kind == "S":
            body = seed_position(filter_at_sync)
            filter_at_sync = filter_now
        elif source == "W" and kind in "RC":
            if kind == "R":
                distances: list[float | None] = [
                    None if d == 255 else int(d) * 10 for d in p["v"]["distances"]
                ]
                walls: list[dict[str, Any]] = []
            else:
                distances = list(p["distances_mm"])
                assoc = associations.get(i, [])
                walls = [
                    {**w, "assoc": assoc[k] if k < len(assoc) else w.get("assoc", -1)}
                    for k, w in enumerate(p.get("walls", []))
                ]
            body = seed_sonar(distances, previous.get(kind), mounts, walls)
            previous[kind] = distances
            if kind == "C":
                body += f" {p['count']}"
        elif source == "O" and kind == "R":
            body = f"{_seed_int(p['v']['steps_left'], 6)} {_seed_int(p['v']['steps_right'], 6)}"
        elif source == "O" and kind == "C":
            body = f"{_seed_int(p['dl'], 6)} {_seed_int(p['dr'], 6)} {p['count']}"
        elif source == "G" and kind == "R":  # the seed's "Drehrate": the angle of one sample
            body = f"{float(p['v']['rate_urad_s']) / 1e6 * GYRO_SAMPLE_S:15.12f}"
        elif source == "G" and kind == "C":  # ... and the angle of the period (figure B.3's sums)
            body = f"{float(p['turn']):15.12f} {p['count']}"
        elif source == "C" and kind == "R":  # the increment (mm): table B.6 names no format
            body = f"{float(p['v']['increment_um']) / 1000.0:8.3f}"
        elif source == "C" and kind == "C":  # ... the sum of the increments (table 3.1)
            body = f"{float(p['distance']):8.3f} {p['count']}"
        elif source == "M" and kind == "R":  # ours: the compass's heading in the gyroscope's format
            body = f"{math.radians(float(p['v']['heading_cdeg']) / 100.0):15.12f}"
        elif source == "M" and kind == "C":
            body = f"{float(p['heading']):15.12f} {p['count']}"
        elif source == "L" and kind in "RC":
            body = _lops_text(p.get("v", p)) + (f" {p['count']}" if kind == "C" else "")
        elif source == "T" and kind in "RC":
            v = p.get("v", p)
            body = seed_position({"x": v["x"], "y": v["y"], "psi": v["theta"]})
            if kind == "C":
                body += f" {p['count']}"
        else:
            # ours alone (events, battery): no seed format; one line whatever text it holds
            body = _record_body(source, kind, p).replace("\r", "\\r").replace("\n", "\\n")
        out.write(f"{head} {body}".rstrip() + "\n")
    return out.getvalue()


DATA_COLUMNS = [
    "stamp_ms", "period_ms", "steps_left", "steps_right", "compass_rad", "gyro_rad_s",
    "truth_x", "truth_y", "truth_psi", "truth_valid",
    "odo_x", "odo_y", "odo_psi",
    "x", "y", "psi", "x_valid", "y_valid", "psi_valid",
]  # fmt: skip


def convert_csv(log: LogFile) -> tuple[str, str]:
    """The seed's logfileconverter: ``data.csv`` (one line per sync) and ``sonar.csv``."""
    if log.kind != "data":
        raise LogError(f"{log.path}: CSV conversion needs a data log")
    data, sonar = io.StringIO(), io.StringIO()
    dw, sw = csv.writer(data, lineterminator="\n"), csv.writer(sonar, lineterminator="\n")
    dw.writerow(DATA_COLUMNS)
    sonar_header_written = False
    row: dict[str, Any] = {}
    distances: list[Any] = []
    last_stamp: int | None = None
    for stamp, source, kind, p in log.records:
        if kind == "C" and source == "O":
            row.update(steps_left=p["dl"], steps_right=p["dr"])
        elif kind == "C" and source == "M":
            row["compass_rad"] = p["heading"]
        elif kind == "C" and source == "G":
            row["gyro_rad_s"] = p["rate"]
        elif kind == "C" and source == "W":
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
            dw.writerow([row.get(c, "") for c in DATA_COLUMNS])
            if not sonar_header_written and distances:
                sw.writerow(["stamp_ms", *[f"sonar{i}_mm" for i in range(len(distances))]])
                sonar_header_written = True
            sw.writerow([stamp, *["" if d is None else d for d in distances]])
            row = {}
    return data.getvalue(), sonar.getvalue()


#: the width of each of ``sonar.dat``'s obstacle coordinates (table B.8)
SEED_SONAR_DAT_WIDTH = 6


def _seed_lops_dat(p: dict[str, Any] | None) -> str:
    """Table B.8's LOPS columns: the three distances (mm, ``0`` where none was heard), the
    position LOPS computed (``0 0`` when it could not) and its valid flag."""
    if p is None:
        return " ".join([f"{0:8d}"] * 5) + " 0"
    distances = " ".join(_num(p.get(k), 8) for k in ("d1", "d2", "d3"))
    x, y = p.get("x"), p.get("y")
    valid = x is not None and y is not None and math.isfinite(float(x)) and math.isfinite(float(y))
    where = f"{_seed_int(x, 8)} {_seed_int(y, 8)}" if valid else f"{0:8d} {0:8d}"
    return f"{distances} {where} {int(valid)}"


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
    from the mounts of the log's configuration), as many sonars on every line (the robot's, or
    the most a ``W C`` carried).

    What the log lacks (no gyroscope or LOPS in a Hamburg run, no filter, no sonar) is written
    ``0`` as the seed writes unknown values, its valid flags 0. Records after the last ``S S``
    (a synchronisation the log ends inside) are not written; nor are the compass, the floor
    correlator and the truth, which table B.8 has no columns for."""
    if log.kind != "data":
        raise LogError(f"{log.path}: data.dat and sonar.dat (table B.8) need a data log")
    mounts = _sonar_mounts(log.header.get("config"))
    sonars = max(
        [len(mounts)]
        + [len(p["distances_mm"]) for _, source, kind, p in log.records if (source, kind) == ("W", "C")]
    )
    data, sonar = io.StringIO(), io.StringIO()
    sync: dict[str, Any] = {}
    for stamp, source, kind, p in log.records:
        if kind == "C" and source in ("O", "G", "L", "W"):
            sync[source] = p
        elif kind == "P" and source == "K":
            sync["K"] = p
        elif source == "S" and kind == "S":
            odometry, gyro = sync.get("O"), sync.get("G")
            encoders = (
                f"{_seed_int(odometry['dl'], 8)} {_seed_int(odometry['dr'], 8)}"
                if odometry is not None
                else f"{0:8d} {0:8d}"
            )
            turn = f"{float(gyro['turn']):15.12f}" if gyro is not None else f"{0:15d}"
            data.write(
                f"{stamp:8d} {_seed_int(p['period_ms'], 4)} {encoders} {turn} "
                f"{_seed_lops_dat(sync.get('L'))} {seed_position(sync.get('K'), 8, 8)}\n"
            )
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
