"""Hosts made of network namespaces on one bridge, each with an sshd of the test's own.

A fourth namespace holds the bridge (the switch), so that nothing is added to the machine's own
network. Each host's sshd runs with a config, host key and authorized key the test made in its
tmp_path, inside a mount namespace of its own where a tmpfs on /run gives it its privilege
separation directory (``/run/sshd``) without touching the machine's. Everything is ended by PID,
and the namespaces deleted, in :meth:`SshHosts.close`, also after a failure.
"""

from __future__ import annotations

import contextlib
import os
import random
import shutil
import signal
import subprocess
import time
import uuid
from dataclasses import dataclass
from pathlib import Path

import pytest

SSHD = "/usr/sbin/sshd"

#: for tests that need them: namespaces need root, iproute2 and iptables; the hosts Debian's openssh-server
needs_ssh_hosts = pytest.mark.skipif(
    os.geteuid() != 0 or shutil.which("ip") is None, reason="network namespaces need root and iproute2"
)


def sh(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run(list(args), capture_output=True, text=True, timeout=30, check=check)


def netns_pids(ns: str) -> set[int]:
    """Every process whose network namespace is ``ns`` (``ip netns pids``: by namespace inode)."""
    done = sh("ip", "netns", "pids", ns, check=False)
    return {int(p) for p in done.stdout.split() if p.isdigit()}


@dataclass
class SshHost:
    name: str  # the namespace
    address: str
    dev: str  # its end of the cable
    sshd: subprocess.Popen | None = None


class SshHosts:
    """``count`` hosts on a bridge, each reachable over ssh as root with the test's key."""

    def __init__(self, directory: Path, count: int = 3, client_alive: bool = True) -> None:
        if not Path(SSHD).exists():
            raise RuntimeError(f"{SSHD} is missing: install Debian's openssh-server (.ci/run does)")
        tag = uuid.uuid4().hex[:6]
        directory.mkdir(parents=True, exist_ok=True)
        self.directory = directory
        self.switch = f"trsw{tag}"
        net = random.randrange(1, 250)
        self.hosts = [SshHost(f"trh{i}{tag}", f"10.213.{net}.{i + 1}", f"th{i}{tag}") for i in range(count)]
        self.cuts: list[list[str]] = []  # iptables rules in force, to take back
        #: sshd finds a silent client gone within 6 s; else Debian's default: never (TCP's keepalive)
        self.client_alive = client_alive
        self._namespaces: list[str] = []
        try:
            self._network()
            self._keys()
            for host in self.hosts:
                self._sshd(host)
            self._wait_listening()
        except BaseException:
            self.close()
            raise

    # -- the network ---------------------------------------------------------------------------
    def _add_ns(self, name: str) -> None:
        sh("ip", "netns", "add", name)
        self._namespaces.append(name)
        sh("ip", "netns", "exec", name, "ip", "link", "set", "lo", "up")

    def _network(self) -> None:
        self._add_ns(self.switch)
        sh("ip", "netns", "exec", self.switch, "ip", "link", "add", "br0", "type", "bridge")
        sh("ip", "netns", "exec", self.switch, "ip", "link", "set", "br0", "up")
        for index, host in enumerate(self.hosts):
            self._add_ns(host.name)
            port = f"tp{index}{host.name[-6:]}"
            sh("ip", "link", "add", host.dev, "netns", host.name, "type", "veth", "peer", "name", port,
               "netns", self.switch)  # fmt: skip
            sh("ip", "netns", "exec", self.switch, "ip", "link", "set", port, "master", "br0")
            sh("ip", "netns", "exec", self.switch, "ip", "link", "set", port, "up")
            sh("ip", "netns", "exec", host.name, "ip", "addr", "add", f"{host.address}/24", "dev", host.dev)
            sh("ip", "netns", "exec", host.name, "ip", "link", "set", host.dev, "up")

    def run(self, host: SshHost, *args: str) -> list[str]:
        """A command line running ``args`` on ``host``."""
        return ["ip", "netns", "exec", host.name, *args]

    # -- ssh -----------------------------------------------------------------------------------
    def _keys(self) -> None:
        d = self.directory
        sh("ssh-keygen", "-q", "-t", "ed25519", "-N", "", "-C", "tokenring-test", "-f", str(d / "id_test"))
        sh("ssh-keygen", "-q", "-t", "ed25519", "-N", "", "-f", str(d / "host_key"))
        (d / "authorized_keys").write_text((d / "id_test.pub").read_text())
        self.identity = d / "id_test"
        self.known_hosts = d / "known_hosts"
        # the test's own client settings: no user config, no agent, its key only
        self.ssh_options = [
            "-F", "/dev/null",
            "-o", f"UserKnownHostsFile={self.known_hosts}",
            "-o", "StrictHostKeyChecking=accept-new",
            "-o", "IdentitiesOnly=yes",
            "-o", "IdentityAgent=none",
            "-o", "LogLevel=ERROR",
        ]  # fmt: skip

    def _sshd(self, host: SshHost) -> None:
        d = self.directory
        config = d / f"sshd_config.{host.name}"
        config.write_text(
            "\n".join(
                [
                    f"ListenAddress {host.address}",
                    "Port 22",
                    f"HostKey {d / 'host_key'}",
                    f"AuthorizedKeysFile {d / 'authorized_keys'}",
                    "PidFile none",
                    "StrictModes no",  # the keys live under /tmp, world-writable above them
                    "UsePAM no",
                    "PermitRootLogin prohibit-password",
                    "PasswordAuthentication no",
                    "KbdInteractiveAuthentication no",
                    "PubkeyAuthentication yes",
                    # a client gone silently is found within 6 s: its session's command gets EOF
                    *(["ClientAliveInterval 2", "ClientAliveCountMax 3"] if self.client_alive else []),
                    "MaxStartups 50",
                    "LogLevel ERROR",
                    "",
                ]
            )
        )
        log = (d / f"sshd.{host.name}.log").open("w")
        # a mount namespace of its own (ip netns exec makes one): a tmpfs on /run gives sshd
        # its /run/sshd there and nowhere else
        script = f"mount -t tmpfs -o mode=0755,size=1m trsshd /run && mkdir -m 0755 /run/sshd && exec {SSHD} -D -e -f {config}"
        host.sshd = subprocess.Popen(
            self.run(host, "sh", "-c", script), stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT
        )
        log.close()

    def _wait_listening(self, timeout: float = 30.0) -> None:
        deadline = time.monotonic() + timeout
        for host in self.hosts:
            while True:
                assert host.sshd is not None
                if host.sshd.poll() is not None:
                    log = (self.directory / f"sshd.{host.name}.log").read_text()
                    raise RuntimeError(f"sshd on {host.name} exited ({host.sshd.returncode}): {log}")
                listening = sh("ip", "netns", "exec", host.name, "ss", "-Htln", "sport", "= :22", check=False)
                if host.address in listening.stdout:
                    break
                if time.monotonic() > deadline:
                    raise RuntimeError(f"sshd on {host.name} is not listening after {timeout:.0f} s")
                time.sleep(0.05)

    def sshd_pids(self) -> set[int]:
        return {h.sshd.pid for h in self.hosts if h.sshd is not None}

    def besides_sshd(self, host: SshHost) -> set[int]:
        """The processes in ``host``'s namespace that are not sshd's (its listener and sessions)."""
        found = set()
        for pid in netns_pids(host.name):
            with contextlib.suppress(OSError):
                if not Path(f"/proc/{pid}/comm").read_text().startswith("sshd"):  # sshd-session too
                    found.add(pid)
        return found

    def leftovers(self) -> dict[str, set[int]]:
        """The processes in each host's namespace besides its sshd listener."""
        found = {h.name: netns_pids(h.name) - self.sshd_pids() for h in self.hosts}
        return {ns: pids for ns, pids in found.items() if pids}

    # -- cutting the cable -----------------------------------------------------------------------
    def cut(self, host: SshHost, ssh_only: bool = False) -> None:
        """Drop everything on ``host``'s cable, silently: nobody gets an error. ``ssh_only``:
        only its sshd's traffic (the ring's goes on)."""
        for chain, flag, port in (("INPUT", "-i", "--dport"), ("OUTPUT", "-o", "--sport")):
            only = ["-p", "tcp", port, "22"] if ssh_only else []
            rule = [chain, flag, host.dev, *only, "-j", "DROP"]
            sh("ip", "netns", "exec", host.name, "iptables", "-I", *rule)
            self.cuts.append([host.name, *rule])

    def mend(self) -> None:
        for ns, *rule in self.cuts:
            sh("ip", "netns", "exec", ns, "iptables", "-D", *rule, check=False)
        self.cuts.clear()

    # -- the end -------------------------------------------------------------------------------
    def close(self) -> None:
        """Take back the cuts, end every process left in the namespaces (by PID), delete them."""
        self.mend()
        for host in self.hosts:
            if host.sshd is not None and host.sshd.poll() is None:
                host.sshd.terminate()
        for host in self.hosts:
            if host.sshd is not None:
                with contextlib.suppress(subprocess.TimeoutExpired):
                    host.sshd.wait(5)
        for _ in range(3):  # what is left (a failed test's ring) is killed by PID
            pids = set().union(*(netns_pids(ns) for ns in self._namespaces)) if self._namespaces else set()
            if not pids:
                break
            for pid in pids:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGKILL)
            time.sleep(0.2)
        for host in self.hosts:
            if host.sshd is not None and host.sshd.poll() is None:
                host.sshd.kill()
                host.sshd.wait(5)
        for ns in reversed(self._namespaces):
            sh("ip", "netns", "del", ns, check=False)
        self._namespaces.clear()
