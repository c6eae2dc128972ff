"""Recording a ring to MCAP and playing it back: ``tokenring record``, ``play``, ``sniff
--write/--read``, ``up --record`` (and the robot's ``log convert --to mcap``) all use this.

An MCAP file written here holds

* every topic of the feed (:mod:`tokenring.observe.feed`) as a channel with message encoding ``json``
  and a ``jsonschema`` schema named by the topic's schema name (``tokenring.Frame``,
  ``foxglove.PoseInFrame``, ...): Foxglove shows the well-known ones without configuration,
  PlotJuggler plots the numbers;
* every Zenoh sample the feed read, raw, on a channel whose topic is the Zenoh key itself and
  whose message encoding is :data:`RAW_ENCODING` (no schema: the bytes are exactly what
  travelled; Foxglove lists such channels and leaves them alone). ``play`` puts these bytes back
  on the same keys; ``sniff --read`` decodes the frames among them offline;
* a metadata record ``tokenring`` (ring name, tokenring version, protocol.yaml's SHA-256, start
  time) and protocol.yaml itself as an attachment, so a file decodes without the tree it came
  from.

Crash safety: the file is written as ``FILE.part`` beside its target and renamed to ``FILE``
only once its summary is written, so ``FILE`` is always a whole recording. Chunks (zstd) are
closed and flushed at least every :data:`FLUSH_INTERVAL_S`: a recorder that is killed outright
leaves ``FILE.part`` holding everything up to the last flush, readable by any MCAP reader
(``mcap recover``, or ``play`` itself: a file without a summary is read front to back). A full
disk ends a recording at its last whole record: the file is written unbuffered, a torn write is
cut off again, and what was kept becomes ``FILE`` (without a summary) — see :class:`McapRecorder`.
"""

from __future__ import annotations

import contextlib
import fnmatch
import hashlib
import io
import json
import os
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from tokenring._util.tables import json_default
from tokenring.contract import keys
from tokenring.errors import UsageError
from tokenring.observe.feed import Message, RawSample, Topic

#: message encoding of the raw channels: the payload is the Zenoh sample's bytes, unchanged
RAW_ENCODING = "tokenring.zenoh"
#: name of the metadata record and of the protocol attachment
METADATA_NAME = "tokenring"
PROTOCOL_ATTACHMENT = "protocol.yaml"
#: a chunk is closed and written out at least this often (what a killed recorder can lose)
FLUSH_INTERVAL_S = 1.0
#: chunks are closed at this size too (before compression)
CHUNK_SIZE = 1 << 20
MCAP_MAGIC = b"\x89MCAP0\r\n"


def tokenring_version() -> str:
    """The installed distribution's version, for the file's metadata."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("tokenring")
    except PackageNotFoundError:
        return "unknown"


def part_path(path: str | Path) -> Path:
    """Where a recording to ``path`` is written until it is complete."""
    target = Path(path)
    return target.with_name(target.name + ".part")


def publish_part(file: Any, part: Path, path: Path) -> None:
    """A complete ``part`` becomes ``path``: synced first (a file system may report a full disk
    only there; its OSError is the caller's), closed, renamed into place."""
    os.fsync(file.fileno())
    file.close()
    os.replace(part, path)


def drop_part(file: Any, part: Path) -> None:
    """An abandoned ``part`` is closed and removed; the file it was to replace stays as it was."""
    file.close()
    with contextlib.suppress(FileNotFoundError):
        part.unlink()


# --------------------------------------------------------------------------------------------
# selecting topics and keys


class Selection:
    """``--topics`` globs: a topic name (``/robot/*``), a Zenoh key (``tokenring/r/token/*``) or a
    key inside the ring (``token/*``, ``world/**`` written ``world/*``) is selected if any glob
    matches it. No globs select everything."""

    def __init__(self, globs: Iterable[str] = ()) -> None:
        self.globs = [g for g in globs if g]

    @classmethod
    def parse(cls, text: str | None) -> Selection:
        """From a comma-separated option value."""
        return cls([part.strip() for part in (text or "").split(",") if part.strip()])

    def __bool__(self) -> bool:
        return bool(self.globs)

    def topic(self, name: str) -> bool:
        return not self.globs or any(fnmatch.fnmatchcase(name, g) for g in self.globs)

    def key(self, key: str) -> bool:
        if not self.globs:
            return True
        parts = key.split("/", 2)
        inner = parts[2] if len(parts) == 3 and parts[0] == keys.PREFIX else key
        return any(fnmatch.fnmatchcase(key, g) or fnmatch.fnmatchcase(inner, g) for g in self.globs)


# --------------------------------------------------------------------------------------------
# writing


def encode_json(data: Any) -> bytes:
    """A message's JSON bytes (compact; numpy values and bytes made plain)."""
    return json.dumps(data, separators=(",", ":"), default=json_default).encode()


class _WholeRecords:
    """The recording's file, unbuffered: each write (the MCAP writer hands over whole records)
    is on the disk whole, or cut back off it when it fails (a full disk), so the file always
    ends at a record boundary and nothing is written after a torn record."""

    def __init__(self, path: Path) -> None:
        flags = os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_CLOEXEC", 0)
        self.fd = os.open(path, flags, 0o644)
        self.size = 0

    def write(self, data: bytes | memoryview) -> int:
        view = memoryview(data)
        try:
            while view:
                view = view[os.write(self.fd, view) :]
        except OSError:
            with contextlib.suppress(OSError):
                os.ftruncate(self.fd, self.size)  # shrinking needs no space
            raise
        self.size += len(data)
        return len(data)

    def tell(self) -> int:
        return self.size

    def flush(self) -> None:
        """Every write is already in the kernel's hands."""

    def fileno(self) -> int:
        return self.fd

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1


class McapRecorder:
    """An MCAP file being written: a message sink and a raw sink for :class:`tokenring.observe.feed.Feed`.

    Thread-safe (the feed's thread writes while a command's loop calls :meth:`tick`). Channels
    are registered at their first message, each schema once per schema name.

    A write that fails (a full disk) ends the recording at once: :attr:`failure` says so in one
    line naming the file, later messages are dropped, and what was written whole (the chunks
    before the failure, readable as a recording without an index, as a killed recorder leaves
    it) becomes ``FILE`` — a live ring's data cannot be had again; ``keep_partial=False`` (a
    conversion, which can be run again) or no message kept: no file at all, ``FILE`` as it was."""

    def __init__(
        self,
        path: str | Path,
        *,
        ring: str,
        topics: Iterable[Topic] = (),
        protocol_text: str | None = None,
        selection: Selection | None = None,
        compression: str = "zstd",
        metadata: dict[str, str] | None = None,
        flush_interval_s: float = FLUSH_INTERVAL_S,
        keep_partial: bool = True,
    ) -> None:
        from mcap.writer import CompressionType, Writer

        self.path = Path(path)
        self.part = part_path(self.path)
        self.ring = ring
        self.selection = selection or Selection()
        self.topics = {t.name: t for t in topics}
        self.counts: Counter[str] = Counter()
        self.raw_bytes = 0
        self.started_ns = time.time_ns()
        self.flush_interval_s = flush_interval_s
        self.keep_partial = keep_partial
        self._lock = threading.Lock()
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._sequence: Counter[int] = Counter()
        self._last_flush = time.monotonic()
        self._closed = False
        #: why the recording ended early (one line naming the file), or None
        self.failure: str | None = None
        self._messages_on_disk = 0  # messages in the chunks written whole
        self._seconds_on_disk = 0.0
        self._size_on_disk = 0
        kind = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
        if compression not in kind:
            raise UsageError(f"compression {compression!r}: use zstd, lz4 or none")
        try:
            self._file = _WholeRecords(self.part)
        except OSError as exc:
            raise UsageError(f"{self.path}: cannot write the recording: {exc.strerror or exc}") from None
        try:
            self._start(Writer, kind[compression], protocol_text, metadata)
        except OSError as exc:  # not even the file's start fits: no file at all
            self._file.close()
            with contextlib.suppress(OSError):
                self.part.unlink()
            raise UsageError(f"{self.path}: cannot write the recording: {exc.strerror or exc}") from None
        self._size_on_disk = self._file.size

    def _start(
        self, writer: Any, compression: Any, protocol_text: str | None, metadata: dict[str, str] | None
    ) -> None:
        self._writer = writer(self._file, chunk_size=CHUNK_SIZE, compression=compression)
        self._writer.start(profile="", library=f"tokenring {tokenring_version()}")
        meta = {
            "ring": self.ring,
            "tokenring_version": tokenring_version(),
            "started": datetime.fromtimestamp(self.started_ns / 1e9, UTC).isoformat(),
            "raw_encoding": RAW_ENCODING,
        }
        if protocol_text is not None:
            meta["protocol_sha256"] = hashlib.sha256(protocol_text.encode()).hexdigest()
            self._writer.add_attachment(
                create_time=self.started_ns,
                log_time=self.started_ns,
                name=PROTOCOL_ATTACHMENT,
                media_type="application/yaml",
                data=protocol_text.encode(),
            )
        meta.update(metadata or {})
        self._writer.add_metadata(METADATA_NAME, meta)
        self._writer.flush()

    # sinks ---------------------------------------------------------------------------------

    def on_message(self, message: Message) -> None:
        """Write one topic message (a :class:`tokenring.observe.feed.Feed` sink)."""
        if not self.selection.topic(message.topic):
            return
        data = message.encoded
        with self._lock:
            if self._closed:
                return
            try:
                channel = self._channels.get(message.topic)
                if channel is None:
                    channel = self._json_channel(message.topic)
                self._add(channel, message.topic, message.time_ns, data)
            except OSError as exc:  # a chunk went out and did not fit
                self._fail(exc)

    def on_raw(self, raw: RawSample) -> None:
        """Write one raw Zenoh sample on the channel named by its key (a raw sink)."""
        if not self.selection.key(raw.key):
            return
        with self._lock:
            if self._closed:
                return
            try:
                channel = self._channels.get(raw.key)
                if channel is None:
                    channel = self._writer.register_channel(
                        topic=raw.key,
                        message_encoding=RAW_ENCODING,
                        schema_id=0,
                        metadata={"ring": self.ring},
                    )
                    self._channels[raw.key] = channel
                self.raw_bytes += len(raw.payload)
                self._add(channel, raw.key, raw.time_ns, raw.payload)
            except OSError as exc:  # a chunk went out and did not fit
                self._fail(exc)

    def _json_channel(self, name: str) -> int:
        topic = self.topics.get(name)
        schema_id = 0
        metadata: dict[str, str] = {}
        if topic is not None:
            schema_id = self._schemas.get(topic.schema_name, 0)
            if not schema_id:
                schema_id = self._writer.register_schema(
                    name=topic.schema_name, encoding="jsonschema", data=encode_json(topic.schema)
                )
                self._schemas[topic.schema_name] = schema_id
            if topic.doc:
                metadata["doc"] = topic.doc
        channel = self._writer.register_channel(
            topic=name, message_encoding="json", schema_id=schema_id, metadata=metadata
        )
        self._channels[name] = channel
        return channel

    def _add(self, channel: int, name: str, time_ns: int, data: bytes) -> None:
        self._writer.add_message(
            channel_id=channel,
            log_time=time_ns,
            publish_time=time_ns,
            data=data,
            sequence=self._sequence[channel],
        )
        self._sequence[channel] += 1
        self.counts[name] += 1
        if self._file.size != self._size_on_disk:  # a full chunk went out
            self._on_disk()
        self._maybe_flush()

    def _on_disk(self) -> None:
        """Note what the file holds whole: every message so far."""
        self._size_on_disk = self._file.size
        self._messages_on_disk = self.messages
        self._seconds_on_disk = (time.time_ns() - self.started_ns) / 1e9

    def _maybe_flush(self) -> None:
        now = time.monotonic()
        if now - self._last_flush >= self.flush_interval_s:
            self._last_flush = now
            self._flush()

    def _flush(self) -> None:
        """Write the open chunk out (with the lock held); a failure ends the recording."""
        try:
            self._writer.flush()
        except OSError as exc:
            self._fail(exc)
            return
        self._on_disk()

    def _fail(self, exc: OSError) -> None:
        """End the recording at its last whole record (the lock held): nothing more is written."""
        self._closed = True
        self._file.close()
        if self._messages_on_disk and self.keep_partial:
            os.replace(self.part, self.path)
            kept = (
                f"the recording ends at its last whole chunk ({self._seconds_on_disk:.1f} s, "
                f"{self._messages_on_disk} messages; without an index, as a killed recorder leaves it)"
            )
        else:
            with contextlib.suppress(OSError):
                self.part.unlink()
            kept = "nothing was kept" + (" (the file there is as it was)" if self.path.exists() else "")
        self.failure = f"{self.path}: cannot write the recording: {exc.strerror or exc}; {kept}"

    def tick(self) -> None:
        """Flush a chunk that has waited :attr:`flush_interval_s` (call it now and then when idle)."""
        with self._lock:
            if not self._closed:
                self._maybe_flush()

    # the end ------------------------------------------------------------------------------

    @property
    def messages(self) -> int:
        return sum(self.counts.values())

    @property
    def messages_kept(self) -> int:
        """The messages in the file: all of them, or those before a failure (:attr:`failure`)."""
        return self._messages_on_disk if self.failure else self.messages

    def close(self) -> Path:
        """Write the summary, sync, and move the file to its final name (a recording that
        failed: see :attr:`failure`; what it kept is already there)."""
        with self._lock:
            if self._closed:
                return self.path
            try:
                self._writer.finish()
                publish_part(self._file, self.part, self.path)
            except OSError as exc:
                self._fail(exc)
                return self.path
            self._closed = True
        return self.path

    def discard(self) -> None:
        """Close without a recording: ``FILE.part`` is removed, ``FILE`` left as it was."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            drop_part(self._file, self.part)

    def __enter__(self) -> McapRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class Stopper:
    """Ctrl-C and SIGTERM end a recording or a play cleanly (a file is finalised, never left
    half); ``signal`` says which one came."""

    def __init__(self) -> None:
        self.event = threading.Event()
        self.signal: int | None = None

    def install(self) -> None:
        """Take SIGINT and SIGTERM (call it from the main thread)."""
        import signal

        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, self._on_signal)

    def _on_signal(self, signum: int, frame: Any) -> None:
        self.signal = signum
        self.event.set()


# --------------------------------------------------------------------------------------------
# reading


@dataclass
class Recording:
    """An MCAP file opened for reading: its metadata, channels and time range."""

    path: Path
    ring: str | None
    metadata: dict[str, str]
    protocol_text: str | None
    #: topic -> (message encoding, schema name, message count)
    channels: dict[str, tuple[str, str, int]] = field(default_factory=dict)
    start_ns: int = 0
    end_ns: int = 0
    #: False for a file without a summary (a killed recorder's ``.part``): read front to back
    indexed: bool = True

    def raw_keys(self) -> list[str]:
        return [t for t, (enc, _, _) in self.channels.items() if enc == RAW_ENCODING]

    @property
    def duration_s(self) -> float:
        return max(0, self.end_ns - self.start_ns) / 1e9


def _damaged(path: Path, exc: BaseException) -> UsageError:
    text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return UsageError(f"{path}: not a readable MCAP file ({text})")


def open_recording(path: str | Path) -> Recording:
    """Open and check an MCAP file; :class:`UsageError` (one line) if it is not one or is damaged."""
    from mcap.reader import make_reader

    file = Path(path)
    try:
        with open(file, "rb") as stream:
            head = stream.read(len(MCAP_MAGIC))
            if head != MCAP_MAGIC:
                raise UsageError(f"{file}: not an MCAP file (it does not start with the MCAP magic)")
            stream.seek(0)
            reader = make_reader(stream)
            try:
                summary = reader.get_summary()
            except Exception:  # no footer: a recorder killed outright (FILE.part), or a torn copy
                return _scan(stream, file)
            metadata: dict[str, str] = {}
            protocol_text = None
            for record in reader.iter_metadata():
                if record.name == METADATA_NAME:
                    metadata = dict(record.metadata)
            for attachment in reader.iter_attachments():
                if attachment.name == PROTOCOL_ATTACHMENT:
                    protocol_text = bytes(attachment.data).decode("utf-8", "replace")
            out = Recording(file, metadata.get("ring"), metadata, protocol_text)
            if summary is not None and summary.statistics is not None:
                counts = summary.statistics.channel_message_counts
                for channel in summary.channels.values():
                    schema = summary.schemas.get(channel.schema_id)
                    out.channels[channel.topic] = (
                        channel.message_encoding,
                        schema.name if schema is not None else "",
                        counts.get(channel.id, 0),
                    )
                out.start_ns = summary.statistics.message_start_time
                out.end_ns = summary.statistics.message_end_time
            else:
                return _scan(stream, file)
            return out
    except UsageError:
        raise
    except OSError as exc:
        raise UsageError(f"{file}: cannot read: {exc.strerror or exc}") from None
    except Exception as exc:  # the mcap reader's errors, zstd/lz4 errors, struct errors ...
        raise _damaged(file, exc) from None


def _scan(stream: io.BufferedReader, file: Path) -> Recording:
    """A file without a summary, read front to back up to its torn tail (every complete
    chunk counts); :class:`UsageError` if not one message could be read."""
    from mcap.reader import StreamReader
    from mcap.records import Attachment, Channel, Message, Metadata, Schema

    stream.seek(0)
    counts: Counter[str] = Counter()
    channels: dict[int, Channel] = {}
    schemas: dict[int, Schema] = {}
    metadata: dict[str, str] = {}
    protocol_text = None
    start, end = None, None
    problem: Exception | None = None
    try:
        for record in StreamReader(stream, skip_magic=False, record_size_limit=1 << 30).records:
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message) and record.channel_id in channels:
                counts[channels[record.channel_id].topic] += 1
                start = record.log_time if start is None else min(start, record.log_time)
                end = record.log_time if end is None else max(end, record.log_time)
            elif isinstance(record, Metadata) and record.name == METADATA_NAME:
                metadata = dict(record.metadata)
            elif isinstance(record, Attachment) and record.name == PROTOCOL_ATTACHMENT:
                protocol_text = bytes(record.data).decode("utf-8", "replace")
    except Exception as exc:  # the torn tail
        problem = exc
    if not counts:
        raise _damaged(file, problem or ValueError("no messages"))
    out = Recording(file, metadata.get("ring"), metadata, protocol_text, indexed=False)
    for channel in channels.values():
        schema = schemas.get(channel.schema_id)
        out.channels[channel.topic] = (
            channel.message_encoding,
            schema.name if schema is not None else "",
            counts[channel.topic],
        )
    out.start_ns, out.end_ns = start or 0, end or 0
    return out


def iter_records(
    recording: Recording,
    topics: Iterable[str] | None = None,
    start_ns: int | None = None,
    end_ns: int | None = None,
) -> Iterator[tuple[str, str, int, bytes]]:
    """(topic, message encoding, log time ns, data) in log-time order; damage raises
    :class:`UsageError` (a torn tail of an unindexed file just ends the iteration)."""
    from mcap.reader import NonSeekingReader, make_reader

    wanted = None if topics is None else list(topics)
    try:
        with open(recording.path, "rb") as stream:
            if recording.indexed:
                reader: Any = make_reader(stream)
                items = reader.iter_messages(topics=wanted, start_time=start_ns, end_time=end_ns)
            else:
                # in file order (a recorder writes in arrival order): sorting would read to the end
                items = NonSeekingReader(stream).iter_messages(
                    topics=wanted, start_time=start_ns, end_time=end_ns, log_time_order=False
                )
            try:
                for _, channel, message in items:
                    yield channel.topic, channel.message_encoding, message.log_time, bytes(message.data)
            except Exception as exc:
                if recording.indexed:
                    raise
                del exc  # an unindexed (killed) recording's torn tail
    except UsageError:
        raise
    except OSError as exc:
        raise UsageError(f"{recording.path}: cannot read: {exc.strerror or exc}") from None
    except Exception as exc:
        raise _damaged(recording.path, exc) from None


def iter_raw(
    recording: Recording,
    selection: Selection | None = None,
    start_ns: int | None = None,
    end_ns: int | None = None,
) -> Iterator[RawSample]:
    """The raw Zenoh samples, in log-time order, those of the selected keys."""
    chosen = [k for k in recording.raw_keys() if selection is None or selection.key(k)]
    if not chosen:
        return
    for topic, encoding, time_ns, data in iter_records(recording, chosen, start_ns, end_ns):
        if encoding == RAW_ENCODING:
            yield RawSample(topic, time_ns, data)


def iter_messages(recording: Recording, topics: Iterable[str] | None = None) -> Iterator[Message]:
    """The JSON topics' messages, decoded, in log-time order."""
    chosen = [
        t
        for t, (enc, _, _) in recording.channels.items()
        if enc == "json" and (topics is None or t in topics)
    ]
    if not chosen:
        return
    for topic, _, time_ns, data in iter_records(recording, chosen):
        try:
            yield Message(topic, time_ns, json.loads(data))
        except ValueError as exc:
            raise UsageError(f"{recording.path}: a {topic} message is not JSON ({exc})") from None


# --------------------------------------------------------------------------------------------
# playing


def asked_with(query: Any) -> list[Any]:
    """What a ``stats`` question asked to be added (``{"with": [...]}``); none if unreadable."""
    import msgpack

    try:
        request = msgpack.unpackb(query.payload.to_bytes()) if query.payload is not None else {}
    except Exception:  # a question that is not msgpack asks for nothing more
        return []
    extra = request.get("with") if isinstance(request, dict) else None
    return extra if isinstance(extra, list) else []


def rename_ring(key: str, recorded: str | None, ring: str | None) -> str:
    """``key`` moved from the recorded ring's namespace into ``ring``'s (unchanged if either is
    unknown or they are the same)."""
    if not recorded or not ring or recorded == ring:
        return key
    head = f"{keys.PREFIX}/{recorded}/"
    return f"{keys.PREFIX}/{ring}/{key[len(head) :]}" if key.startswith(head) else key


@dataclass
class PlayStats:
    """What a play has put back so far."""

    samples: int = 0
    frames: int = 0
    loops: int = 0
    recorded_s: float = 0.0  # how far into the recording (from its start)
    counts: Counter[str] = field(default_factory=Counter)


class Player:
    """Puts a recording's raw samples back on Zenoh at the recorded pace times ``rate``."""

    def __init__(
        self,
        session: Any,
        recording: Recording,
        *,
        rate: float = 1.0,
        start_s: float = 0.0,
        duration_s: float | None = None,
        selection: Selection | None = None,
        ring: str | None = None,
    ) -> None:
        self.session = session
        self.recording = recording
        self.rate = rate
        self.start_s = start_s
        self.duration_s = duration_s
        self.selection = selection or Selection()
        self.ring: str = ring or recording.ring or keys.DEFAULT_RING
        self.stats = PlayStats()
        self._publishers: dict[str, Any] = {}
        self._tokens: list[Any] = []
        self._queryables: list[Any] = []
        #: the recorded /ring/nodes as play has reached it (node ID -> stats, -> faults)
        self.nodes: dict[str, Any] = {}
        self.faults: dict[str, Any] = {}
        self.keys = [k for k in recording.raw_keys() if self.selection.key(k)]
        # taps (sniffs) by ID: seen listening, their token gone, said goodbye, confirmed drained
        self.taps_seen: set[str] = set()
        self.taps_gone: Counter[str] = Counter()
        self.taps_left: Counter[str] = Counter()
        self.taps_drained: set[str] = set()
        self._tap_watch: list[Any] = []

    def target_key(self, key: str) -> str:
        return rename_ring(key, self.recording.ring, self.ring)

    def declare(self) -> None:
        """A publisher per key, declared up front (so :meth:`wait_subscribers` can ask)."""
        import zenoh

        for key in self.keys:
            target = self.target_key(key)
            if target not in self._publishers:
                self._publishers[target] = self.session.declare_publisher(
                    target, congestion_control=zenoh.CongestionControl.BLOCK
                )

    def wait_subscribers(self, timeout: float, stop: threading.Event) -> bool:
        """Wait until something subscribes to one of the keys (a viewer started just before
        misses nothing); False if nobody did within ``timeout``."""
        deadline = time.monotonic() + timeout
        while not stop.is_set():
            if any(p.matching_status.matching for p in self._publishers.values()):
                return True
            if time.monotonic() >= deadline:
                return False
            stop.wait(0.05)
        return False

    def watch_taps(self) -> None:
        """Follow the ring's taps while playing: a tap whose liveliness token goes without its
        goodbye (:func:`tokenring.contract.keys.tap_left`) had its link cut by Zenoh (frozen past the
        blocked-link wait, or its lease), and what was queued towards it was dropped."""
        import zenoh

        def on_token(sample: Any) -> None:
            tap_id = keys.tap_id_from_key(str(sample.key_expr))
            if tap_id is None:
                return
            if sample.kind == zenoh.SampleKind.PUT:
                self.taps_seen.add(tap_id)
            else:
                self.taps_gone[tap_id] += 1

        def on_left(sample: Any) -> None:
            tap_id = keys.tap_id_from_key(str(sample.key_expr))
            if tap_id is not None:
                self.taps_left[tap_id] += 1

        self._tap_watch.append(
            self.session.liveliness().declare_subscriber(keys.tap(self.ring), on_token, history=True)
        )
        self._tap_watch.append(self.session.declare_subscriber(keys.tap_left(self.ring), on_left))

    def taps_lost(self) -> list[str]:
        """Taps that missed frames: a token gone more often than its tap said goodbye (cut off,
        perhaps back since), or seen but silent at the end without a goodbye. Counted, not
        ordered: the goodbye and the token's end may arrive either way round."""
        cut = {tap_id for tap_id, gone in self.taps_gone.items() if gone > self.taps_left[tap_id]}
        silent = {t for t in self.taps_seen - self.taps_drained if not self.taps_left[t]}
        return sorted(cut | silent)

    def serve_control(self) -> None:
        """Answer ``monitor``: every recorded node's liveliness token and its ``stats`` and
        ``fault`` queryables, answered with the recorded ``/ring/nodes`` as play reaches it."""
        import msgpack

        if "/ring/nodes" not in self.recording.channels:
            return
        ids: set[int] = set()
        for message in iter_messages(self.recording, ["/ring/nodes"]):
            if message.data.get("nodes") and not self.nodes:  # answered until play reaches more
                self.nodes, self.faults = message.data["nodes"], message.data.get("faults", {})
            ids.update(int(i) for i in message.data.get("nodes", {}))

        def answerer(node: str, verb: str) -> Callable[[Any], None]:
            def answer(query: Any) -> None:
                if verb == "stats" and node not in self.nodes:
                    return  # not live at this point of the recording: no answer, as live
                if verb == "stats":
                    result = dict(self.nodes[node])
                    if "faults" in asked_with(query):  # a watcher asks for both at once
                        result["faults"] = self.faults.get(node, {})
                else:
                    result = {"id": int(node), "faults": self.faults.get(node, {})}
                query.reply(
                    keys.control(self.ring, node, verb), msgpack.packb({"ok": True, "result": result})
                )

            return answer

        for node_id in sorted(ids):
            self._tokens.append(self.session.liveliness().declare_token(keys.node(self.ring, node_id)))
            for verb in ("stats", "fault"):
                self._queryables.append(
                    self.session.declare_queryable(
                        keys.control(self.ring, node_id, verb), answerer(str(node_id), verb)
                    )
                )

    def play_once(self, stop: threading.Event, on_sample: Callable[[RawSample], None] | None = None) -> None:
        """One pass over the recording (from ``start_s``, for ``duration_s``)."""
        rec = self.recording
        first_ns = rec.start_ns + int(self.start_s * 1e9)
        end_ns = None if self.duration_s is None else first_ns + int(self.duration_s * 1e9) + 1
        began = time.monotonic()
        chosen = [k for k in rec.raw_keys() if self.selection.key(k)]
        if self._queryables:
            chosen.append("/ring/nodes")
        for topic, encoding, time_ns, data in iter_records(rec, chosen, first_ns, end_ns):
            if stop.is_set():
                return
            if encoding != RAW_ENCODING:  # /ring/nodes: what monitor is answered from now on
                with contextlib.suppress(ValueError, AttributeError):
                    snapshot = json.loads(data)
                    self.nodes, self.faults = snapshot["nodes"], snapshot["faults"]
                continue
            raw = RawSample(topic, time_ns, data)
            due = began + max(0, raw.time_ns - first_ns) / 1e9 / self.rate
            delay = due - time.monotonic()
            if delay > 0 and stop.wait(delay):
                return
            target = self.target_key(raw.key)
            publisher = self._publishers.get(target)
            if publisher is None:
                self.declare()
                publisher = self._publishers[target]
            publisher.put(raw.payload)
            self.stats.samples += 1
            self.stats.counts[target] += 1
            if "/token/" in target:
                self.stats.frames += 1
            self.stats.recorded_s = (raw.time_ns - rec.start_ns) / 1e9
            if on_sample is not None:
                on_sample(raw)

    def wait_drained(self, timeout: float, stop: threading.Event) -> tuple[int, bool]:
        """Ask every tap of the ring (:func:`tokenring.contract.keys.tap_drained`) and wait for their
        replies: a reply comes after the tap took every sample played before the question, so
        closing the session then loses nothing still queued towards a slow tap. Returns
        (taps that answered, whether the wait ran out or was stopped first)."""
        import zenoh

        replies = self.session.get(
            keys.tap_drained(self.ring),
            handler=zenoh.handlers.FifoChannel(256),
            target=zenoh.QueryTarget.ALL,
            consolidation=zenoh.ConsolidationMode.NONE,
            timeout=timeout + 1.0,  # the loop below times out first, so it can tell
        )
        deadline = time.monotonic() + timeout
        while not stop.is_set() and time.monotonic() < deadline:
            try:
                reply = replies.try_recv()
            except zenoh.ZError:  # every reply in, or the query's timeout: the channel closed
                return len(self.taps_drained), False
            if reply is None:
                stop.wait(0.02)
            elif reply.ok is not None and (tap_id := keys.tap_id_from_key(str(reply.ok.key_expr))):
                self.taps_drained.add(tap_id)
        return len(self.taps_drained), True

    def close(self) -> None:
        for declared in [*self._queryables, *self._tokens, *self._tap_watch]:
            with contextlib.suppress(Exception):
                declared.undeclare()
        for publisher in self._publishers.values():
            with contextlib.suppress(Exception):
                publisher.undeclare()
        self._publishers.clear()
