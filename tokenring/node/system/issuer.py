"""The issuing side of system commands: the token handler's hook (a transaction's steps written
into the token, their answers read back) and the calls that queue transactions (scan, configs,
download, start, stop). Mixed into :class:`~tokenring.node.system.layer.SystemLayer`."""

from __future__ import annotations

import contextlib
import logging
import zlib
from typing import Any

from tokenring.contract.ring import EPOCH_MASK
from tokenring.errors import UsageError
from tokenring.node.program import program_sha256
from tokenring.node.system.vocabulary import (
    EXCLUDED_WAIT_S,
    LOST_LIMIT,
    NO_ACK_LIMIT,
    POLL_TIMEOUT_S,
    State,
    Status,
    Step,
    SystemCommandError,
    SystemParts,
    Transaction,
    _text,
    decode_config,
)

log = logging.getLogger("tokenring.system")


class SystemIssuer(SystemParts):
    """Transactions this node issues, one step per free round."""

    # the token handler hook (hot path)

    def handle(self, work: bytearray) -> bool:
        """Called at every token visit; True while a system command is active (user channels pause)."""
        issuer = work[self._o_issuer]
        if not issuer:
            if not self.os.system_busy:
                return False
            return self._begin(work)
        if issuer == self.me:
            return self._returned(work)
        if issuer not in self.os.membership.active:
            self._clear_orphan(work, issuer)
            return self._begin(work) if self.os.system_busy else False
        target = work[self._o_target]
        if target == self.me or target == self.all_nodes:
            self._take(work)
        return True

    def _take(self, work: bytearray) -> None:
        receiver = self._receivers.get(work[self._o_code])
        self.stats.commands_taken += 1
        if receiver is None:
            work[self.w0] = Status.UNKNOWN_COMMAND
        else:
            receiver(work)
        if work[self._o_target] != self.all_nodes or not work[self._o_ack]:
            work[self._o_ack] = self.me

    def _clear_orphan(self, work: bytearray, issuer: int) -> None:
        """The issuer left or hangs: nobody will restore its window; clear it (zeros are every
        channel's initial state) so that user communication resumes."""
        self.stats.orphans_cleared += 1
        log.warning("system command of node %d cleared: the node is no longer on the ring", issuer)
        for offset in (self._o_issuer, self._o_target, self._o_code, self._o_length, self._o_ack):
            work[offset] = 0
        work[self.w0 : self.w1] = bytes(self.wsize)

    def _epoch(self, work: bytearray) -> int:
        return ((work[self._o_epoch] & EPOCH_MASK) << 8) | work[self._o_origin]

    def _begin(self, work: bytearray) -> bool:
        """The token is free of system commands and we have one to send."""
        tx = self._current
        if tx is not None:
            # our command vanished from the token (regenerated from an older copy, cleared as an
            # orphan while we hung): the window was not restored by us, so save it again
            tx.lost += 1
            self.stats.lost_commands += 1
            if tx.lost > LOST_LIMIT:
                self._finish(tx, f"the command vanished from the token {tx.lost} times")
                return False
        else:
            if self._rest:
                self._rest = False
                return False
            with self._lock:
                if not self._queue:
                    self.os.system_busy = False
                    return False
                tx = self._queue.popleft()
            self._current = tx
            tx.started = self._clock()
        self._saved = bytes(work[self.w0 : self.w1])
        self._write(work, tx)
        return True

    def _write(self, work: bytearray, tx: Transaction) -> None:
        step = tx.steps[tx.index]
        payload = step.payload
        work[self._o_issuer] = self.me
        work[self._o_target] = step.target
        work[self._o_code] = step.code
        work[self._o_length] = len(payload)
        work[self._o_ack] = 0
        work[self.w0 : self.w0 + len(payload)] = payload
        tx.epoch = self._epoch(work)
        self.stats.commands_issued += 1
        if step.target == self.me or step.target == self.all_nodes:
            self._take(work)  # the issuer is its own first receiver

    def _returned(self, work: bytearray) -> bool:
        """Our command made the round: read the answer, then the next step, or restore."""
        tx = self._current
        if tx is None:  # an old copy of a finished command came back after a regeneration
            self._restore(work)
            return False
        tx.rounds += 1
        if tx.cancelled:
            self._finish(tx, "cancelled (timed out)")
            return self._next_or_restore(work)
        if self._epoch(work) != tx.epoch:  # the answer may belong to an older copy: resend
            tx.resends += 1
            self.stats.resends += 1
            self._write(work, tx)
            return True
        step = tx.steps[tx.index]
        if step.target != self.all_nodes:
            if work[self._o_ack] != step.target:
                membership = self.os.membership
                if step.target not in membership.live:
                    self._finish(tx, f"node {step.target} left the ring")
                    return self._next_or_restore(work)
                if step.target not in membership.active:
                    now = self._clock()
                    if not tx.excluded_since:
                        tx.excluded_since = now
                    elif now - tx.excluded_since > EXCLUDED_WAIT_S:
                        self._finish(
                            tx,
                            f"node {step.target} is skipped by the ring (not answering for {EXCLUDED_WAIT_S:.0f} s)",
                        )
                        return self._next_or_restore(work)
                else:
                    tx.retries += 1
                if tx.retries > NO_ACK_LIMIT:
                    self._finish(tx, f"node {step.target} did not acknowledge")
                    return self._next_or_restore(work)
                tx.resends += 1
                self.stats.resends += 1
                self._write(work, tx)
                return True
            tx.excluded_since = 0.0  # the target answered: a later skip starts its own wait
            status = work[self.w0]
            if status == Status.PENDING and step.poll:
                now = self._clock()
                if not tx.poll_deadline:
                    tx.poll_deadline = now + POLL_TIMEOUT_S
                elif now > tx.poll_deadline:
                    self._finish(tx, f"node {step.target} did not finish within {POLL_TIMEOUT_S:.0f} s")
                    return self._next_or_restore(work)
                self._write(work, tx)
                return True
            if status != Status.OK:
                tx.status = Status(status) if status in Status._value2member_map_ else None
                detail = _text(bytes(work[self.w0 + 1 : self.w1]))
                name = tx.status.name if tx.status is not None else f"status {status}"
                self._finish(tx, f"{name}: {detail}" if detail else name)
                return self._next_or_restore(work)
        if step.keep:
            tx.answers[tx.index] = bytes(work[self.w0 : self.w1])
        tx.index += 1
        tx.retries = 0
        tx.poll_deadline = 0.0
        if tx.index < len(tx.steps):
            self._write(work, tx)
            return True
        self._finish(tx, None)
        return self._next_or_restore(work)

    def _finish(self, tx: Transaction, error: str | None) -> None:
        if error is not None:
            tx.error = error
            tx.failed_step = tx.index
        tx.finished = self._clock()
        if self._current is tx:
            self._current = None
        tx.done.set()

    def _next_or_restore(self, work: bytearray) -> bool:
        self._restore(work)
        self._rest = True  # one free round for others before our next transaction
        with self._lock:
            self.os.system_busy = bool(self._queue) or self._current is not None
        return False

    def _restore(self, work: bytearray) -> None:
        for offset in (self._o_issuer, self._o_target, self._o_code, self._o_length, self._o_ack):
            work[offset] = 0
        if self._saved is not None:
            work[self.w0 : self.w1] = self._saved

    # issuer API (any thread)

    def submit(self, steps: list[Step], what: str = "") -> Transaction:
        tx = Transaction(steps, what)
        if not steps:
            tx.done.set()
            return tx
        with self._lock:
            self._queue.append(tx)
            self.os.system_busy = True
        return tx

    def execute(self, steps: list[Step], what: str = "", timeout: float = 10.0) -> Transaction:
        """Submit and wait; raises :class:`SystemCommandError` if it failed or timed out."""
        tx = self.submit(steps, what)
        if not tx.done.wait(timeout):
            tx.cancelled = True
            with self._lock, contextlib.suppress(ValueError):
                self._queue.remove(tx)
            raise SystemCommandError(f"{what or 'system command'}: no answer within {timeout:.0f} s")
        if tx.error is not None:
            step = tx.steps[tx.failed_step or 0]
            raise SystemCommandError(f"{what}: {tx.error}", tx.status, step.target)
        return tx

    def scan(self, timeout: float = 5.0) -> list[int]:
        """ARCNET_SCAN: the IDs of every node that answered in one round."""
        bitmap = bytearray(self.wsize)
        tx = self.execute([Step(self.all_nodes, self.SCAN, bytes(bitmap), keep=True)], "scan", timeout)
        answer = tx.answers[0]
        return [i for i in range(1, 256) if i >> 3 < len(answer) and answer[i >> 3] & (1 << (i & 7))]

    def configs(self, ids: list[int], timeout: float = 10.0) -> dict[int, dict[str, Any]]:
        """ARCNET_GET_CONFIG of each node (one transaction, one round each)."""
        steps = [Step(i, self.GET_CONFIG, keep=True) for i in ids]
        tx = self.execute(steps, "get config", timeout)
        return {ids[i]: decode_config(answer, ids[i], self.layouts) for i, answer in tx.answers.items()}

    def download_steps(
        self, target: int, source: bytes, stamp_ms: int, *, compress: bool = True, start: bool = False
    ) -> list[Step]:
        """BEGIN, one DATA per chunk, TERMINATED (verify), SEND_CONFIG (install), START_PROGRAM."""
        blob = zlib.compress(source, 9) if compress else source
        encoding = 1 if compress else 0
        if compress and len(blob) >= len(source):
            blob, encoding = source, 0
        size = self.chunk_size
        chunks = (len(blob) + size - 1) // size
        if chunks > 0xFFFF:
            raise UsageError(f"a program of {len(source)} bytes needs {chunks} chunks, more than 65535")
        digest = program_sha256(source)
        steps = [Step(target, self.BEGIN, self.layouts.BEGIN.pack(len(source), len(blob), encoding, size))]
        steps += [
            Step(target, self.DATA, self.layouts.INDEX.pack(i) + blob[i * size : (i + 1) * size])
            for i in range(chunks)
        ]
        steps.append(Step(target, self.TERMINATED, digest, poll=True))
        steps.append(Step(target, self.SEND_CONFIG, self.layouts.STAMP.pack(stamp_ms, digest[:8]), poll=True))
        if start:
            steps.append(self.start_step(target))
        return steps

    def start_step(self, target: int) -> Step:
        return Step(target, self.START_PROGRAM, self.layouts.NONCE.pack(self._rng.getrandbits(32)), poll=True)

    def stop_step(self, target: int) -> Step:
        return Step(target, self.STOP_PROGRAM, self.layouts.NONCE.pack(self._rng.getrandbits(32)), poll=True)

    def restamp_step(self, target: int, digest: bytes, stamp_ms: int) -> Step:
        return Step(target, self.SEND_CONFIG, self.layouts.STAMP.pack(stamp_ms, digest[:8]), poll=True)

    def broadcast(self, code: int, what: str, timeout: float = 5.0) -> list[int]:
        """START_SYSTEM / STOP_SYSTEM: the IDs of the nodes that took it."""
        tx = self.execute([Step(self.all_nodes, code, bytes(self.wsize), keep=True)], what, timeout)
        answer = tx.answers[0]
        return [i for i in range(1, 256) if answer[i >> 3] & (1 << (i & 7))]

    def status_of(self, target: int, timeout: float = 5.0) -> dict[str, Any]:
        tx = self.execute([Step(target, self.GET_STATUS, keep=True)], "get status", timeout)
        _, state, current, error = self.layouts.STATUS.unpack(tx.answers[0])
        return {"state": State(state).name, "runs_installed": bool(current), "error": _text(error) or None}
