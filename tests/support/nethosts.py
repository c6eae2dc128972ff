"""Two network namespaces on one veth cable: two hosts for tests that cross a network."""

from __future__ import annotations

import os
import random
import shutil
import subprocess
import uuid

import pytest

#: for test modules that need them: namespaces need root and iproute2 (both here and in CI)
needs_namespaces = pytest.mark.skipif(
    os.geteuid() != 0 or shutil.which("ip") is None, reason="network namespaces need root and iproute2"
)


def sh(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run(list(args), capture_output=True, text=True, timeout=30, check=check)


class Hosts:
    """Two namespaces joined by a veth pair, torn down completely afterwards."""

    def __init__(self) -> None:
        tag = uuid.uuid4().hex[:6]
        self.a, self.b = f"tra{tag}", f"trb{tag}"
        self.va, self.vb = f"va{tag}", f"vb{tag}"
        net = random.randrange(1, 250)
        self.ip_a, self.ip_b = f"10.211.{net}.1", f"10.211.{net}.2"
        sh("ip", "netns", "add", self.a)
        sh("ip", "netns", "add", self.b)
        sh("ip", "link", "add", self.va, "type", "veth", "peer", "name", self.vb)
        sh("ip", "link", "set", self.va, "netns", self.a)
        sh("ip", "link", "set", self.vb, "netns", self.b)
        for ns, dev, ip in ((self.a, self.va, self.ip_a), (self.b, self.vb, self.ip_b)):
            sh("ip", "netns", "exec", ns, "ip", "addr", "add", f"{ip}/24", "dev", dev)
            sh("ip", "netns", "exec", ns, "ip", "link", "set", dev, "up")
            sh("ip", "netns", "exec", ns, "ip", "link", "set", "lo", "up")
        self.iptables = shutil.which("iptables") is not None

    def run(self, ns: str, *args: str) -> list[str]:
        return ["ip", "netns", "exec", ns, *args]

    def cut(self) -> None:
        if self.iptables:  # silent: packets on the cable vanish, nobody gets an error
            for ns, dev in ((self.a, self.va), (self.b, self.vb)):
                sh("ip", "netns", "exec", ns, "iptables", "-I", "INPUT", "-i", dev, "-j", "DROP")
                sh("ip", "netns", "exec", ns, "iptables", "-I", "OUTPUT", "-o", dev, "-j", "DROP")
        else:
            sh("ip", "netns", "exec", self.a, "ip", "link", "set", self.va, "down")

    def mend(self) -> None:
        if self.iptables:
            for ns in (self.a, self.b):
                sh("ip", "netns", "exec", ns, "iptables", "-F")
        else:
            sh("ip", "netns", "exec", self.a, "ip", "link", "set", self.va, "up")

    def close(self) -> None:
        sh("ip", "netns", "del", self.a, check=False)
        sh("ip", "netns", "del", self.b, check=False)
