"""The programs' face of a node: the seed's calls, in Pythonic form.

A user program (:class:`~tokenring.node.program.UserProgram`) reaches the ring only through these
calls on ``self.os``:

=============================  ===========================================================
call                           what it does
=============================  ===========================================================
``subscribe(channel)``         copy another module's data channel out of every visit
``publish(channel=None)``      write this module's data channel into every visit
``get_data`` / ``store_data``  the seed's registrations (locked until ``unlock_data``)
``lock_data`` / ``unlock_data``  pause / resume a registration; ``cancel_data`` ends it
``set_own_input_id()``         take this module's inbox (command channel)
``receive_command(timeout)``   the next command taken from the inbox, or None
``get_command()``              the seed's non-blocking form; ``command_received()``
``send_command(target, ...)``  put a command into ``target``'s inbox at the next visits
``deliver(target, ..., timeout)``  send and wait until acknowledged (True) or not
``command_transmitted`` / ``command_acknowledged``  the seed's flags of the last command
``wait_channel_free(target)``  wait until ``target``'s inbox can take a command
``wait_visit(timeout)``        wait for the next token visit; ``counter()`` the round
``channel(name)``              a channel of protocol.yaml by name
=============================  ===========================================================

:class:`ProgramAPI` is mixed into :class:`~tokenring.node.node_os.NodeOS`, which sets up the state it
declares; the token path reads the registrations through ``_active``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from tokenring.contract.protocol import Channel, CommandChannel, NodeSpec, Protocol
from tokenring.errors import ChannelError
from tokenring.node.channels import (
    ChannelBuffer,
    CommandMemory,
    DataRegistration,
    Inbox,
    Outbox,
    ReceivedCommand,
    _Offsets,
)
from tokenring.node.tokenpath import TokenPathHost


@dataclass(frozen=True)
class Delivery:
    """What became of a command sent until acknowledged: written into the inbox at least once,
    acknowledged, and in how many rounds."""

    transmitted: bool
    acknowledged: bool
    attempts: int


class ProgramAPI(TokenPathHost):
    """The calls user programs make on their node (mixed into NodeOS, which sets it up)."""

    protocol: Protocol
    name: str
    spec: NodeSpec | None
    incarnation: int
    command_memory: CommandMemory
    _cmd: _Offsets
    _cmd_seqs: dict[str, int]
    _regs: dict[str, DataRegistration]
    _inbox: Inbox | None
    _regs_lock: Any  # the runtime's lock and condition (tokenring.runtime)
    _visit_cond: Any

    @property
    def stopping(self) -> bool:
        raise NotImplementedError

    def channel(self, name: str) -> Channel:
        """A channel by ``node.kind``, seed name (``ROBSONAR_DATA``) or, for inboxes, node name."""
        if name in self.protocol.nodes:
            return self.protocol.nodes[name].command
        return self.protocol.channel(name)

    def set_token_area(self, channel: str, address: int | None = None) -> Channel:
        """Seed call; addresses come from protocol.yaml, so this only checks they agree."""
        ch = self.channel(channel)
        if address is not None and address != ch.address:
            raise ChannelError(f"{ch.name} lives at byte {ch.address} per protocol.yaml, not {address}")
        return ch

    def set_own_input_id(self, channel: str | None = None) -> None:
        """Declare this node's own command channel (default: the one protocol.yaml gives it)."""
        ch = self.channel(channel) if channel else (self.spec.command if self.spec else None)
        if not isinstance(ch, CommandChannel):
            raise ChannelError(f"{channel!r} is not a command channel")
        if self.spec is not None and ch.name != self.spec.command.name:
            raise ChannelError(f"{ch.name} belongs to {ch.node}, not to {self.name}")
        with self._regs_lock:
            if self._inbox is None or self._inbox.channel is not ch:
                self._inbox = Inbox(ch, self._cmd, self.membership.live, self.stats, self.command_memory)
            self._rebuild_active()

    def get_data(self, channel: str, owner: str = "program") -> ChannelBuffer:
        """Copy ``channel`` out of the token at every visit (once unlocked); returns the buffer.

        ``owner="os"`` marks a registration of an OS service (the PC link) that outlives the
        user program; the program's own registrations are dropped when it stops."""
        ch = self.channel(channel)
        if isinstance(ch, CommandChannel):
            if self.spec is not None and ch.node == self.spec.name:
                self.set_own_input_id(ch.name)
                assert self._inbox is not None
                return self._inbox.buffer
            raise ChannelError(f"{ch.name} is another module's inbox: use send_command")
        return self._register(ch, "get", owner)

    def store_data(self, channel: str) -> ChannelBuffer:
        """Copy the returned buffer into ``channel`` at every visit (once unlocked)."""
        ch = self.channel(channel)
        if isinstance(ch, CommandChannel):
            raise ChannelError(f"{ch.name} is a command channel: use send_command")
        if self.spec is not None and ch.node != self.spec.name:
            raise ChannelError(f"{ch.name} belongs to {ch.node}; only its owner may store into it")
        return self._register(ch, "store", "program")

    def _register(self, ch: Channel, kind: str, owner: str) -> ChannelBuffer:
        with self._regs_lock:
            reg = self._regs.get(ch.name)
            if reg is None or reg.kind != kind:
                reg = DataRegistration(ch, kind, ChannelBuffer(ch), owner)
                self._regs[ch.name] = reg
                self._rebuild_active()
            elif owner == "program":
                reg.owner = "program"  # shared with an OS service: the program now holds it too
            return reg.buffer

    def lock_data(self, channel: str) -> None:
        """Stop copying this channel (the seed's semaphore)."""
        self._set_locked(channel, True)

    def unlock_data(self, channel: str) -> None:
        """Resume copying this channel; for the own inbox: ready to receive the next command."""
        self._set_locked(channel, False)

    def _set_locked(self, channel: str, locked: bool) -> None:
        ch = self.channel(channel)
        with self._regs_lock:
            if self._inbox is not None and ch.name == self._inbox.channel.name:
                if not locked:
                    self._inbox.received = False
                    self._inbox.event.clear()
                self._inbox.locked = locked
                return
            reg = self._regs.get(ch.name)
            if reg is None:
                raise ChannelError(
                    f"{ch.name} is not registered on {self.name}: call get_data/store_data first"
                )
            reg.locked = locked
            self._rebuild_active()

    def cancel_data(self, channel: str) -> None:
        """Remove a registration."""
        ch = self.channel(channel)
        with self._regs_lock:
            if self._inbox is not None and ch.name == self._inbox.channel.name:
                self._inbox = None
            else:
                self._regs.pop(ch.name, None)
            self._rebuild_active()

    def subscribe(self, channel: str, owner: str = "program") -> ChannelBuffer:
        """get_data + unlock_data in one call."""
        buffer = self.get_data(channel, owner)
        self.unlock_data(channel)
        return buffer

    def publish(self, channel: str | None = None) -> ChannelBuffer:
        """store_data + unlock_data of this node's own data channel (or ``channel``)."""
        name = channel or (self.spec.data.name if self.spec else "")
        buffer = self.store_data(name)
        self.unlock_data(name)
        return buffer

    def send_command(self, target: str, command: str | int, **args: Any) -> Outbox:
        """Queue a command for another module's inbox; the OS writes it when the inbox is free.

        Every call is a new command with the next seq: a receiver that took an earlier one
        takes this one too."""
        outbox = self._queue_command(target, command, args)
        assert outbox is not None
        return outbox

    def _queue_command(
        self, target: str, command: str | int, args: dict[str, Any], again: Outbox | None = None
    ) -> Outbox | None:
        """Queue a command; with ``again``, the same command once more, under its own seq.

        A resend keeps the command's name (sender, incarnation, seq), so a receiver that took
        it already acknowledges it again and never hands it over twice. It is queued only while
        ``again`` is still the last command to ``target``: once a newer one was sent (by another
        thread), the receiver would clear this older seq unexecuted, never acknowledged: None.
        """
        ch = self.channel(target)
        if not isinstance(ch, CommandChannel):
            raise ChannelError(f"{ch.name} is not a command channel")
        cmd = ch.command(command)
        # token lock first (the handler's order): a waiting outbox is never replaced mid-visit
        with self._token_lock, self._regs_lock:
            current = self._outboxes.get(ch.name)
            if again is not None and current is not again:
                return None
            if current is not None and current.state == Outbox.IN_TOKEN:
                raise ChannelError(f"a command to {ch.name} is still travelling; wait for it first")
            if current is not None:
                current.cancel()
            if again is not None:
                seq = again.seq
            else:
                seq = self._cmd_seqs[ch.name] = (self._cmd_seqs.get(ch.name, 0) + 1) & 0xFFFF
            outbox = Outbox(ch, cmd, self._cmd, self.node_id, seq, args, self.stats, self.incarnation)
            self._outboxes[ch.name] = outbox
            self._pending_outboxes.append(outbox)
        return outbox

    def _sweep_own_commands(self, work: bytearray) -> None:
        """After a regeneration from an old copy, clear our own finished commands from it."""
        off = self._cmd
        for outbox in tuple(self._outboxes.values()):
            a = outbox.start
            if (
                outbox.state == Outbox.DONE
                and work[a + off.sender] == self.node_id
                and work[a + off.state] != off.FREE
            ):
                work[a : outbox.end] = bytes(outbox.end - a)
                self.stats.stale_commands_cleared += 1

    def _activate_outboxes(self) -> None:
        with self._regs_lock:
            self._rebuild_active()

    def _drop_outboxes(self, finished: list[Any]) -> None:
        with self._regs_lock:
            self._rebuild_active(exclude=finished)

    def _rebuild_active(self, exclude: list[Any] | None = None) -> None:
        """Recompute what the handler visits (caller holds the registration lock)."""
        items: list[Any] = [r for r in self._regs.values() if not r.locked]
        if self._inbox is not None:
            items.append(self._inbox)
        items.extend(
            o
            for o in self._outboxes.values()
            if o.state != Outbox.DONE and (exclude is None or o not in exclude)
        )
        self._active = tuple(items)
        self._pending_outboxes = []

    def command_transmitted(self, target: str) -> bool:
        """The last command to ``target`` was written into the token and came back."""
        outbox = self._outboxes.get(self.channel(target).name)
        return bool(outbox and outbox.transmitted)

    def command_acknowledged(self, target: str) -> bool:
        """... and the receiver's OS copied it into its structure."""
        outbox = self._outboxes.get(self.channel(target).name)
        return bool(outbox and outbox.acknowledged)

    def command_received(self, channel: str | None = None) -> bool:
        """Has a command arrived in this node's inbox (which is now locked)?"""
        return bool(self._inbox and self._inbox.received)

    def get_command(self) -> ReceivedCommand:
        """Decode the command in the inbox (call unlock_data on the inbox for the next one)."""
        if self._inbox is None or not self._inbox.received:
            raise ChannelError(f"no command received on {self.name}")
        return self._inbox.take()

    def receive_command(self, timeout: float | None = None) -> ReceivedCommand | None:
        """Wait for the next command, take it and reopen the inbox; None on timeout or stop."""
        inbox = self._inbox
        if inbox is None:
            self.set_own_input_id()
            inbox = self._inbox
            assert inbox is not None
        if inbox.locked and not inbox.received:
            self.unlock_data(inbox.channel.name)
        deadline = None if timeout is None else self._now() + timeout
        while not inbox.received:
            if self.stopping:
                return None
            remaining = 0.1 if deadline is None else min(0.1, deadline - self._now())
            if remaining <= 0:
                return None
            inbox.event.wait(remaining)
        received = inbox.take()
        self.unlock_data(inbox.channel.name)
        return received

    def deliver(self, target: str, command: str | int, *, timeout: float = 5.0, **args: Any) -> bool:
        """Send until acknowledged (resending after each unacknowledged round) or timeout.

        Each resend is the same command (same seq), never a new one: when the receiver took it
        but the acknowledgement was lost (a token regenerated from an older copy), the resend
        is acknowledged again and not handed over twice. False: not acknowledged in time, the
        receiver may or may not have it; a new call sends it as a new command."""
        return self.send_until_acknowledged(target, command, args, timeout).acknowledged

    def send_until_acknowledged(
        self, target: str, command: str | int, args: dict[str, Any], timeout: float, retry: bool = True
    ) -> Delivery:
        """:meth:`deliver` with its account (the PC link reports it); ``retry`` False: one round."""
        deadline = self._now() + timeout
        self.wait_channel_free(target, timeout)
        outbox: Outbox | None = self.send_command(target, command, **args)
        attempts, transmitted = 0, False
        while outbox is not None and not self.stopping:
            attempts += 1
            while not outbox.done.wait(0.05):
                if self.stopping or self._now() > deadline:
                    outbox.cancel()
                    return Delivery(transmitted, False, attempts)
            transmitted = transmitted or outbox.transmitted
            if outbox.acknowledged or not retry or self._now() > deadline:
                return Delivery(transmitted, outbox.acknowledged, attempts)
            self._sleep(min(0.002, max(0.0, deadline - self._now())))
            outbox = self._queue_command(target, command, args, again=outbox)
        return Delivery(transmitted, False, attempts)

    def wait_channel_free(self, target: str, timeout: float) -> bool:
        """Wait until no earlier command of ours to ``target`` is still travelling."""
        outbox = self._outboxes.get(self.channel(target).name)
        if outbox is None or outbox.state != Outbox.IN_TOKEN:
            return True
        return outbox.done.wait(timeout)

    def wait_visit(self, timeout: float | None = None) -> bool:
        """Block until the token's next visit; False on timeout or stop."""
        with self._visit_cond:
            self._visit_waiters += 1
            try:
                before = self.stats.visits
                ok = self._visit_cond.wait_for(lambda: self.stats.visits != before or self.stopping, timeout)
                return bool(ok) and not self.stopping
            finally:
                self._visit_waiters -= 1

    @property
    def counter(self) -> int:
        """The token counter seen at the last visit."""
        return max(self._last_counter, 0)
