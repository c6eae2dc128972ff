"""The receiving side of system commands: answers written into the token (byte copies only, on
the token path), a worker thread for slow effects (verify, install, start, stop a program) and
the program state it reports. Mixed into :class:`~tokenring.node.system.layer.SystemLayer`."""

from __future__ import annotations

import logging
import zlib
from collections.abc import Callable
from typing import Any

from tokenring.errors import ProgramError, UsageError
from tokenring.node.program import load_program, program_sha256
from tokenring.node.store import Installed, format_stamp, now_ms
from tokenring.node.system.vocabulary import (
    ENCODINGS,
    ERROR_PARTS,
    START_GRACE_S,
    State,
    Status,
    Step,
    SystemParts,
    _clipped,
    _Download,
    _Job,
    _short,
)

log = logging.getLogger("tokenring.system")


class SystemReceiver(SystemParts):
    """Commands other nodes address to this one, and their effects."""

    # receiver side (in the token handler: byte copies only)

    def _set_bit(self, work: bytearray) -> None:
        work[self.w0 + (self.me >> 3)] |= 1 << (self.me & 7)

    def _bit_set(self, work: bytearray) -> bool:
        return bool(work[self.w0 + (self.me >> 3)] & (1 << (self.me & 7)))

    def _answer(self, work: bytearray, status: Status, detail: str = "") -> None:
        work[self.w0] = status
        if detail or status != Status.OK:
            raw = _clipped(detail, self.wsize - 1)
            work[self.w0 + 1 : self.w1] = raw + bytes(self.wsize - 1 - len(raw))

    def _take_scan(self, work: bytearray) -> None:
        self._set_bit(work)

    def _take_get_config(self, work: bytearray) -> None:
        installed = self.installed
        if installed is None:
            stamp, size, digest = 0, 0, bytes(8)
        else:
            stamp, size, digest = installed.stamp_ms, installed.size, installed.digest[:8]
        work[self.w0 : self.w1] = self.layouts.CONFIG.pack(
            Status.OK, self.program_state(), stamp, size, digest, _short(self.os.name, 10)
        )

    def _take_get_status(self, work: bytearray) -> None:
        error = self.os.program_error or ""
        work[self.w0 : self.w1] = self.layouts.STATUS.pack(
            Status.OK, self.program_state(), self._runs_installed(), _clipped(error, 29)
        )

    def _take_begin(self, work: bytearray) -> None:
        size, transfer, encoding, chunk = self.layouts.BEGIN.unpack_from(work, self.w0)
        self._job = None
        self._download = None
        if size > self.capacity:
            self._answer(work, Status.REFUSED, f"accepts up to {self.capacity} bytes")
            return
        if encoding not in ENCODINGS or not 0 < chunk <= self.chunk_size or transfer > 2 * self.capacity + 64:
            self._answer(work, Status.REFUSED, "bad download header")
            return
        chunks = (transfer + chunk - 1) // chunk
        self._download = _Download(size, transfer, encoding, chunk, chunks, bytearray(transfer))
        self.stats.downloads_begun += 1
        self._answer(work, Status.OK)

    def _take_data(self, work: bytearray) -> None:
        dl = self._download
        index = work[self.w0] | (work[self.w0 + 1] << 8)
        if dl is None:
            self._answer(work, Status.NOT_DOWNLOADING, "no DOWNLOAD_BEGIN")
            return
        if index == dl.next:
            n = work[self._o_length] - 2
            start = index * dl.chunk
            if n < 0 or start + n > dl.transfer:
                self._answer(work, Status.BAD_SEQUENCE, f"chunk {index} overruns the program")
                return
            dl.buffer[start : start + n] = work[self.w0 + 2 : self.w0 + 2 + n]
            if index == self.corrupt_chunk and n:  # test hook: a bad write into the node's RAM
                dl.buffer[start] ^= 0x20
                self.corrupt_chunk = None
            dl.next = index + 1
            self.stats.chunks_received += 1
            self.stats.bytes_received += n
            work[self.w0] = Status.OK
        elif index + 1 == dl.next:
            self.stats.chunk_repeats += 1
            work[self.w0] = Status.OK
        else:
            self._answer(work, Status.BAD_SEQUENCE, f"chunk {index}, expected {dl.next}")

    def _job_answer(self, work: bytearray, key: bytes) -> bool:
        """A repeat of the command whose job runs (or ran): answer its status."""
        job = self._job
        if job is None or job.key != key:
            return False
        self._answer(work, job.status, job.detail)
        return True

    def _new_job(self, work: bytearray, key: bytes, action: Callable[..., None], *args: Any) -> None:
        job = _Job(key)
        self._job = job
        self._work.put((action, (job, *args)))
        work[self.w0] = Status.PENDING

    def _take_terminated(self, work: bytearray) -> None:
        key = bytes([self.TERMINATED]) + bytes(work[self.w0 : self.w1])
        if self._job_answer(work, key):
            return
        dl = self._download
        if dl is None:
            self._answer(work, Status.NOT_DOWNLOADING, "no download in progress")
            return
        if dl.next < dl.chunks:
            self._answer(work, Status.BAD_SEQUENCE, f"incomplete: {dl.next} of {dl.chunks} chunks")
            return
        self._download = None
        self._new_job(work, key, self._verify, dl, bytes(work[self.w0 : self.w1]))

    def _take_send_config(self, work: bytearray) -> None:
        key = bytes([self.SEND_CONFIG]) + bytes(work[self.w0 : self.w0 + self.layouts.STAMP.size])
        if self._job_answer(work, key):
            return
        stamp, digest8 = self.layouts.STAMP.unpack_from(work, self.w0)
        verified, installed = self._verified, self.installed
        if verified is not None and verified.digest[:8] == digest8:
            self._new_job(work, key, self._install, verified, stamp)
        elif installed is not None and installed.digest[:8] == digest8:
            self._new_job(work, key, self._install, installed, stamp)
        else:
            self._answer(work, Status.NO_PROGRAM, "no verified download with this hash")

    def _take_start_program(self, work: bytearray) -> None:
        key = bytes([self.START_PROGRAM]) + bytes(work[self.w0 : self.w0 + self.layouts.NONCE.size])
        if not self._job_answer(work, key):
            self._new_job(work, key, self._start)

    def _take_stop_program(self, work: bytearray) -> None:
        key = bytes([self.STOP_PROGRAM]) + bytes(work[self.w0 : self.w0 + self.layouts.NONCE.size])
        if not self._job_answer(work, key):
            self._new_job(work, key, self._stop)

    def _take_start_system(self, work: bytearray) -> None:
        if self.installed is not None and not self._bit_set(work):
            self._set_bit(work)
            self._work.put((self._start, (None,)))

    def _take_stop_system(self, work: bytearray) -> None:
        if not self._bit_set(work):
            self._set_bit(work)
            self._work.put((self._stop, (None,)))

    def _take_error(self, work: bytearray) -> None:
        part, about, text = self.layouts.ERROR.unpack_from(work, self.w0)
        issuer = work[self._o_issuer]
        parts = self._error_parts.setdefault(issuer, {})
        parts[part & 0x7F] = text.rstrip(b"\0")
        work[self.w0] = Status.OK
        if part & 0x80:
            raw = b"".join(parts[i] for i in sorted(parts))
            del self._error_parts[issuer]
            self._work.put((self._record_error, (issuer, about, raw.decode("utf-8", "replace"))))

    # the worker: slow effects, off the token path

    def _work_loop(self) -> None:
        while not self._closing:
            # blocks: a failed program wakes it through NodeOS.on_program_error (no polling,
            # which 255 idle nodes would pay for 5 times a second each)
            item = self._work.get()
            if item is None:
                return
            action, args = item
            try:
                action(*args)
            except Exception as exc:  # the worker must survive anything
                log.exception("system worker: %s", exc)
                if args and isinstance(args[0], _Job):
                    args[0].detail = f"{type(exc).__name__}: {exc}"
                    args[0].status = Status.STORE_ERROR
            self._watch_program()

    def _verify(self, job: _Job, dl: _Download, digest: bytes) -> None:
        data = bytes(dl.buffer)
        if dl.encoding == 1:
            try:
                inflater = zlib.decompressobj()
                data = inflater.decompress(data, dl.size + 1)
            except zlib.error as exc:
                self._reject(job, Status.CORRUPT, f"cannot inflate: {exc}")
                return
        if len(data) != dl.size:
            self._reject(job, Status.CORRUPT, f"{len(data)} bytes, not {dl.size}")
            return
        got = program_sha256(data)
        if got != digest:
            self._reject(job, Status.CORRUPT, f"hash {got.hex()[:8]}, sent {digest.hex()[:8]}")
            return
        filename = f"{self.os.name}.py"
        try:
            program_class = load_program(data, filename)
        except ProgramError as exc:  # the status has room for 31 bytes, ARCNET_ERROR for all
            self._reject(job, Status.LOAD_ERROR, str(exc).removeprefix(filename).lstrip(": "))
            self._send_error(self.TERMINATED, str(exc))
            return
        wanted = getattr(program_class, "module", "")
        if wanted and wanted != self.os.name:
            self._reject(job, Status.LOAD_ERROR, f"program of {wanted!r}")
            return
        self._verified = Installed(data, digest, 0, filename, program_class)
        self.stats.downloads_verified += 1
        job.status = Status.OK

    def _reject(self, job: _Job, status: Status, detail: str) -> None:
        self.stats.downloads_rejected += 1
        log.warning("download rejected: %s: %s (the previous program stays)", status.name, detail)
        job.detail = detail
        job.status = status

    def _install(self, job: _Job, program: Installed, stamp_ms: int) -> None:
        try:
            filename = self.store.save(program.source, program.digest, stamp_ms)
        except OSError as exc:
            job.detail = f"store: {exc.strerror or exc}"  # the answer's 31 bytes; the report has all
            job.status = Status.STORE_ERROR
            log.error("cannot store the program: %s", exc)
            self._send_error(self.TERMINATED, f"cannot store the program: {exc}")
            return
        if self.installed is not None and self.installed.digest != program.digest:
            self._previous = self.installed  # what runs again if this one fails to start
        self.installed = Installed(program.source, program.digest, stamp_ms, filename, program.program_class)
        if self._verified is program:
            self._verified = None
        self.stats.installs += 1
        log.info(
            "program installed: %d bytes, sha256 %s, time stamp %s",
            program.size,
            program.digest.hex()[:12],
            format_stamp(stamp_ms),
        )
        job.status = Status.OK

    def _start(self, job: _Job | None) -> None:
        installed = self.installed
        if installed is None:
            if job is not None:
                job.detail, job.status = "no program installed", Status.NO_PROGRAM
            return
        if self.program_state().runs and self._running_digest == installed.digest:
            if job is not None:
                job.status = Status.OK
            return
        try:
            if installed.program_class is None:
                installed.program_class = load_program(installed.source, installed.filename)
            self.starter(installed.program_class)
        except Exception as exc:
            line = str(exc) if isinstance(exc, ProgramError) else f"{type(exc).__name__}: {exc}"
            self._send_error(self.START_PROGRAM, line)
            line += self._roll_back()
            if job is not None:
                job.detail, job.status = line, Status.START_FAILED
            return
        self._running_digest = installed.digest
        self.stats.starts += 1
        program = self.os.program
        rt = self._rt
        deadline = rt.monotonic() + START_GRACE_S
        while rt.monotonic() < deadline and self.os.program_error is None:
            rt.sleep(0.02)
        if self.os.program_error is not None and self.os.program is program:
            self._report_program_error(program)
            line = self.os.program_error + self._roll_back()
            if job is not None:
                job.detail, job.status = line, Status.START_FAILED
            return
        self._previous = None  # started: no way back needed any more
        if job is not None:
            job.status = Status.OK

    def _roll_back(self) -> str:
        """A newly installed program failed to start: the one before it is installed and run
        again (a failed load must not leave the node without its program). Returns what to
        add to the failure's report."""
        previous, self._previous = self._previous, None
        if previous is None:
            return ""
        try:
            self.store.save(previous.source, previous.digest, previous.stamp_ms)
            self.installed = previous
            if previous.program_class is None:
                previous.program_class = load_program(previous.source, previous.filename)
            self.starter(previous.program_class)
        except Exception as exc:
            log.error("the previous program could not be restored: %s", exc)
            return "; the previous program could not be restored"
        self._running_digest = previous.digest
        log.warning(
            "the new program failed to start: the previous one (sha256 %s) runs again",
            previous.digest.hex()[:12],
        )
        return "; the previous program runs again"

    def _stop(self, job: _Job | None) -> None:
        if self.os.program is not None:
            self.os.stop_program()
            self.stats.stops += 1
        self._running_digest = None
        if job is not None:
            job.status = Status.OK

    def _watch_program(self) -> None:
        """Report a program that raised (on start or later) through ARCNET_ERROR, once."""
        program = self.os.program
        if (
            program is not None
            and self.os.program_error is not None
            and self._reported_program is not program
        ):
            self._report_program_error(program)

    def _report_program_error(self, program: Any) -> None:
        if self._reported_program is program:
            return
        self._reported_program = program
        self._send_error(0, self.os.program_error or "failed")

    def _send_error(self, about: int, text: str) -> None:
        """ARCNET_ERROR to the master: ``text`` in 30-byte parts (up to 240 bytes)."""
        raw = _clipped(text, 30 * ERROR_PARTS) or b"?"
        parts = [raw[i : i + 30] for i in range(0, len(raw), 30)]
        master = self.os.preferred_master or self.me
        steps = [
            Step(
                master,
                self.ERROR,
                self.layouts.ERROR.pack(i | (0x80 if i == len(parts) - 1 else 0), about, part),
            )
            for i, part in enumerate(parts)
        ]
        self.stats.errors_sent += 1
        self.submit(steps, "error report")

    def _record_error(self, issuer: int, about: int, text: str) -> None:
        spec = self.os.protocol.by_id.get(issuer)
        entry = {
            "n": next(self._error_count),
            "node": issuer,
            "name": spec.name if spec else f"node{issuer}",
            "about": self.os.protocol.system_command_name(about) if about else "program",
            "text": text,
            "time_ms": now_ms(),
        }
        self.stats.errors_received += 1
        self.errors.append(entry)
        log.warning("ARCNET_ERROR from %s (id %d, %s): %s", entry["name"], issuer, entry["about"], text)

    # state

    def program_state(self) -> State:
        os_ = self.os
        program = os_.program
        if program is None:
            return State.STOPPED if self.installed is not None else State.NONE
        if os_.program_error is not None:
            return State.FAILED
        if os_.setting_up:
            return State.SETTING_UP
        thread = os_._program_thread
        return State.RUNNING if thread is not None and thread.is_alive() else State.STOPPED

    def _runs_installed(self) -> bool:
        installed = self.installed
        return bool(
            installed is not None and self._running_digest == installed.digest and self.program_state().runs
        )

    def adopt(self, source: bytes, stamp_ms: int, filename: str, program_class: type) -> None:
        """A program started from a file (``--program``): report it as installed (not stored)."""
        digest = program_sha256(source)
        self.installed = Installed(source, digest, stamp_ms, filename, program_class)
        self._running_digest = digest

    def start_installed(self) -> bool:
        """Start the stored program at boot (``--autostart``); False if there is none."""
        if self.installed is None:
            return False
        self._work.put((self._start, (None,)))
        return True

    def report(self) -> dict[str, Any]:
        """The control verb ``system``: counters, the installed program, the error log."""
        installed = self.installed
        download = self._download
        return {
            "stats": vars(self.stats).copy(),
            "state": self.program_state().name,
            # the download under way: its chunks, and how many have come in order so far
            "download": None if download is None else {"chunks": download.chunks, "received": download.next},
            "runs_installed": self._runs_installed(),
            "installed": None
            if installed is None
            else {
                "size": installed.size,
                "sha256": installed.digest.hex(),
                "stamp_ms": installed.stamp_ms,
                "file": installed.filename,
            },
            "store": str(self.store.directory) if self.store.directory else None,
            "capacity": self.capacity,
            "errors": list(self.errors),
        }

    def control(self, request: dict[str, Any]) -> dict[str, Any]:
        """Control verb ``system``: the report; ``{"corrupt_chunk": N}`` arms the test hook."""
        if "corrupt_chunk" in request:
            value = request["corrupt_chunk"]
            if not isinstance(value, int) or value < 0:
                raise UsageError("corrupt_chunk needs a chunk index >= 0")
            self.corrupt_chunk = value
        return self.report()
