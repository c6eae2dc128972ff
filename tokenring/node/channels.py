"""User channels: what the node OS copies between the token and a user program's structures.

A **data channel** is a broadcast: its owner stores a structure into it at every visit, every
interested node gets a copy out of it. A **command channel** is an inbox with the seed's
registered-letter semantics:

* the sender's OS writes a command into the target inbox only when that inbox is **free** in
  the token, and marks it occupied;
* the receiver's OS copies it into the user's structure only if the inbox is **unlocked**, sets
  the acknowledge state and **locks** the inbox (the user unlocks it to receive the next one);
  a command is named by (sender, incarnation, seq): the one last taken is acknowledged again
  but never handed over twice, the newest one refused may be taken when it comes again, an
  older copy is cleared unexecuted (:class:`CommandMemory`);
* when the token is back at the sender, its OS records transmitted/acknowledged and **clears**
  the inbox in every case. There is no retry: the user program resends if it wants (``deliver``
  resends the same command, under its own seq).

The objects here run inside the token handler: each ``visit`` is a handful of byte operations.
"""

from __future__ import annotations

import functools
import logging
import os
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tokenring import runtime
from tokenring.contract.protocol import Channel, Command, CommandChannel, Protocol
from tokenring.errors import ChannelError

if TYPE_CHECKING:
    import numpy as np

# numpy is imported where a program's channel is built or read, never at import: a node that
# runs no program only passes the token on and needs none of it

log = logging.getLogger("tokenring.channels")


class ChannelBuffer:
    """A user program's structure for one channel: raw bytes plus typed field access.

    Reads and writes through this object are atomic with respect to the token handler, which
    copies under the same mutex — the Pythonic form of the seed's lock/unlock guard.
    """

    def __init__(self, channel: Channel) -> None:
        import numpy as np

        self.channel = channel
        self.raw = bytearray(channel.size)
        self.fields = np.ndarray((), dtype=channel.dtype, buffer=self.raw)
        self.mutex = runtime.current().lock()
        self.visits = 0  # how many visits copied into/out of this buffer

    @property
    def published(self) -> bool:
        """True once the channel holds anything but the token's initial zeros (SPEC: main starts
        the token as zeros), i.e. its owner has stored into it; a reader started together with
        the owner may copy the zeros first, which are no data."""
        with self.mutex:
            return any(self.raw)

    def read(self) -> dict[str, Any]:
        """All fields as plain Python values, consistent with one visit."""
        with self.mutex:
            return {f.name: f.to_python(self.fields[f.name]) for f in self.channel.fields}

    def snapshot(self) -> np.ndarray:
        """A copy of the structured record (numpy), consistent with one visit."""
        with self.mutex:
            return self.fields.copy()

    def write(self, **values: Any) -> None:
        """Set several fields at once; unknown names and out-of-range values are refused."""
        names = {f.name: f for f in self.channel.fields}
        for name, value in values.items():
            if name not in names:
                raise ChannelError(f"{self.channel.name} has no field {name!r} (fields: {', '.join(names)})")
            _check_value(self.channel.name, names[name], value)
        with self.mutex:
            for name, value in values.items():
                self.fields[name] = value.encode("ascii") if isinstance(value, str) else value

    def __getitem__(self, name: str) -> Any:
        field = next((f for f in self.channel.fields if f.name == name), None)
        if field is None:
            raise ChannelError(f"{self.channel.name} has no field {name!r}")
        with self.mutex:
            return field.to_python(self.fields[name])

    def __setitem__(self, name: str, value: Any) -> None:
        self.write(**{name: value})


@functools.cache
def _int_bounds(dtype: Any) -> tuple[int, int]:
    """The smallest and largest value of an integer dtype (numpy's iinfo, once per dtype)."""
    import numpy as np

    info = np.iinfo(dtype)
    return int(info.min), int(info.max)


def _check_value(where: str, field: Any, value: Any) -> None:
    if type(value) is int and not field.dtype.shape and not field.is_text:
        # a plain int for a scalar field, the common argument: what the numpy path below
        # concludes, without building arrays (a program's every command passes here)
        if field.dtype.kind in "iu":
            low, high = _int_bounds(field.dtype)
            if not low <= value <= high:
                raise ChannelError(
                    f"{where}.{field.name}: {value} does not fit {field.type_name} ({low}..{high})"
                )
        return
    import numpy as np

    dtype = field.dtype.base if field.dtype.shape else field.dtype
    if field.is_text:
        if not isinstance(value, str | bytes) or len(value) > field.size:
            raise ChannelError(f"{where}.{field.name}: text of at most {field.size} characters expected")
        return
    values = np.ravel(np.asarray(value))
    if field.dtype.shape and values.size != int(np.prod(field.dtype.shape)):
        raise ChannelError(f"{where}.{field.name}: expected {field.dtype.shape[0]} values, got {values.size}")
    if dtype.kind in "iu":
        info = np.iinfo(dtype)
        for v in values.tolist():
            if not isinstance(v, int | bool) and not float(v).is_integer():
                raise ChannelError(f"{where}.{field.name}: {v!r} is not an integer")
            if not info.min <= int(v) <= info.max:
                raise ChannelError(
                    f"{where}.{field.name}: {v} does not fit {field.type_name} ({info.min}..{info.max})"
                )


@dataclass(frozen=True)
class ReceivedCommand:
    """A command taken from this node's inbox."""

    sender: int
    name: str
    code: int
    seq: int
    args: dict[str, Any]
    incarnation: int = 0


class _Offsets:
    """Command header offsets and state values, compiled once from the protocol."""

    def __init__(self, protocol: Protocol) -> None:
        head = {f.name: f.offset for f in protocol.command_header}
        self.sender = head["sender"]
        self.state = head["state"]
        self.code = head["code"]
        self.seq = head["seq"]
        self.incarnation = head["incarnation"]
        self.FREE = protocol.command_states["FREE"]
        self.OCCUPIED = protocol.command_states["OCCUPIED"]
        self.ACKNOWLEDGED = protocol.command_states["ACKNOWLEDGED"]


class DataRegistration:
    """A data channel registered with get_data (token -> user) or store_data (user -> token)."""

    __slots__ = ("buffer", "channel", "end", "kind", "locked", "owner", "start")

    def __init__(self, channel: Channel, kind: str, buffer: ChannelBuffer, owner: str = "program") -> None:
        self.channel = channel
        self.kind = kind  # "get" or "store"
        self.buffer = buffer
        self.owner = owner  # "program" registrations go when the program stops; "os" ones stay
        self.start = channel.address
        self.end = channel.end
        self.locked = True  # the seed: every channel starts locked

    def visit(self, work: bytearray) -> None:
        buffer = self.buffer
        with buffer.mutex:
            if self.kind == "get":
                buffer.raw[:] = work[self.start : self.end]
            else:
                work[self.start : self.end] = buffer.raw
            buffer.visits += 1


NEW, REPEAT, STALE = "new", "repeat", "stale"
_FORGET_TAKEN = 0x4000


class _SenderRecord:
    """What a receiver remembers of one sender: its incarnation, seqs and earlier incarnations."""

    __slots__ = ("incarnation", "newest", "retired", "taken")

    def __init__(self, incarnation: int, seq: int) -> None:
        self.incarnation = incarnation
        self.newest = seq  # the newest seq seen from this incarnation, taken or refused
        self.taken = -1  # the seq last taken from it (-1: none yet)
        self.retired: deque[int] = deque(maxlen=64)


class CommandMemory:
    """The receiver's side of exactly-once delivery (see protocol.yaml's command_channel).

    It belongs to the node, not to the program's inbox, so a program restarted on a node that
    stays up still never takes a command twice. With a ``log`` file (the node's store: the seed's
    battery-backed RAM) every command taken is appended there before it is acknowledged, and a
    node process started again reads it back: a respawned receiver never takes again what its
    predecessor took, even from a token that kept the command since (a partition)."""

    __slots__ = ("_fd", "_lines", "_path", "_senders")

    COMPACT_AFTER = 50_000  # lines in the log before it is rewritten as one line per incarnation

    def __init__(self, log: str | os.PathLike[str] | None = None) -> None:
        self._senders: dict[int, _SenderRecord] = {}
        self._fd = -1
        self._lines = 0
        self._path = Path(log) if log is not None else None
        if self._path is not None:
            self._load()

    def classify(self, sender: int, incarnation: int, seq: int) -> str:
        """NEW (not taken yet: may be taken), REPEAT (the one last taken) or STALE (an old copy).

        Not taken yet: never seen, or the newest seen but refused (the inbox was locked): the
        sender resends a command under its own seq until it is acknowledged."""
        record = self._senders.get(sender)
        if record is None:
            return NEW
        if incarnation != record.incarnation:
            return STALE if incarnation in record.retired else NEW
        if seq == record.taken:
            return REPEAT
        return NEW if (seq - record.newest) & 0xFFFF < 0x8000 else STALE

    def saw(self, sender: int, incarnation: int, seq: int, taken: bool) -> None:
        """Record a NEW command as seen (refused: inbox locked) or taken."""
        self._apply(sender, incarnation, seq, taken)
        if taken and self._fd >= 0:
            self._append(f"{sender} {incarnation} {seq}\n")

    def _apply(self, sender: int, incarnation: int, seq: int, taken: bool) -> None:
        record = self._senders.get(sender)
        if record is None:
            record = self._senders[sender] = _SenderRecord(incarnation, seq)
        elif incarnation != record.incarnation:
            record.retired.append(record.incarnation)
            record.incarnation, record.taken = incarnation, -1
        record.newest = seq
        if taken:
            record.taken = seq
        elif record.taken >= 0 and (seq - record.taken) & 0xFFFF >= _FORGET_TAKEN:
            # a copy of the command taken can lag only a few seqs behind: far past it, the same
            # number coming round again (2^16 refused commands later) is a new command
            record.taken = -1

    def _load(self) -> None:
        """Read the log back (a line cut short by a kill is skipped) and rewrite it compactly."""
        assert self._path is not None
        try:
            text = self._path.read_text(errors="replace") if self._path.exists() else ""
            for line in text.splitlines():
                parts = line.split()
                if len(parts) == 3 and all(p.lstrip("-").isdigit() for p in parts):
                    sender, incarnation, seq = map(int, parts)
                    self._apply(sender, incarnation, seq, taken=seq >= 0)
            self._compact()
        except OSError as exc:
            log.warning("%s: the inbox memory stays in RAM only: %s", self._path, exc)
            self._fd = -1

    def _compact(self) -> None:
        assert self._path is not None
        lines = []
        for sender, record in self._senders.items():
            lines += [f"{sender} {old} -1\n" for old in record.retired]
            lines.append(f"{sender} {record.incarnation} {record.taken}\n")
        self._path.parent.mkdir(parents=True, exist_ok=True)
        fresh = self._path.with_name(self._path.name + ".new")
        fresh.write_text("".join(lines))
        os.replace(fresh, self._path)
        if self._fd >= 0:
            os.close(self._fd)
        self._fd = os.open(self._path, os.O_WRONLY | os.O_APPEND)
        self._lines = len(lines)

    def _append(self, line: str) -> None:
        try:
            os.write(self._fd, line.encode())  # one write(2): kept by the kernel if we are killed
            self._lines += 1
            if self._lines > self.COMPACT_AFTER:
                self._compact()
        except OSError as exc:
            log.warning("%s: the inbox memory stays in RAM only: %s", self._path, exc)
            self._fd = -1

    def close(self) -> None:
        """Close the log (the memory stays usable, in RAM only)."""
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1


class Inbox:
    """This node's own command channel (set_own_input_id + get_data)."""

    __slots__ = (
        "_off",
        "buffer",
        "channel",
        "end",
        "event",
        "live",
        "locked",
        "memory",
        "received",
        "refused",
        "start",
        "stats",
    )

    def __init__(
        self,
        channel: CommandChannel,
        offsets: _Offsets,
        live: set[int],
        stats: Any,
        memory: CommandMemory | None = None,
    ) -> None:
        self.channel = channel
        self.buffer = ChannelBuffer(channel)
        self.start = channel.address
        self.end = channel.end
        self._off = offsets
        self.locked = True
        self.received = False
        self.event = runtime.current().event()
        self.memory = memory if memory is not None else CommandMemory()
        self.live = live
        self.refused = 0
        self.stats = stats

    def visit(self, work: bytearray) -> None:
        off, a = self._off, self.start
        state = work[a + off.state]
        if state == off.FREE:
            return
        sender = work[a + off.sender]
        if sender not in self.live:
            # the sender is gone and will never come back to clear its command
            work[a : self.end] = bytes(self.end - a)
            self.stats.stale_commands_cleared += 1
            return
        if state != off.OCCUPIED:
            return
        s, i = a + off.seq, a + off.incarnation
        seq = work[s] | work[s + 1] << 8
        incarnation = int.from_bytes(work[i : i + 4], "little")
        verdict = self.memory.classify(sender, incarnation, seq)
        if verdict is REPEAT:
            work[a + off.state] = off.ACKNOWLEDGED  # already taken once: ack, never twice
            self.stats.duplicate_commands += 1
            return
        if verdict is STALE:
            # an old copy (a token regenerated from an earlier one, or a dead incarnation's
            # leftover): never executed, never acknowledged; cleared so the inbox is free
            work[a : self.end] = bytes(self.end - a)
            self.stats.stale_commands_cleared += 1
            return
        if self.locked:
            self.memory.saw(sender, incarnation, seq, taken=False)
            self.refused += 1
            self.stats.inbox_full += 1
            return
        with self.buffer.mutex:
            self.buffer.raw[:] = work[a : self.end]
        self.memory.saw(sender, incarnation, seq, taken=True)
        work[a + off.state] = off.ACKNOWLEDGED
        self.locked = True  # the flap closes by itself
        self.received = True
        self.stats.commands_received += 1
        self.event.set()

    def take(self) -> ReceivedCommand:
        """Decode the received command (the caller unlocks the inbox for the next one)."""
        off = self._off
        with self.buffer.mutex:
            raw = bytes(self.buffer.raw)
        code = raw[off.code]
        seq = raw[off.seq] | raw[off.seq + 1] << 8
        incarnation = int.from_bytes(raw[off.incarnation : off.incarnation + 4], "little")
        try:
            command = self.channel.command(code)
        except ChannelError:
            return ReceivedCommand(raw[off.sender], f"UNKNOWN_{code}", code, seq, {}, incarnation)
        import numpy as np

        view = np.ndarray((), dtype=command.dtype, buffer=raw)
        args = {f.name: f.to_python(view[f.name]) for f in command.args}
        return ReceivedCommand(raw[off.sender], command.name, code, seq, args, incarnation)


class Outbox:
    """A command from this node into another module's inbox, and its fate."""

    __slots__ = (
        "_off",
        "acknowledged",
        "channel",
        "command",
        "done",
        "end",
        "ident",
        "image",
        "incarnation",
        "own_id",
        "queued_at",
        "rounds_waited",
        "seq",
        "start",
        "state",
        "stats",
        "transmitted",
    )

    WAITING, IN_TOKEN, DONE = 0, 1, 2

    def __init__(
        self,
        channel: CommandChannel,
        command: Command,
        offsets: _Offsets,
        own_id: int,
        seq: int,
        args: dict[str, Any],
        stats: Any,
        incarnation: int = 1,
    ) -> None:
        self.channel = channel
        self.command = command
        self._off = offsets
        self.own_id = own_id
        self.seq = seq
        self.incarnation = incarnation
        self.start = channel.address
        self.end = channel.end
        self.image = encode_command(channel, command, own_id, seq, offsets.OCCUPIED, args, incarnation)
        # where (sender, seq, incarnation) sit in the channel: what names this command
        self.ident = tuple((o, self.image[o]) for o in _ident_offsets(offsets))
        self.state = Outbox.WAITING
        self.transmitted = False
        self.acknowledged = False
        rt = runtime.current()
        self.done = rt.event()
        self.rounds_waited = 0
        self.queued_at = rt.monotonic()
        self.stats = stats

    def visit(self, work: bytearray) -> bool:
        """Returns True when this outbox is finished (the handler drops it)."""
        off, a = self._off, self.start
        mine = work[a + off.sender] == self.own_id and work[a + off.state] != off.FREE
        if self.state == Outbox.IN_TOKEN:
            if mine:
                if all(work[a + o] == v for o, v in self.ident):
                    self.transmitted = True
                    self.acknowledged = work[a + off.state] == off.ACKNOWLEDGED
                # back at the sender the inbox is cleared in every case — also of an older
                # command of ours that a token regenerated from an old copy brought back
                work[a : self.end] = bytes(self.end - a)
            if self.acknowledged:
                self.stats.commands_acknowledged += 1
            else:
                self.stats.commands_unacknowledged += 1
            self.state = Outbox.DONE
            self.done.set()
            return True
        if work[a + off.state] == off.FREE or mine:  # an old command of ours is ours to replace
            work[a : self.end] = self.image
            self.state = Outbox.IN_TOKEN
            self.stats.commands_sent += 1
        else:
            self.rounds_waited += 1
        return False

    def cancel(self) -> None:
        """Withdraw a command not yet written; one already in the token still completes its
        round (the sender's OS must clear the inbox it occupies)."""
        if self.state == Outbox.WAITING:
            self.state = Outbox.DONE
            self.done.set()


def _ident_offsets(off: _Offsets) -> tuple[int, ...]:
    """Channel-relative offsets of the bytes that name a command: sender, seq, incarnation."""
    return (off.sender, off.seq, off.seq + 1, *range(off.incarnation, off.incarnation + 4))


def encode_command(
    channel: CommandChannel,
    command: Command,
    sender: int,
    seq: int,
    state: int,
    args: dict[str, Any],
    incarnation: int = 1,
) -> bytes:
    """The full channel image of a command; arguments are checked against ``protocol.yaml``."""
    names = command.arg_names()
    unknown = set(args) - set(names)
    if unknown:
        raise ChannelError(
            f"{channel.name} {command.name}: unknown argument(s) {', '.join(sorted(unknown))} "
            f"(takes: {', '.join(names) or 'none'})"
        )
    missing = [n for n in names if n not in args]
    if missing:
        raise ChannelError(f"{channel.name} {command.name}: missing argument(s) {', '.join(missing)}")
    import numpy as np

    raw = bytearray(channel.size)
    view = np.ndarray((), dtype=command.dtype, buffer=raw)
    view["sender"] = sender
    view["state"] = state
    view["code"] = command.code
    view["seq"] = seq
    view["incarnation"] = incarnation
    for field in command.args:
        value = args[field.name]
        _check_value(f"{channel.name} {command.name}", field, value)
        view[field.name] = value.encode("ascii") if isinstance(value, str) else value
    return bytes(raw)
