"""The services a launcher runs beside its nodes (the world simulator, the watcher that records
and serves the web view): started before the nodes, watched like them — a death is named and
counted in the exit code, ``--respawn`` starts again only what keeps no state — stopped after
them."""

from __future__ import annotations

import contextlib
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

from tokenring.errors import TokenRingError, TransportError, UsageError
from tokenring.host.children import KILL_REAP_S, RESPAWN_DELAY_S, describe_exit

if TYPE_CHECKING:
    from tokenring.host.launcher import Launcher


#: a service gets this long after SIGTERM before SIGKILL: longer than a node's, because a world
#: simulator closes its session and its logs after the nodes' last requests, and on a loaded
#: machine that took more than a node's 1.5 s (a stop then ended in a false failure)
STOP_TIMEOUT_S = 5.0


@dataclass
class ServicePlan:
    """A helper process the ring needs (e.g. the world simulator): started before the nodes,
    stopped after them, its output prefixed with ``name``. ``argv`` follows ``python -m``;
    ``{endpoint}``, ``{ring}`` and ``{connect}`` in it are filled in by the launcher."""

    name: str
    argv: list[str]
    ready_key: str | None = None  # a liveliness key the launcher waits for before the nodes start
    ready_timeout: float = 15.0
    #: ``--respawn`` may start it again after a death: it keeps nothing a new one would lack
    #: (a world simulator keeps the robot's pose, a recorder its file: they are not restarted)
    restart: bool = False


@dataclass
class ServiceChild:
    """A service process the launcher supervises (its ``service_children`` entry's record)."""

    plan: ServicePlan
    process: subprocess.Popen
    restarts: int = 0
    reported: bool = False
    group_ended: bool = False


class ServiceSupervisor:
    """Starts, watches and stops one launcher's services, through the launcher's own process
    plumbing (its output, its exit watch, its process groups, its failures)."""

    def __init__(self, launcher: Launcher) -> None:
        self.launcher = launcher
        self.children: dict[str, subprocess.Popen] = {}  # the running process of each service
        self.records: dict[str, ServiceChild] = {}
        self._due: dict[str, float] = {}  # service -> when --respawn starts it again

    def start(self, service: ServicePlan, wait_ready: bool = True) -> subprocess.Popen:
        """Start a service process and wait until its ``ready_key`` liveliness token appears
        (not when ``--respawn`` starts it again: the supervisor does not wait)."""
        launcher = self.launcher
        fill = {
            "endpoint": launcher.endpoint or "",
            "ring": launcher.ring,
            "connect": (launcher.node_connect() or [""])[0],
        }
        argv = [sys.executable, "-m", *(a.format(**fill) for a in service.argv)]
        process = launcher.popen_child(argv, service.name)
        self.children[service.name] = process
        previous = self.records.get(service.name)
        record = ServiceChild(service, process, restarts=previous.restarts + 1 if previous else 0)
        self.records[service.name] = record
        launcher.watch_exit(process.pid, record)
        if wait_ready and service.ready_key and launcher.session is not None:
            deadline = time.monotonic() + service.ready_timeout
            while time.monotonic() < deadline:
                if any(r.ok for r in launcher.session.liveliness().get(service.ready_key, timeout=0.5)):
                    break
                if process.poll() is not None:
                    raise UsageError(f"{service.name} {describe_exit(process.poll())} while starting")
                time.sleep(0.05)
            else:
                raise TransportError(f"{service.name} did not come up within {service.ready_timeout:.0f} s")
        return process

    def due(self) -> list[float]:
        """When the services waiting for ``--respawn`` are due (monotonic seconds)."""
        return list(self._due.values())

    def check(self, stopping: bool) -> None:
        """Report services that died (not during the stop) and end what they started; start
        the ones due again."""
        launcher = self.launcher
        for record in list(self.records.values()):
            code = record.process.poll()
            if code is None or record.reported or stopping:
                continue
            record.reported = True
            launcher.end_group(record)
            self._died(record, code)
        now = time.monotonic()
        for name, due in list(self._due.items()):
            if now >= due and not stopping:
                del self._due[name]
                launcher.say(f"respawning {name}")
                try:
                    self.start(self.records[name].plan, wait_ready=False)
                except (OSError, TokenRingError) as exc:
                    launcher.failure(f"{name} could not be started again: {exc}")

    def _died(self, record: ServiceChild, code: int) -> None:
        """A service died mid-run: say so, restart it if ``--respawn`` and it is safe, count it."""
        launcher = self.launcher
        name, pid = record.plan.name, record.process.pid
        if launcher.respawn and record.plan.restart:
            launcher.failure(f"service {name} (pid {pid}) {describe_exit(code)}; restarting it")
            self._due.setdefault(name, time.monotonic() + RESPAWN_DELAY_S)
            return
        why = (
            "--respawn does not restart it: a new one would not have its state"
            if launcher.respawn
            else "the ring goes on without it"
        )
        launcher.failure(f"service {name} (pid {pid}) {describe_exit(code)}: {why}")

    def stop(self) -> None:
        """SIGTERM each service, SIGKILL it after :data:`STOP_TIMEOUT_S`; one that failed to stop cleanly (an
        exit code, or not stopping in time: a recorder may not have finished its file) counts."""
        launcher = self.launcher
        for name, process in self.children.items():
            record = self.records.get(name)
            if process.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    process.send_signal(signal.SIGTERM)
                try:
                    code = process.wait(STOP_TIMEOUT_S)
                    if code not in (0, -signal.SIGTERM) and record is not None and not record.reported:
                        launcher.failure(
                            f"service {name} (pid {process.pid}) {describe_exit(code)} as it stopped"
                        )
                except subprocess.TimeoutExpired:
                    launcher.failure(f"service {name} did not stop in {STOP_TIMEOUT_S} s: killing it")
                    with contextlib.suppress(ProcessLookupError):
                        process.kill()
                    try:  # a loaded machine may take seconds to reap it; the stop goes on
                        process.wait(KILL_REAP_S)
                    except subprocess.TimeoutExpired:
                        launcher.say(f"{name} (pid {process.pid}) survived SIGKILL")
            if record is not None and record.process is process and process.poll() is not None:
                record.reported = True
                launcher.end_group(record)
