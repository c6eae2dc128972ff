"""Program hosting and introspection: a node runs one user program on a thread of its own,
and describes itself for ``stats`` queries (``tokenring status``, ``monitor``).

:class:`ProgramHost` is mixed into :class:`~tokenring.node.node_os.NodeOS`, which sets up the state
it declares.
"""

from __future__ import annotations

import logging
import os
import socket
import sys
import traceback
from collections.abc import Callable
from typing import Any

from tokenring.contract import ring as R
from tokenring.node.channels import DataRegistration, Inbox, Outbox
from tokenring.node.tokenpath import TokenPathHost

log = logging.getLogger("tokenring.node")

#: a program's ``setup()`` that has not returned after this long is reported (the log, the
#: launcher's output): until it returns the program shows as setting up, and its run() waits
SETUP_WARNING_S = 10.0


def program_file(program: Any) -> str:
    """The file a program was loaded from (``motor.py`` when downloaded), else its class name."""
    module = sys.modules.get(type(program).__module__)
    return str(getattr(module, "__file__", None) or type(program).__name__)


class ProgramHost(TokenPathHost):
    """Runs a node's user program and reports on the node (mixed into NodeOS)."""

    name: str
    timing: R.Timing
    on_program_error: Callable[[], None] | None
    #: told (program file, "setup" or "run", the error's last line) when a program raises
    #: before it was asked to stop: the node process tells its launcher (the run's exit code)
    on_program_failed: Callable[[str, str, str], None] | None = None
    program_error: str | None
    _halt: Any  # the runtime's event, lock, condition and thread (tokenring.runtime)
    _program: Any
    _program_thread: Any
    _program_set_up: bool  # the current program's setup() has returned
    _program_started: float  # the node's clock (_now) when the current program was started
    _regs: dict[str, DataRegistration]
    _inbox: Inbox | None
    _regs_lock: Any
    _visit_cond: Any

    def _rebuild_active(self, exclude: list[Any] | None = None) -> None:
        raise NotImplementedError

    @property
    def counter(self) -> int:
        raise NotImplementedError

    def start_program(self, program_class: type, *args: Any) -> None:
        """Instantiate and run a user program in its own thread (``setup`` then ``run``)."""
        self.stop_program()
        self._halt.clear()
        self.program_error = None
        program = program_class(self, *args)
        self._program = program
        self._program_set_up = False
        self._program_started = self._now()
        warning = self._rt.timer(SETUP_WARNING_S, self._warn_setting_up, (program,))
        warning.daemon = True

        def runner() -> None:
            phase = "setup"
            try:
                program.setup()
                warning.cancel()
                self._program_set_up = program is self._program
                phase = "run"
                program.run()
            except Exception as exc:  # a user program's bug must not take the node down
                # read before on_program_error: the rollback it starts stops this program too
                was_stopping = program.stop_requested.is_set() or self._halt.is_set()
                last = traceback.format_exception_only(type(exc), exc)[-1].strip()
                self.program_error = last
                log.error("user program %s failed: %s", type(program).__name__, last)
                log.debug("traceback:\n%s", traceback.format_exc())
                if self.on_program_error is not None:
                    self.on_program_error()
                # one that raises because it was being stopped (a blocking call cut short) is
                # logged, not counted
                if self.on_program_failed is not None and not was_stopping:
                    self.on_program_failed(program_file(program), phase, last)
            finally:
                warning.cancel()
                try:
                    program.teardown()
                except Exception as exc:
                    log.error("user program teardown failed: %s", exc)

        self._program_thread = self._rt.spawn(runner, f"program-{self.name}")
        warning.start()

    def _warn_setting_up(self, program: Any) -> None:
        """Say that ``program``'s setup() has not returned yet (it may never: a blocking call)."""
        if program is self._program and not self._program_set_up and not program.stop_requested.is_set():
            log.warning(
                "user program %s: setup() has not returned after %.0f s, so its run() has not "
                "started (it shows as SETTING_UP in 'tokenring status' and 'tokenring load')",
                type(program).__name__,
                self._now() - self._program_started,
            )

    def stop_program(self, timeout: float = 1.0) -> bool:
        """Ask the running program to stop, wait for it, drop its registrations."""
        program, thread = self._program, self._program_thread
        if program is None:
            return True
        program.stop_requested.set()
        self._halt.set()
        with self._visit_cond:
            self._visit_cond.notify_all()
        if thread is not None and thread is not self._rt.current_thread():
            thread.join(timeout)
        stopped = thread is None or not thread.is_alive()
        if not stopped:
            log.warning("user program %s did not stop within %.1f s", type(program).__name__, timeout)
        with self._regs_lock:
            self._regs = {k: r for k, r in self._regs.items() if r.owner != "program"}
            self._inbox = None
            for outbox in self._outboxes.values():
                if outbox.state == Outbox.WAITING:
                    outbox.cancel()
            self._rebuild_active()
        self._program = None
        self._program_thread = None
        self._halt.clear()  # only the stopping program's blocking calls were to return early
        return stopped

    @property
    def program(self) -> Any:
        return self._program

    @property
    def setting_up(self) -> bool:
        """The current program is inside its ``setup()`` (its thread alive, setup not returned)."""
        thread = self._program_thread
        return (
            self._program is not None
            and not self._program_set_up
            and self.program_error is None
            and thread is not None
            and thread.is_alive()
        )

    def program_status(self) -> str | None:
        """``setting up``, ``running``, ``failed`` or ``stopped``; None without a program."""
        if self._program is None:
            return None
        if self.program_error is not None:
            return "failed"
        if self.setting_up:
            return "setting up"
        thread = self._program_thread
        return "running" if thread is not None and thread.is_alive() else "stopped"

    @property
    def program_set_up(self) -> bool:
        """The current program's ``setup()`` has returned: requests to it (the PC link's) may
        use what it set up."""
        return self._program is not None and self._program_set_up

    # =========================================================================================
    # introspection

    def snapshot(self) -> dict[str, Any]:
        """Counters, membership and timing for ``stats`` queries, the monitor and benchmarks."""
        timing = self.timing
        t = timing.current
        rounds = timing.rounds.recent(512)  # recent: a status must follow what happens now
        handler = timing.handler.recent(512)
        send = timing.send.recent(512)

        def pct(values: list[float], q: float) -> float:
            return R.percentiles(values, (q,))[0] * 1e3  # plain Python: no numpy in a node

        return {
            "id": self.node_id,
            "name": self.name,
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "epoch": [self._epoch, self._origin],
            "counter": self.counter,
            "master": min(self.membership.active),
            "successor": self.membership.successor,
            "live": sorted(self.membership.live),
            "active": list(self.membership.active),
            "excluded": sorted(self.membership.excluded),
            "stats": self.stats.as_dict(),
            "timeouts_ms": {
                "hop": t.hop * 1e3,
                "ack": t.ack * 1e3,
                "recon": t.recon * 1e3,
                "slot": t.slot * 1e3,
                "ack_interval": t.ack_interval * 1e3,
            },
            "round_ms": {"median": pct(rounds, 50), "p99": pct(rounds, 99), "n": len(rounds)},
            "handler_us": {
                "median": pct(handler, 50) * 1e3,
                "p99": pct(handler, 99) * 1e3,
                "n": len(handler),
            },
            "send_us": {"median": pct(send, 50) * 1e3, "p99": pct(send, 99) * 1e3},
            "program": type(self._program).__name__ if self._program is not None else None,
            "program_state": self.program_status(),
            "setup_s": round(self._now() - self._program_started, 1) if self.setting_up else None,
            "program_error": self.program_error,
            "bitrate": timing.bitrate,
            "ack_mode": timing.ack_mode,
        }

    def round_times(self) -> list[float]:
        """Seconds between this node's last visits (up to 1024)."""
        return self.timing.rounds.as_list()
