"""The other hosts of ``tokenring up --hosts``: each runs its share of the ring as a ``tokenring up
--share`` started over SSH, supervised by the launcher like its own nodes.

The system's ``ssh`` client, not a library: the user's ssh_config, agent, ProxyJump and
known_hosts all apply as they do for any ``ssh`` the user types. A share is its host's Zenoh
router (its nodes are its clients) and connects to the launcher's router, the hub. It stops
when its standard input closes: the launcher closes it to stop the ring, and a dropped SSH
session closes it too. The launcher also writes a line to it every :data:`HEARTBEAT_S`; a share
that hears nothing for its host's ``lost_after`` stops by itself, so that a host cut off while
the launcher stopped does not keep its share until its sshd notices. A share whose SSH
connection is lost (ssh's exit code 255), or that stopped for want of the launcher, is started
again until the launcher stops: its nodes rejoin when the host is back.
"""

from __future__ import annotations

import contextlib
import os
import re
import shlex
import signal
import subprocess
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import zenoh

from tokenring.contract import keys
from tokenring.errors import UsageError
from tokenring.host.children import KILL_REAP_S, describe_exit

if TYPE_CHECKING:
    from tokenring.host.hosts import Host, Inventory
    from tokenring.host.launcher import Launcher

#: ssh's own exit code for a connection that failed or was lost (the remote command's otherwise)
SSH_FAILED = 255
#: the shell's "command not found"
NOT_FOUND = 127
#: a share's exit code once it stopped for want of the launcher (sysexits' EX_TEMPFAIL)
SHARE_LOST = 75
#: a usage error's: a share refused to start (e.g. its host's previous share still holds the ring)
REFUSED = 2
#: how often the launcher tells each share it is there (a line on the share's input)
HEARTBEAT_S = 1.0
#: how long a share gets to stop its nodes once its input closed, before its ssh is ended
SHARE_STOP_S = 10.0
#: reconnecting a lost host: first after this long, doubling up to RECONNECT_MAX_S
RECONNECT_S = 1.0
RECONNECT_MAX_S = 10.0
#: defaults after the inventory's own options, so that those win (ssh keeps an option's first
#: value): never prompt (nobody could answer), and find a silently dead connection in ~15 s
SSH_DEFAULTS = (
    "-o", "BatchMode=yes",
    "-o", "ConnectTimeout=10",
    "-o", "ServerAliveInterval=5",
    "-o", "ServerAliveCountMax=3",
)  # fmt: skip
#: a share's output line, as its launcher prefixes it: ``   name | text``
_PREFIXED = re.compile(r"^\s*(\S+) \| (.*)$")
#: a share's last line, with why its run was not whole: ``stopped (exit code 1): REASONS``
_STOPPED = re.compile(r"^stopped \(exit code \d+\)(?:: (.*))?$")


@dataclass
class ShareSettings:
    """What every share is told: the ring's settings as the launcher resolved them."""

    ring: str
    bitrate: str
    ack: str
    log_level: str
    total: int  # nodes in the whole ring (the first token waits for them)
    hub: str  # the launcher's router, which every share's router connects to
    scheme: str = "tcp"
    respawn: bool = False
    profile: str | None = None
    protocol: str | None = None
    zenoh_config: str | None = None
    no_programs: bool = False
    no_download: bool = False
    programs: str | None = None
    env: dict[str, str] = field(default_factory=dict)


def ssh_command(host: Host, remote: Sequence[str], env: Mapping[str, str] | None = None) -> list[str]:
    """``ssh`` to ``host`` running ``remote`` there (through ``env`` with ``env``); the
    inventory's options come first, so they win over the defaults."""
    argv = ["ssh", "-T", *host.ssh_options]
    if host.ssh_port is not None:
        argv += ["-p", str(host.ssh_port)]
    if host.identity is not None:
        argv += ["-i", host.identity]
    if host.user is not None:
        argv += ["-l", host.user]
    command = list(remote)
    if env:
        command = ["env", *(f"{k}={v}" for k, v in sorted(env.items())), *command]
    return [*argv, *SSH_DEFAULTS, host.ssh_host or host.address, "--", "exec " + shlex.join(command)]


def share_command(host: Host, settings: ShareSettings) -> list[str]:
    """The ``tokenring up --share`` a host runs: its router, its nodes, the hub to connect to."""
    cmd = [*host.tokenring, "--log-level", settings.log_level, "up", "--share", str(settings.total)]
    cmd += ["--nodes", ",".join(host.nodes), "--ring", settings.ring, "--bitrate", settings.bitrate]
    cmd += ["--ack", settings.ack, "--router", "--listen", host.endpoint(settings.scheme)]
    cmd += ["--connect", settings.hub, "--lost-after", f"{host.lost_after:g}"]
    if settings.respawn:
        cmd.append("--respawn")
    if settings.profile:
        cmd += ["--profile", settings.profile]
    if settings.protocol:
        cmd += ["--protocol", settings.protocol]
    zenoh_config = host.zenoh_config or settings.zenoh_config
    if zenoh_config:
        cmd += ["--zenoh-config", zenoh_config]
    if host.store:
        cmd += ["--store", host.store]
    if settings.no_programs:
        cmd.append("--no-programs")
    elif settings.no_download:
        cmd.append("--no-download")
        if settings.programs:
            cmd += ["--programs", settings.programs]
    return cmd


def check_reachable(inventory: Inventory, timeout: float = 30.0) -> None:
    """Ask every remote host, at once, for its ``tokenring --version`` over SSH: an unreachable
    host or a missing tokenring is refused (exit 2, naming the inventory's line) before anything
    starts."""

    def ask(host: Host) -> str | None:
        argv = ssh_command(host, [*host.tokenring, "--version"])
        try:
            done = subprocess.run(
                argv, stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=timeout
            )
        except subprocess.TimeoutExpired:
            return f"no answer over ssh within {timeout:.0f} s"
        except OSError as exc:
            return f"cannot run ssh: {exc.strerror or exc}"
        last = (done.stderr.strip() or done.stdout.strip()).splitlines()[-1:] or [""]
        if done.returncode == SSH_FAILED:
            return f"unreachable over ssh: {last[0] or 'ssh exited with code 255'}"
        if done.returncode == NOT_FOUND:
            return f"{shlex.join(host.tokenring)} is not a command there (give its path as 'tokenring:')"
        if done.returncode != 0:
            return f"{shlex.join(host.tokenring)} --version failed there ({describe_exit(done.returncode)}): {last[0]}"
        return None

    remote = inventory.remote
    if not remote:
        return
    with ThreadPoolExecutor(max_workers=min(16, len(remote))) as pool:
        problems = list(pool.map(ask, remote))
    for host, problem in zip(remote, problems, strict=True):
        if problem:
            raise UsageError(f"{inventory.where(host)}: host {host.name} ({host.address}): {problem}")


@dataclass
class Share:
    """One host's share: its ssh process and what it said last."""

    host: Host
    process: subprocess.Popen
    started: float
    restarts: int = 0
    reported: bool = False
    group_ended: bool = False
    last: deque[str] = field(default_factory=lambda: deque(maxlen=5))
    said: str = ""  # the last line ssh or the share's shell said itself (not a module's)
    connected: bool = False  # its launcher spoke: ssh reached the host and tokenring runs there
    stopped: bool = False  # its launcher said its last line, "stopped (...)"
    reasons: str = ""  # why the share's run was not whole, as its last line says

    def relay(self, say: Callable[[str, str], None]) -> Callable[[str], None]:
        """Its output lines under ``host/module`` (the share's launcher prefixed them with the
        module), kept for a failure's message."""

        def line(text: str) -> None:
            self.last.append(text)
            match = _PREFIXED.match(text)
            if match:
                self.connected = True
                module, said = match.group(1), match.group(2)
                stopped = _STOPPED.match(said) if module == "up" else None
                if stopped:
                    self.stopped, self.reasons = True, stopped.group(1) or ""
                say(said, f"{self.host.name}/{module}")
            else:
                self.said = text
                say(text, self.host.name)

        return line

    def beat(self) -> None:
        """Tell the share the launcher is there: a line on its input, never blocking (a share
        whose ssh reads nothing just misses it)."""
        stdin = self.process.stdin
        if stdin is None or stdin.closed or self.process.poll() is not None:
            return
        with contextlib.suppress(OSError, ValueError):
            os.write(stdin.fileno(), b"\n")


class HostShares:
    """Starts, watches, reconnects and stops the other hosts' shares, through the launcher's own
    plumbing (its output, its exit watch, its process groups, its failures)."""

    def __init__(self, launcher: Launcher, inventory: Inventory, settings: ShareSettings) -> None:
        self.launcher = launcher
        self.inventory = inventory
        self.settings = settings
        self.shares: dict[str, Share] = {}
        self._due: dict[str, float] = {}  # host -> when it is connected again
        self._backoff: dict[str, float] = {}
        self.booted = False  # every host came up once: from now on a lost one is reconnected
        self._lost: set[str] = set()  # hosts lost once: a refusal of their new share is tried again
        self._next_beat = 0.0
        self._lock = threading.RLock()

    def labels(self) -> list[str]:
        """The prefixes of the shares' lines (for the output's width)."""
        return [f"{h.name}/{n}" for h in self.inventory.remote for n in [*h.nodes, "up"]]

    def start(self) -> None:
        for host in self.inventory.remote:
            self._start(host)

    def _start(self, host: Host) -> Share:
        argv = ssh_command(host, share_command(host, self.settings), self.settings.env)
        previous = self.shares.get(host.name)
        process = self.launcher.popen_child(argv, host.name, stdin=subprocess.PIPE, watch=False)
        assert process.stdin is not None
        os.set_blocking(process.stdin.fileno(), False)  # a heartbeat never holds up the supervisor
        share = Share(host, process, time.monotonic(), restarts=previous.restarts + 1 if previous else 0)
        assert process.stdout is not None
        self.launcher.output.watch(process.stdout, host.name, share.relay(self.launcher.say))
        with self._lock:
            self.shares[host.name] = share
        self.launcher.watch_exit(process.pid, share)
        return share

    def due(self) -> list[float]:
        return [*self._due.values(), self._next_beat]

    def check(self, stopping: bool) -> None:
        """Tell every share the launcher is there; report shares that ended; reconnect a lost
        host (ssh 255, or its share stopped for want of the launcher) and, with ``--respawn``, any."""
        launcher = self.launcher
        with self._lock:  # begin_stop() closes the inputs under it: no beat to a closed (reused) fd
            shares = list(self.shares.values())
            if not stopping and time.monotonic() >= self._next_beat:
                self._next_beat = time.monotonic() + HEARTBEAT_S
                for share in shares:
                    share.beat()
        for share in shares:
            code = share.process.poll()
            if code is None or share.reported or stopping:
                continue
            share.reported = True
            launcher.end_group(share)
            if not self.booted:
                continue  # wait_up() says it, with the inventory's line: the run stops
            host = share.host
            lost = code in (SSH_FAILED, SHARE_LOST)
            # back after a loss, a host's new share is refused while its old one still holds the
            # ring there; that one stops within lost_after of its last word from the launcher
            refused = code == REFUSED and host.name in self._lost
            if lost or refused or launcher.respawn:
                new_loss = share.connected and not refused  # not another attempt that failed
                if lost:
                    self._lost.add(host.name)
                if new_loss:  # back to 1 s
                    self._backoff.pop(host.name, None)
                delay = self._backoff.get(host.name, RECONNECT_S)
                self._backoff[host.name] = min(RECONNECT_MAX_S, delay * 2)
                self._due[host.name] = time.monotonic() + delay
                line = self._said(share, code)
                if new_loss:  # counted once per loss, however many attempts it takes
                    launcher.failure(
                        f"{line}: its nodes are out of the ring; connecting again in {delay:.0f} s"
                    )
                else:
                    launcher.say(f"{line}: connecting again in {delay:.0f} s")
            else:
                launcher.failure(f"{self._said(share, code)}: the ring goes on without it")
        now = time.monotonic()
        for name, due in list(self._due.items()):
            if now >= due and not stopping:
                del self._due[name]
                host = next(h for h in self.inventory.remote if h.name == name)
                launcher.say(f"connecting to host {name} ({host.address}) again")
                try:
                    self._start(host)
                except OSError as exc:
                    launcher.failure(f"host {name}: cannot run ssh: {exc}")

    def _why(self, share: Share, code: int) -> str:
        """Why a share ended, in a few words: its ssh's, its own last line's, or its exit code."""
        if code == SSH_FAILED:
            return f"lost (ssh exited with code 255{': ' + share.said if share.said else ''})"
        if code == SHARE_LOST:
            return f"lost (its share heard nothing from the launcher for {share.host.lost_after:g} s and stopped)"
        if share.reasons:
            return f"{share.reasons} (its share {describe_exit(code)})"
        last = share.said or ("" if share.stopped or not share.last else share.last[-1].strip())
        return f"share {describe_exit(code)}" + (f" ({last})" if last else "")

    def _said(self, share: Share, code: int) -> str:
        """One line naming the host and why its share ended."""
        return f"host {share.host.name} ({share.host.address}): {self._why(share, code)}"

    def wait_up(self, wanted: set[int], timeout: float) -> bool:
        """Wait until every node of the inventory is live on the ring. A share that ends first
        is refused (:class:`UsageError` naming the inventory's line: the run stops, exit 2);
        False if the time ran out (the run goes on; its nodes may still come)."""
        launcher = self.launcher
        assert launcher.session is not None
        deadline = time.monotonic() + timeout
        try:
            while time.monotonic() < deadline and not launcher.stopping:
                for share in list(self.shares.values()):
                    code = share.process.poll()
                    if code is not None:
                        launcher.flush_output()
                        raise UsageError(
                            f"{self.inventory.where(share.host)}: host {share.host.name} "
                            f"({share.host.address}): {self._why(share, code)}"
                        )
                live: set[int] = set()
                with contextlib.suppress(zenoh.ZError):
                    for reply in launcher.session.liveliness().get(
                        keys.node(launcher.ring, "*"), timeout=1.0
                    ):
                        if reply.ok is not None:
                            node_id = keys.id_from_key(str(reply.ok.key_expr))
                            if node_id is not None:
                                live.add(node_id)
                if wanted <= live:
                    return True
                time.sleep(0.2)
            return False
        finally:
            self.booted = True

    def begin_stop(self) -> None:
        """Close every share's input: each stops its nodes and exits."""
        self._due.clear()
        with self._lock:
            for share in self.shares.values():
                if share.process.stdin is not None:
                    with contextlib.suppress(OSError):
                        share.process.stdin.close()

    def stop(self) -> None:
        """Wait for the shares to exit (SHARE_STOP_S), then end their ssh; a share that did not
        stop cleanly counts."""
        self.begin_stop()
        launcher = self.launcher
        deadline = time.monotonic() + SHARE_STOP_S
        with self._lock:
            shares = list(self.shares.values())
        for share in shares:
            process = share.process
            code: int | None
            try:
                code = process.wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                launcher.failure(
                    f"host {share.host.name} ({share.host.address}) did not stop within {SHARE_STOP_S:.0f} s: "
                    f"ending its ssh (its share stops by itself {share.host.lost_after:g} s after the "
                    "launcher's last word reached it)"
                )
                with contextlib.suppress(ProcessLookupError):
                    process.send_signal(signal.SIGTERM)
                try:
                    code = process.wait(1.0)
                except subprocess.TimeoutExpired:
                    process.kill()
                    with contextlib.suppress(subprocess.TimeoutExpired):
                        process.wait(KILL_REAP_S)
                    code = process.poll()
                share.reported = True  # said: the exit code of an ssh we ended tells nothing more
            if not share.reported and code not in (0, None, -signal.SIGTERM):
                launcher.failure(self._said(share, code))
            share.reported = True
            if process.poll() is not None:
                launcher.end_group(share)

    def status(self) -> list[dict[str, Any]]:
        """The launcher's status of its hosts: each share's ssh and the nodes it runs."""
        with self._lock:
            shares = list(self.shares.values())
        return [
            {
                "host": s.host.name,
                "address": s.host.address,
                "nodes": list(s.host.nodes),
                "ssh_pid": s.process.pid,
                "running": s.process.poll() is None,
                "restarts": s.restarts,
            }
            for s in shares
        ]
