"""An application's resident part of a node's OS: what the node runs from boot on while none of
its user programs runs.

The seed's nodes ran an OS of their own before any program was downloaded or started; on the LCD
node that OS had a menu ("OS V2.0 Main Menu": start the programs, list the nodes). The ring knows
nothing of what such a part does: an extension names a :class:`ResidentProgram` class for a node
(:meth:`tokenring.extensions.Extension.resident_program`), the node process runs it on a thread
of its own with the node's hardware client, and it steps aside while a user program runs.
"""

from __future__ import annotations

import logging
import traceback
from typing import TYPE_CHECKING, Any

from tokenring import runtime

if TYPE_CHECKING:
    from tokenring.node.node_os import NodeOS
    from tokenring.node.system.layer import SystemLayer

log = logging.getLogger("tokenring.resident")


class ResidentProgram:
    """Base class: ``setup``, then ``run`` until :attr:`running` turns false, then ``teardown``.

    It shares the node's hardware client (``self.hw``) with the user program, so it leaves the
    hardware alone while :attr:`program_running` is true."""

    def __init__(self, os: NodeOS, system: SystemLayer, hardware: Any = None) -> None:
        self.os = os
        self.system = system
        self.hw = hardware
        self.stop_requested = runtime.current().event()

    @property
    def running(self) -> bool:
        return not self.stop_requested.is_set() and not self.os.stopping

    @property
    def program_running(self) -> bool:
        """A user program runs on this node now (it has the hardware)."""
        return self.system.program_state().runs

    def wait(self, seconds: float) -> bool:
        """Sleep unless asked to stop; False if the resident should end."""
        return not self.stop_requested.wait(seconds) and not self.os.stopping

    def broadcast_start_system(self, timeout: float = 10.0) -> list[int]:
        """ARCNET_START_SYSTEM from this node: every node with a program starts it. Returns the
        IDs of the nodes that took it; raises :class:`~tokenring.node.system.vocabulary.SystemCommandError`."""
        return self.system.broadcast(self.system.START_SYSTEM, "start system", timeout)

    def scan_programs(self, timeout: float = 10.0) -> list[dict[str, Any]]:
        """ARCNET_SCAN, then ARCNET_GET_CONFIG of every node found: each node's ``id``, ``name``,
        program ``state``, ``stamp_ms`` (0: no program), ``size`` and ``sha256``, by ID."""
        ids = self.system.scan(timeout)
        configs = self.system.configs(ids, timeout) if ids else {}
        return [configs[i] for i in ids if i in configs]

    def setup(self) -> None:
        """Take what ``run`` needs."""

    def run(self) -> None:
        """The resident's loop; the default waits until asked to stop."""
        while self.wait(0.5):
            pass

    def teardown(self) -> None:
        """Release what ``setup`` took."""

    def report(self) -> dict[str, Any]:
        """What the resident tells tools (the control verb ``resident``); plain values."""
        return {}


class ResidentHost:
    """Runs one :class:`ResidentProgram` on its own thread; a failure is logged and reported,
    never taken further (the node and its user program go on)."""

    def __init__(
        self, resident_class: type[ResidentProgram], os: NodeOS, system: SystemLayer, hardware: Any
    ) -> None:
        self._rt = runtime.current()
        self.resident = resident_class(os, system, hardware)
        self.error: str | None = None
        self._name = f"resident-{os.name}"
        self._thread: Any = None  # the runtime's thread, once started

    def _run(self) -> None:
        resident = self.resident
        try:
            resident.setup()
            resident.run()
        except Exception as exc:
            self.error = traceback.format_exception_only(type(exc), exc)[-1].strip()
            log.error("resident %s failed: %s", type(resident).__name__, self.error)
            log.debug("traceback:\n%s", traceback.format_exc())
        finally:
            try:
                resident.teardown()
            except Exception as exc:
                log.error("resident teardown failed: %s", exc)

    def start(self) -> None:
        self._thread = self._rt.spawn(self._run, self._name)

    def stop(self, timeout: float = 1.0) -> None:
        self.resident.stop_requested.set()
        thread = self._thread
        if thread is not None and thread.is_alive() and thread is not self._rt.current_thread():
            thread.join(timeout)

    def control(self, _request: dict[str, Any]) -> dict[str, Any]:
        """The control verb ``resident``: its class, its error and its report."""
        report: dict[str, Any] = {}
        if self.error is None:
            try:
                report = self.resident.report()
            except Exception as exc:  # a report must not fail the query
                report = {"report_error": f"{type(exc).__name__}: {exc}"}
        return {
            "resident": type(self.resident).__name__,
            "alive": self._thread is not None and self._thread.is_alive(),
            "error": self.error,
            "report": report,
        }
