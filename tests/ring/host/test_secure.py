"""A secured deployment: ``tokenring secure init`` and a ring that only its operator controls.

The ring runs on host A (a network namespace) with the node role's config; host B tries every
role: the operator may download, inject faults and stop programs; an observer may read stats
and frames but not download, inject, stop nor put a frame on the ring; a peer without a
certificate of the deployment's authority (plain TCP, or TLS with another authority's
certificate) gets nothing at all.
"""

from __future__ import annotations

import json
import random
import signal
import stat
import subprocess
import sys
import uuid
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pytest
from cryptography import x509
from cryptography.x509.oid import NameOID

from tests.support.nethosts import Hosts, needs_namespaces
from tests.support.processes import REPO, run_tokenring, wait_gone
from tests.support.ringutil import wait_until

PROGRAM = """
from tokenring import UserProgram


class Program(UserProgram):
    module = "motor"
"""

FORGE = """
import sys, time
from tokenring.transport.zenoh_config import make_config, open_session
session = open_session(make_config(connect=[sys.argv[1]], config_file=sys.argv[2]))
publisher = session.declare_publisher(f"tokenring/{sys.argv[3]}/token/20")
deadline = time.monotonic() + 60
while not publisher.matching_status.matching:  # motor's subscriber is known: linked to it
    if time.monotonic() > deadline:
        sys.exit("never linked to motor")
    time.sleep(0.05)
for _ in range(5):
    publisher.put(b"forged")  # 6 bytes: a length reject
    time.sleep(0.1)
session.close()
"""


def common_name(config: Path) -> str:
    """The CN of the certificate inlined in a role's config, read with the X.509 parser."""
    import base64

    tls = json.loads(config.read_text())["transport"]["link"]["tls"]
    cert = x509.load_pem_x509_certificate(base64.b64decode(tls["connect_certificate_base64"]))
    return cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value


@pytest.mark.slow
def test_init_writes_one_private_config_per_role_and_refuses_to_overwrite(tmp_path):
    keys = tmp_path / "keys"
    done = run_tokenring("secure", "init", str(keys), "--host", "10.1.2.3", "--json")
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    assert report["hosts"] == ["10.1.2.3"]
    for role in ("node", "operator", "observer"):
        config = keys / f"{role}.json5"
        assert stat.S_IMODE(config.stat().st_mode) == 0o600  # it holds the role's private key
        assert common_name(config) == f"tokenring-{role}"
        assert json.loads(config.read_text())["transport"]["link"]["protocols"] == ["tls"]
    assert stat.S_IMODE((keys / "ca-key.pem").stat().st_mode) == 0o600
    node = json.loads((keys / "node.json5").read_text())
    assert node["access_control"]["default_permission"] == "deny"
    before = {p.name: p.read_bytes() for p in keys.iterdir()}
    again = run_tokenring("secure", "init", str(keys))
    assert again.returncode == 2 and "exists" in again.stderr and "--force" in again.stderr
    assert len(again.stderr.strip().splitlines()) == 1 and "Traceback" not in again.stderr
    assert {p.name: p.read_bytes() for p in keys.iterdir()} == before  # nothing overwritten
    forced = run_tokenring("secure", "init", str(keys), "--force")
    assert forced.returncode == 0 and (keys / "ca.pem").read_bytes() != before["ca.pem"]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--host", "not a host!"], "neither an IP address nor a host name"),
        (["--days", "0"], "--days"),
        (["--days", "99999"], "within 1..3650"),
    ],
)
def test_init_refuses_bad_arguments_in_one_line(tmp_path, args, message):
    done = run_tokenring("secure", "init", str(tmp_path / "keys"), *args)
    assert done.returncode == 2 and message in done.stderr and "Traceback" not in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "keys" / "node.json5").exists()


def test_init_refuses_a_file_where_the_directory_should_be(tmp_path):
    target = tmp_path / "keys"
    target.write_text("not a directory")
    done = run_tokenring("secure", "init", str(target))
    assert done.returncode == 2 and "not a directory" in done.stderr
    assert target.read_text() == "not a directory"


def together(**calls: Callable[[], Any]) -> dict[str, Any]:
    """Each call's result by name, the calls made side by side (each in its own thread)."""
    with ThreadPoolExecutor(max_workers=len(calls)) as pool:
        futures = {name: pool.submit(call) for name, call in calls.items()}
        return {name: future.result() for name, future in futures.items()}


class Host:
    """Runs ``tokenring`` (or Python) on one namespace of :class:`Hosts`."""

    def __init__(self, hosts: Hosts, ns: str, ring: str, endpoint: str) -> None:
        self.hosts, self.ns, self.ring, self.endpoint = hosts, ns, ring, endpoint

    def tokenring(
        self, *args: str, config: Path | None = None, timeout: float = 90
    ) -> subprocess.CompletedProcess:
        cmd = [sys.executable, "-m", "tokenring", *args, "--ring", self.ring, "-e", self.endpoint]
        if config is not None:
            cmd += ["--zenoh-config", str(config)]
        return subprocess.run(
            self.hosts.run(self.ns, *cmd), capture_output=True, text=True, timeout=timeout, cwd=REPO
        )

    def nodes(self, config: Path | None) -> dict[int, dict]:
        done = self.tokenring("status", "--json", "--timeout", "1.5", config=config)
        if done.returncode != 0 or not done.stdout.strip():
            return {}
        return {n["id"]: n for n in json.loads(done.stdout)["nodes"]}

    def faults(self, config: Path, node: int) -> dict | None:
        done = self.tokenring("fault", "--list", "--json", "--timeout", "2", config=config)
        if done.returncode != 0:
            return None
        found = [n for n in json.loads(done.stdout)["nodes"] if n["id"] == node]
        return found[0]["faults"] if found else None


@pytest.mark.slow
@needs_namespaces
@pytest.mark.timeout(400)
def test_only_the_operator_downloads_injects_and_stops_observers_only_read(procs, tmp_path):
    hosts = Hosts()
    ring = f"s{uuid.uuid4().hex[:8]}"
    endpoint = f"tls/{hosts.ip_a}:{random.randrange(20000, 40000)}"
    keys, foreign = tmp_path / "keys", tmp_path / "foreign"
    for directory in (keys, foreign):  # another deployment: a valid certificate, a stranger's CA
        assert run_tokenring("secure", "init", str(directory), "--host", hosts.ip_a).returncode == 0
    operator, observer, stranger = (
        keys / "operator.json5",
        keys / "observer.json5",
        foreign / "operator.json5",
    )
    program = tmp_path / "motor.py"
    program.write_text(PROGRAM)
    launcher = None
    try:
        with (tmp_path / "ring.log").open("w") as log:  # a file: an unread pipe would stall the launcher
            launcher = procs.start(
                hosts.run(
                    hosts.a, sys.executable, "-m", "tokenring", "up", "--ring", ring, "--listen", endpoint,
                    "--zenoh-config", str(keys / "node.json5"), "--nodes", "main,motor,sonar", "--bitrate", "10M",
                ),
                stdout=log,
                env={"TOKENRING_EXTENSIONS": ""},
            )  # fmt: skip
        b = Host(hosts, hosts.b, ring, endpoint)
        wait_until(lambda: set(b.nodes(operator)) == {10, 20, 30}, 90, "the operator to see the ring")

        # the observer reads stats and frames
        assert set(b.nodes(observer)) == {10, 20, 30}
        sniffed = b.tokenring("sniff", "-n", "5", "--header-only", "--json", config=observer)
        assert sniffed.returncode == 0, sniffed.stderr
        assert len(sniffed.stdout.splitlines()) == 5

        # ... and nothing else: no download, no fault, no frame onto the ring (no stop: below);
        # strangers get nothing at all: not even the frames. Each attempt is its own process
        # and each refusal mostly waits out a timeout, so they are made side by side; what they
        # leave on the ring is judged once all have ended
        plain = Host(hosts, hosts.b, ring, endpoint.replace("tls/", "tcp/"))  # plain TCP, TLS-only ring
        forge = [sys.executable, "-c", FORGE, endpoint, str(observer), ring]
        attempts = together(
            observer_load=lambda: b.tokenring("load", "--no-progress", "-s", str(program), config=observer),
            observer_fault=lambda: b.tokenring("fault", "motor", "delay", "5", "--timeout", "3", config=observer),
            observer_forge=lambda: subprocess.run(hosts.run(hosts.b, *forge), timeout=90, cwd=REPO),
            plain_nodes=lambda: plain.nodes(None),
            plain_sniff=lambda: plain.tokenring("sniff", "-n", "1", "--wait", "3"),
            stranger_nodes=lambda: b.nodes(stranger),
            stranger_sniff=lambda: b.tokenring("sniff", "-n", "1", "--wait", "3", config=stranger),
            stranger_load=lambda: b.tokenring("load", "--no-progress", "-s", str(program), config=stranger),
            stranger_fault=lambda: b.tokenring("fault", "motor", "delay", "5", "--timeout", "3", config=stranger),
        )  # fmt: skip
        assert attempts["observer_load"].returncode != 0
        refused = attempts["observer_fault"]
        assert refused.returncode == 2 and "certificate lack the right" in refused.stderr
        assert attempts["observer_forge"].returncode == 0
        assert attempts["plain_nodes"] == {}
        assert attempts["plain_sniff"].returncode != 0
        assert attempts["stranger_nodes"] == {}
        for name in ("stranger_sniff", "stranger_load", "stranger_fault"):
            assert attempts[name].returncode != 0, name
        seen = b.nodes(operator)
        assert seen[20]["program"] is None and b.faults(operator, 20) == {}
        assert seen[20]["stats"]["rejected_length"] == 0  # the forged frames never arrived

        # the operator may do all of it
        loaded = b.tokenring("load", "--no-progress", "-s", str(program), config=operator)
        assert loaded.returncode == 0, loaded.stdout + loaded.stderr
        assert b.tokenring("fault", "motor", "delay", "5", config=operator).returncode == 0
        forge = [sys.executable, "-c", FORGE, endpoint, str(operator), ring]
        assert subprocess.run(hosts.run(hosts.b, *forge), timeout=90, cwd=REPO).returncode == 0
        assert "delay" in (b.faults(operator, 20) or {})
        assert b.tokenring("load", "--start", "motor", config=operator).returncode == 0
        seen = wait_until(
            lambda: (n := b.nodes(operator)) and n.get(20, {}).get("program") == "Program" and n,
            60,
            "motor running the operator's program",
        )
        assert seen[20]["stats"]["rejected_length"] >= 1  # the operator's forged frames arrived
        # an observer cannot stop it, nor a stranger
        stops = together(**{
            name: (lambda config=config: b.tokenring("load", "--stop", "motor", config=config))
            for name, config in (("observer", observer), ("stranger", stranger))
        })  # fmt: skip
        assert all(done.returncode != 0 for done in stops.values()), stops
        assert b.nodes(operator)[20]["program"] == "Program"
        assert b.tokenring("fault", "motor", "clear", config=operator).returncode == 0
        assert b.tokenring("load", "--stop", "motor", config=operator).returncode == 0
        wait_until(lambda: b.nodes(operator).get(20, {}).get("program", 1) is None, 60, "motor stopped")
    finally:
        if launcher is not None:
            launcher.send_signal(signal.SIGTERM)
            try:
                launcher.wait(30)
            except subprocess.TimeoutExpired:
                launcher.kill()
            assert wait_gone([launcher.pid], 30) == []
        hosts.close()
