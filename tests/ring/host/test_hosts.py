"""``tokenring up --hosts FILE``: one ring across hosts from one command, over ssh.

The slow tests run hosts made of network namespaces on a bridge, each with an sshd of its own
(tests/support/sshhosts.py). Three hosts: one ``up --hosts`` on host a forms the ring, the
programs are downloaded over it, ``status``, ``monitor``, the web view and the metrics on host a
see every node, ``record --pcap`` captures frames of every node, a ``chaos`` scenario learns the
ring's nodes and hangs one on host c, faults reach nodes on host b (a hang resumed by b's
launcher, a crash respawned by it), host c's cable is cut silently (its ssh session dies, and
with it its share) while a and b re-form, and c's nodes rejoin once the cable is back; Ctrl-C
then leaves no process in any namespace. Two hosts: a remote node's death is the run's exit
code 1, named with its host; a host whose sshd never notices a silent client has its share stop
by itself, during a long cut and during Ctrl-C; a host back while its old share still runs is
tried again until that one has stopped. The quick tests refuse bad input (one line naming
the inventory's file and line, exit code 2) and run a share's heartbeat without ssh.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path

import pytest

from tests.support.processes import REPO, pid_alive, run_tokenring
from tests.support.ringutil import wait_until, write_probe_programs
from tests.support.sshhosts import SshHost, SshHosts, needs_ssh_hosts
from tokenring.host.remote import HEARTBEAT_S

#: how long before a cut the share's last heartbeat may have come: one interval, and the launcher's
#: supervising thread may send it late on a loaded machine
LAST_BEAT_S = HEARTBEAT_S + 3.0

TOKENRING = str(Path(sys.executable).with_name("tokenring"))


def inventory(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("text", "where", "what"),
    [
        ("hosts:\n  a: {address: 127.0.0.1, ssh: local, nodes: [main]\n", ":3:", "YAML syntax error"),
        (
            "hosts:\n  a: {address: 127.0.0.1, ssh: local, nodes: [main]}\n"
            "  b: {address: 10.9.9.9, nodes: [motor, wheel]}\n",
            ":3:",
            "unknown node 'wheel'",
        ),
        (
            "hosts:\n  a: {address: 127.0.0.1, ssh: local, nodes: [main]}\n"
            "  b: {address: 10.9.9.9, nodes: [motor, main]}\n",
            ":3:",
            "node main is on host a already",
        ),
        (
            "hosts:\n  a: {address: 127.0.0.1, ssh: local, nodes: [main]}\n  b:\n    adress: 10.9.9.9\n",
            ":4:",
            "hosts.b.adress: unknown key",
        ),
        ("hosts:\n  a: {address: 10.9.9.8, nodes: [main]}\n", ":2:", "exactly one host must be 'ssh: local'"),
        (
            # nothing listens on port 1: ssh is refused at once
            "hosts:\n  a: {address: 127.0.0.1, ssh: local, nodes: [main]}\n"
            "  b:\n    address: 127.0.0.1\n    port: 7450\n    ssh: {port: 1}\n    nodes: [motor]\n",
            ":4:",  # within host b
            "host b (127.0.0.1): unreachable over ssh",
        ),
        (
            "lost_after: 30\nhosts:\n  a: {address: 127.0.0.1, ssh: local, nodes: [main]}\n"
            "  b: {address: 10.9.9.9, nodes: [motor], lost_after: 1}\n",
            ":4:",
            "hosts.b.lost_after: 1 is not a number of seconds 5..86400",
        ),
    ],
    ids=["syntax", "unknown-module", "twice", "unknown-key", "no-local", "unreachable", "lost-after"],
)
def test_a_bad_inventory_is_one_line_naming_file_and_line(tmp_path, text, where, what):
    path = inventory(tmp_path / "ring.yaml", text)
    done = run_tokenring("up", "--hosts", str(path), "--ring", f"h{uuid.uuid4().hex[:8]}", "--no-world")
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in done.stderr, done.stderr
    assert f"{path}{where}" in lines[0] and what in lines[0], lines[0]
    assert done.stdout == ""  # nothing started


def test_an_existing_output_path_is_refused_before_any_host_is_asked(tmp_path):
    path = inventory(
        tmp_path / "ring.yaml",
        "hosts:\n  a: {address: 127.0.0.1, ssh: local, nodes: [main]}\n"
        "  b: {address: 127.0.0.1, port: 7450, ssh: {port: 1}, nodes: [motor]}\n",
    )
    (tmp_path / "run.mcap").write_text("")
    done = run_tokenring("up", "--hosts", str(path), "--record", str(tmp_path / "run.mcap"), "--no-world")
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        f"tokenring up: error: --record {tmp_path / 'run.mcap'}: exists; give --force to replace it, or another path"
    ]


def test_hosts_places_the_nodes_itself(tmp_path):
    path = inventory(tmp_path / "ring.yaml", "hosts:\n  a: {address: 127.0.0.1, ssh: local, nodes: 2}\n")
    done = run_tokenring("up", "--hosts", str(path), "--nodes", "main")
    assert done.returncode == 2
    assert "leave out --nodes" in done.stderr and len(done.stderr.strip().splitlines()) == 1


def test_the_inventory_places_counted_nodes_and_ssh_gets_its_options_first(tmp_path):
    """``nodes: N`` takes the next N of protocol.yaml's nodes no host names; the inventory's ssh
    options come before the defaults (ssh keeps an option's first value), and the share's command
    line is quoted for the remote shell with the nodes' environment before it (``tokenring:`` is
    a command, split as a shell would)."""
    from tokenring.contract.protocol import default_protocol
    from tokenring.host.hosts import load_inventory
    from tokenring.host.remote import ShareSettings, share_command, ssh_command

    path = inventory(
        tmp_path / "ring.yaml",
        "port: 7500\nhosts:\n  pc: {address: 10.0.0.1, ssh: local, nodes: 2}\n"
        "  b1:\n    address: 10.0.0.2\n    nodes: [charger]\n    tokenring: /opt/ring/bin/python -m tokenring\n"
        "    store: /var/lib/my ring\n    lost_after: 45\n"
        "    ssh: {host: b1-alias, user: robot, port: 2222, options: [-o, ServerAliveInterval=1]}\n",
    )
    found = load_inventory(path, default_protocol())
    assert [h.nodes for h in found.hosts] == [["main", "motor"], ["charger"]]
    assert [h.lost_after for h in found.hosts] == [30.0, 45.0]  # the default, and b1's own
    b1 = found.remote[0]
    settings = ShareSettings(
        ring="lab", bitrate="10M", ack="adaptive", log_level="info", total=3, hub="tcp/10.0.0.1:7500",
        env={"TOKENRING_EXTENSIONS": ""},
    )  # fmt: skip
    argv = ssh_command(b1, share_command(b1, settings), settings.env)
    assert argv[:8] == ["ssh", "-T", "-o", "ServerAliveInterval=1", "-p", "2222", "-l", "robot"]
    assert argv.index("ServerAliveInterval=1") < argv.index("ServerAliveInterval=5")
    assert argv[-3:-1] == ["b1-alias", "--"]
    remote = argv[-1]
    assert remote.startswith(
        "exec env TOKENRING_EXTENSIONS= /opt/ring/bin/python -m tokenring --log-level info up --share 3 "
    )
    assert "--nodes charger" in remote
    assert "--listen tcp/10.0.0.2:7500 --connect tcp/10.0.0.1:7500 --lost-after 45" in remote
    assert remote.endswith(" --store '/var/lib/my ring'")


def test_a_share_that_hears_nothing_from_its_launcher_stops_by_itself(procs, ring_name, endpoint):
    """``up --share`` as ssh runs it on a host: the launcher's lines on its input keep it
    running past ``--lost-after``; once they stop for that long it stops its nodes by itself,
    saying why, exit code 75 (which the launcher takes for a lost host: it connects again)."""
    from tokenring.host.remote import SHARE_LOST

    share = procs.tokenring(
        "up", "--share", "1", "--lost-after", "5", "--nodes", "main", "--no-programs", "--ring", ring_name,
        "--listen", endpoint, stdin=subprocess.PIPE, env={"TOKENRING_EXTENSIONS": ""},
    )  # fmt: skip
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(share.stdout), daemon=True)
    reader.start()
    wait_until(lambda: any("node main (id 10) joined" in line for line in lines), 60, "main to join")
    for _ in range(8):  # 8 s of heartbeats: longer than --lost-after
        share.stdin.write("\n")
        share.stdin.flush()
        time.sleep(HEARTBEAT_S)
    assert share.poll() is None, lines
    silent = time.monotonic()
    code = share.wait(60)
    waited = time.monotonic() - silent
    reader.join(10)
    said = [line.strip() for line in lines]
    assert code == SHARE_LOST, said
    assert waited >= 5 - HEARTBEAT_S, f"stopped {waited:.1f} s after the last heartbeat"
    assert "up | heard nothing from the launcher for 5 s: stopping this host's share" in said
    assert said[-1] == "up | stopped (exit code 75): heard nothing from the launcher for 5 s"


# -- three hosts ---------------------------------------------------------------------------------


@pytest.fixture
def ssh_hosts(tmp_path):
    """Three namespaces on a bridge with an sshd each; all of it gone afterwards, failed or not."""
    hosts = SshHosts(tmp_path / "hosts")
    yield hosts
    hosts.close()


def status(hosts: SshHosts, host: SshHost, ring: str, *options: str) -> dict[int, dict]:
    """``tokenring status --json`` on ``host`` (by default at the tools' endpoint: loopback there)."""
    done = subprocess.run(
        hosts.run(host, TOKENRING, "status", "--ring", ring, "--json", "--timeout", "1.5", *options),
        capture_output=True,
        text=True,
        timeout=60,  # a hang guard: a loaded machine starts an interpreter slowly
        cwd=REPO,
    )
    if done.returncode != 0 or not done.stdout.strip():
        return {}
    return {n["id"]: n for n in json.loads(done.stdout)["nodes"]}


def one_ring(nodes: dict[int, dict], members: list[int]) -> bool:
    """Exactly ``members`` answer, chained in ID order, all on one epoch (one token)."""
    if set(nodes) != set(members):
        return False
    ring = sorted(members)
    chained = all(nodes[a]["successor"] == ring[(i + 1) % len(ring)] for i, a in enumerate(ring))
    return chained and len({tuple(nodes[i]["epoch"]) for i in members}) == 1


#: asks the web view's API on a host for the nodes it shows
WEB_NODES = """
import json, sys, urllib.request
with urllib.request.urlopen(f"http://127.0.0.1:{sys.argv[1]}/api/state", timeout=5) as answer:
    print(json.dumps(sorted(json.loads(answer.read())["topics"].get("/ring/nodes", {}).get("nodes", {}))))
"""


def asked_on(hosts: SshHosts, host: SshHost, script: str, port: int) -> list[int]:
    """The node IDs ``script`` (WEB_NODES, METRICS_NODES) reads on ``host`` from ``port``'s page
    (none while it does not answer)."""
    done = subprocess.run(
        hosts.run(host, sys.executable, "-c", script, str(port)),
        capture_output=True,
        text=True,
        timeout=60,
    )
    return sorted(int(i) for i in json.loads(done.stdout)) if done.returncode == 0 else []


def web_nodes(hosts: SshHosts, host: SshHost, port: int) -> list[int]:
    """The node IDs the web view on ``host`` shows."""
    return asked_on(hosts, host, WEB_NODES, port)


def log_says(log: Path, text: str) -> bool:
    return text in log.read_text()


def tool(hosts: SshHosts, host: SshHost, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    """``tokenring ARGS`` on ``host`` (a hang guard: a loaded machine starts an interpreter slowly)."""
    return subprocess.run(
        hosts.run(host, TOKENRING, *args), capture_output=True, text=True, timeout=timeout, cwd=REPO
    )


#: asks the metrics page on a host for the nodes it has series of
METRICS_NODES = """
import json, re, sys, urllib.request
with urllib.request.urlopen(f"http://127.0.0.1:{sys.argv[1]}/metrics", timeout=5) as answer:
    text = answer.read().decode()
print(json.dumps(sorted({int(i) for i in re.findall(r'^tokenring_node_info[{][^}]*node="([0-9]+)"', text, re.M)})))
"""


def metrics_nodes(hosts: SshHosts, host: SshHost, port: int) -> list[int]:
    """The node IDs ``up --metrics`` on ``host`` serves figures of."""
    return asked_on(hosts, host, METRICS_NODES, port)


def tools_see_every_host(
    hosts: SshHosts, host: SshHost, ring: str, folder: Path, everyone: list[int]
) -> None:
    """From the launcher's host: ``monitor`` sees every node, ``record --pcap`` captures frames
    of every node, and a ``chaos`` scenario that names no nodes learns the ring's eight (not
    protocol.yaml's) and hangs and resumes a node on host c."""
    from tokenring.contract.protocol import default_protocol
    from tokenring.observe.pcapng import open_pcapng

    capture = folder / "ring.pcapng"
    recording = subprocess.Popen(
        hosts.run(
            host, TOKENRING, "record", "--pcap", str(capture), "--ring", ring, "--duration", "3", "--quiet"
        ),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=REPO,
    )
    try:
        done = tool(hosts, host, "monitor", "--ring", ring, "--once", "--json")
        assert done.returncode == 0, done.stderr
        assert sorted(int(i) for i in json.loads(done.stdout)["nodes"]) == everyone, done.stdout[:2000]
        _, err = recording.communicate(timeout=120)
    finally:
        if recording.poll() is None:
            recording.kill()
            recording.wait()
    assert recording.returncode == 0, err
    offsets = default_protocol().header.offsets
    frames = list(open_pcapng(capture))
    senders = {f.frame[offsets["sid"]] for f in frames}
    assert senders == set(everyone) and {f.did for f in frames} == set(everyone), (len(frames), senders)

    scenario = folder / "hang-lcd.yaml"  # no ring.nodes: the running ring's own
    scenario.write_text(
        "settle: 2.0\nfaults:\n  - {at: 0.5, node: lcd, kind: hang}\n  - {at: 2.0, node: lcd, kind: resume}\n"
    )
    done = tool(hosts, host, "chaos", str(scenario), "--ring", ring, "--json", "-", timeout=240)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    report = json.loads(done.stdout)
    assert report["ok"] and all(f["recovered_ms"] is not None for f in report["faults"]), report
    assert f"ring {ring}: 8 nodes (main, motor, sonar, compass, copro, map, lcd, charger)" in done.stderr


@needs_ssh_hosts
@pytest.mark.slow
@pytest.mark.timeout(600)  # its hang guards: a loaded machine's ssh and status are slow
def test_one_command_runs_a_ring_across_three_hosts_over_ssh(procs, ssh_hosts, tmp_path):
    hosts = ssh_hosts
    a, b, c = hosts.hosts
    ring = f"h{uuid.uuid4().hex[:8]}"
    programs = write_probe_programs(tmp_path / "programs")
    # the test's own ssh settings; the client finds a dead connection within ~6 s
    ssh = {
        "identity": str(hosts.identity),
        "options": [*hosts.ssh_options, "-o", "ServerAliveInterval=2", "-o", "ServerAliveCountMax=3"],
    }
    spec = {
        "hosts": {
            "a": {"address": a.address, "ssh": "local", "nodes": ["main", "motor", "sonar"]},
            "b": {
                "address": b.address,
                "ssh": ssh,
                "nodes": ["compass", "copro", "map"],
                "tokenring": TOKENRING,
                "store": str(tmp_path / "store-b"),
            },
            "c": {
                "address": c.address,
                "ssh": ssh,
                "nodes": 2,  # the two nodes left: lcd and charger
                "tokenring": TOKENRING,
                "store": str(tmp_path / "store-c"),
            },
        }
    }
    path = inventory(tmp_path / "ring.yaml", json.dumps(spec, indent=2))  # JSON is YAML
    log = tmp_path / "launcher.log"
    everyone, without_c = [10, 20, 30, 40, 50, 60, 70, 80], [10, 20, 30, 40, 50, 60]
    seen: dict[int, dict] = {}

    def ring_of(members: list[int]) -> dict[int, dict] | None:
        nodes = status(hosts, a, ring)
        seen.clear()
        seen.update(
            {i: {k: n[k] for k in ("successor", "epoch", "pid", "program")} for i, n in nodes.items()}
        )
        return nodes if one_ring(nodes, members) else None

    started = time.monotonic()
    with log.open("w") as out:  # a file: an unread pipe would fill and stall the launcher's writer
        launcher = procs.start(
            hosts.run(
                a,
                TOKENRING,
                "up",
                "--hosts",
                str(path),
                "--ring",
                ring,
                "--bitrate",
                "10M",
                "--programs",
                str(programs),
                "--store",
                str(tmp_path / "store-a"),
                "--web",  # host a's own port space: the default ports are free there
                "--metrics",
                "9464",
                "--respawn",
            ),
            stdout=out,
            env={"TOKENRING_EXTENSIONS": ""},  # the bare ring: the probe programs need no world
        )
    try:
        # one ring over the three hosts, seen from host a, every program downloaded over it
        wait_until(lambda: ring_of(everyone), 120, "one ring across the three hosts")
        formed = time.monotonic() - started
        # the web view on the launcher's host shows every node, whichever host runs it
        wait_until(lambda: web_nodes(hosts, a, 8080) == everyone, 60, "the web view showing all nodes")
        wait_until(lambda: log_says(log, "changed: 8 of 8 program(s)"), 120, "the programs downloaded")

        def programs_run() -> bool:
            nodes = status(hosts, a, ring)
            return len(nodes) == 8 and all(n.get("program") == "Program" for n in nodes.values())

        wait_until(programs_run, 60, "every node running its downloaded program")
        for name in ("b/compass", "c/lcd", "b/up", "c/up", "a/main"):
            assert f"{name} | " in log.read_text(), name  # lines prefixed with host and module
        # the launcher's metrics have every host's nodes; the tools on its host reach them all
        tools_started = time.monotonic()
        wait_until(lambda: metrics_nodes(hosts, a, 9464) == everyone, 60, "every node in the metrics")
        tools_see_every_host(hosts, a, ring, tmp_path, everyone)
        wait_until(lambda: ring_of(everyone), 60, "the whole ring after the chaos scenario")
        tools = time.monotonic() - tools_started

        # a fault on a remote node: copro (host b) hangs, really stopped, and the ring routes
        # around it; resumed through host b's launcher (SIGCONT), it is back in the ring
        done = subprocess.run(
            hosts.run(a, TOKENRING, "fault", "--ring", ring, "copro", "hang"),
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert done.returncode == 0, done.stderr
        wait_until(lambda: ring_of([i for i in everyone if i != 50]), 60, "the ring around hung copro")
        assert seen[40]["successor"] == 60
        done = subprocess.run(
            hosts.run(a, TOKENRING, "fault", "--ring", ring, "copro", "resume"),
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert done.returncode == 0, done.stderr
        wait_until(lambda: ring_of(everyone), 60, "copro back in the ring")

        # a remote node that dies is reported and started again by its host's share (--respawn),
        # with its program from that host's store; the lines come back prefixed with the host
        before = seen[60]["pid"]
        done = subprocess.run(
            hosts.run(a, TOKENRING, "fault", "--ring", ring, "map", "crash"),
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert done.returncode == 0, done.stderr
        wait_until(lambda: log_says(log, "b/up | respawning map"), 60, "host b to respawn map")
        assert log_says(log, "b/up | node map (id 60) crashed on purpose")
        wait_until(
            lambda: (
                (ring := ring_of(everyone)) and ring[60]["pid"] != before and ring[60]["program"] == "Program"
            ),
            60,
            "the respawned map in the ring, running its program",
        )
        pids = {i: n["pid"] for i, n in seen.items()}

        # host c's cable cut silently: a and b re-form without lcd and charger; c's ssh session
        # dies (sshd's ClientAlive), and with it c's share: nothing of the ring is left on c
        cut = time.monotonic()
        hosts.cut(c)
        wait_until(lambda: ring_of(without_c), 120, "hosts a and b re-formed without host c")
        reformed = time.monotonic() - cut
        wait_until(lambda: not hosts.leftovers().get(c.name), 60, "host c's share ended with its session")
        wait_until(lambda: log_says(log, "host c (") and log_says(log, "lost"), 60, "host c reported lost")
        hosts.mend()
        mended = time.monotonic()
        after = wait_until(lambda: ring_of(everyone), 120, "host c's nodes back in the ring")
        rejoined = time.monotonic() - mended
        assert log_says(log, "connecting to host c")
        # the nodes on a and b are the ones that were there all along; c's are new processes
        assert all(after[i]["pid"] == pids[i] for i in without_c)
        assert all(after[i]["pid"] != pids[i] for i in (70, 80))
        live = re.search(r"every host's nodes are live \(8 nodes, ([0-9.]+) s\)", log.read_text())
        assert live, "the launcher said when every host's nodes were live"
        print(
            f"nodes live {live.group(1)} s, one ring seen {formed:.1f} s, the tools {tools:.1f} s, "
            f"re-formed after the cut {reformed:.1f} s, rejoined {rejoined:.1f} s after the mend"
        )
    except AssertionError as failure:
        tail = "\n".join(log.read_text().splitlines()[-60:])
        raise AssertionError(f"{failure}\nlast status: {seen}\n--- launcher\n{tail}") from None
    finally:
        # Ctrl-C stops everything everywhere
        launcher.send_signal(signal.SIGINT)
        try:
            code = launcher.wait(60)
        except subprocess.TimeoutExpired:
            launcher.kill()
            code = None
    assert code == 130, log.read_text()[-3000:]
    assert not pid_alive(launcher.pid)
    # no process in any namespace but the sshd listeners (a session's sshd ends just after its command)
    wait_until(lambda: not hosts.leftovers(), 30, "no process left in any namespace")
    assert log_says(log, "b/up | stopped (exit code 0)") and log_says(log, "c/up | stopped (exit code 0)")


@needs_ssh_hosts
@pytest.mark.slow
@pytest.mark.timeout(400)
def test_a_secured_ring_across_hosts_obeys_only_its_operator(procs, ssh_hosts, tmp_path):
    """``tokenring secure``'s deployment across hosts: every router and node on TLS with the node
    certificate (which names the three hosts' addresses); the operator hangs and resumes a node
    on another host, an observer sees the whole ring but its fault never arrives."""
    hosts = ssh_hosts
    a, b, c = hosts.hosts
    ring = f"s{uuid.uuid4().hex[:8]}"
    keys = tmp_path / "keys"
    made = run_tokenring("secure", "init", str(keys), *(f"--host={h.address}" for h in hosts.hosts))
    assert made.returncode == 0, made.stderr
    operator, observer = keys / "operator.json5", keys / "observer.json5"
    ssh = {"identity": str(hosts.identity), "options": hosts.ssh_options}
    remote = {"ssh": ssh, "tokenring": TOKENRING}
    spec = {
        "scheme": "tls",
        "hosts": {
            "a": {"address": a.address, "ssh": "local", "nodes": ["main", "motor", "sonar"]},
            "b": {"address": b.address, "nodes": ["compass", "copro", "map"], **remote},
            "c": {"address": c.address, "nodes": ["lcd", "charger"], **remote},
        },
    }
    path = inventory(tmp_path / "ring.yaml", json.dumps(spec, indent=2))
    log = tmp_path / "launcher.log"
    hub = ["-e", f"tls/{a.address}:7447"]
    with log.open("w") as out:
        launcher = procs.start(
            hosts.run(
                a, TOKENRING, "up", "--hosts", str(path), "--ring", ring, "--bitrate", "10M", "--no-programs",
                "--zenoh-config", str(keys / "node.json5"),
            ),
            stdout=out,
            env={"TOKENRING_EXTENSIONS": ""},
        )  # fmt: skip
    everyone = [10, 20, 30, 40, 50, 60, 70, 80]

    def ring_of(members: list[int], config: Path) -> dict[int, dict] | None:
        nodes = status(hosts, a, ring, *hub, "--zenoh-config", str(config))
        return nodes if one_ring(nodes, members) else None

    def fault(config: Path, *args: str) -> subprocess.CompletedProcess:
        return subprocess.run(
            hosts.run(a, TOKENRING, "fault", "--ring", ring, *hub, "--zenoh-config", str(config), *args),
            capture_output=True,
            text=True,
            timeout=60,
        )

    try:
        wait_until(lambda: ring_of(everyone, observer), 120, "the observer to see one ring over three hosts")
        assert "tls/" in log.read_text() and "tcp/" not in log.read_text()
        done = fault(operator, "copro", "hang")
        assert done.returncode == 0, done.stderr
        wait_until(lambda: ring_of([i for i in everyone if i != 50], observer), 60, "the ring around copro")
        done = fault(operator, "copro", "resume")  # SIGCONT by host b's launcher
        assert done.returncode == 0, done.stderr
        wait_until(lambda: ring_of(everyone, observer), 60, "copro back")
        refused = fault(observer, "lcd", "hang", "--timeout", "3")
        assert refused.returncode != 0 and "certificate lack the right" in refused.stderr, refused.stderr
        assert ring_of(everyone, operator) or wait_until(
            lambda: ring_of(everyone, operator), 30, "lcd untouched"
        )
    except AssertionError as failure:
        tail = "\n".join(log.read_text().splitlines()[-60:])
        raise AssertionError(f"{failure}\n--- launcher\n{tail}") from None
    finally:
        code = interrupt(launcher)
    assert code == 130, log.read_text()[-3000:]
    wait_until(lambda: not hosts.leftovers(), 30, "no process left in any namespace")


@needs_ssh_hosts
@pytest.mark.slow
@pytest.mark.timeout(300)
def test_a_host_whose_share_refuses_to_start_stops_the_run_naming_its_line(procs, request, tmp_path):
    """Host b answers ssh, but its share refuses (its store is a file): one line naming the
    inventory's line and b's reason, exit code 2, and nothing left running on either host."""
    hosts = SshHosts(tmp_path / "hosts", count=2)
    request.addfinalizer(hosts.close)
    a, b = hosts.hosts
    (tmp_path / "not-a-dir").write_text("")
    spec = {
        "hosts": {
            "a": {"address": a.address, "ssh": "local", "nodes": ["main", "motor"]},
            "b": {
                "address": b.address,
                "ssh": {"identity": str(hosts.identity), "options": hosts.ssh_options},
                "nodes": ["sonar"],
                "tokenring": TOKENRING,
                "store": str(tmp_path / "not-a-dir"),
            },
        }
    }
    path = inventory(tmp_path / "ring.yaml", json.dumps(spec, indent=2))
    launcher = procs.start(
        hosts.run(
            a, TOKENRING, "up", "--hosts", str(path), "--ring", f"r{uuid.uuid4().hex[:8]}", "--no-programs"
        ),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env={"TOKENRING_EXTENSIONS": ""},
    )
    out, err = launcher.communicate(timeout=120)
    assert launcher.returncode == 2, out[-2000:] + err
    line = path.read_text().splitlines().index('    "b": {') + 1
    assert err.strip().splitlines() == [
        f"tokenring up: error: {path}:{line}: host b ({b.address}): share exited with code 2 "
        f"(tokenring up: error: --store {tmp_path / 'not-a-dir'}: not a directory)"
    ], err
    wait_until(lambda: not hosts.leftovers(), 30, "no process left in either namespace")


@needs_ssh_hosts
@pytest.mark.slow
@pytest.mark.timeout(300)
def test_a_killed_launcher_leaves_nothing_on_any_host(procs, request, tmp_path):
    """SIGKILL gives the launcher no time to stop anything: its ssh clients die with it (their
    parent-death signal), each host's sshd closes the session, and the share there stops its
    nodes when its input closes. Nothing is left on any host, by PID. (Host b is reached by an
    ssh_config Host alias: the user's ssh configuration applies.)"""
    hosts = SshHosts(tmp_path / "hosts", count=2)
    request.addfinalizer(hosts.close)
    a, b = hosts.hosts
    ring = f"k{uuid.uuid4().hex[:8]}"
    spec = two_hosts_spec(hosts, tmp_path)
    # host b reached through an ssh_config of the test's own: its Host alias, key and known_hosts
    config = tmp_path / "ssh_config"
    config.write_text(
        f"Host ring-b\n  HostName {b.address}\n  IdentityFile {hosts.identity}\n  IdentitiesOnly yes\n"
        f"  IdentityAgent none\n  UserKnownHostsFile {hosts.known_hosts}\n  StrictHostKeyChecking accept-new\n"
        "  LogLevel ERROR\n"
    )
    spec["hosts"]["b"]["ssh"] = {"host": "ring-b", "options": ["-F", str(config)]}
    path = inventory(tmp_path / "ring.yaml", json.dumps(spec, indent=2))
    log = tmp_path / "launcher.log"
    with log.open("w") as out:
        launcher = procs.start(
            hosts.run(a, TOKENRING, "up", "--hosts", str(path), "--ring", ring, "--no-programs"),
            stdout=out,
            env={"TOKENRING_EXTENSIONS": ""},
        )
    wait_until(lambda: one_ring(status(hosts, a, ring), [10, 20, 30, 40]), 120, "the ring over two hosts")
    assert hosts.leftovers().get(b.name), "host b runs its share"
    killed = time.monotonic()
    launcher.kill()
    launcher.wait(30)
    wait_until(lambda: not hosts.leftovers(), 60, "nothing left on either host")
    print(f"host b empty {time.monotonic() - killed:.1f} s after the launcher's SIGKILL")


def two_hosts_spec(hosts: SshHosts, tmp_path: Path, **extra: object) -> dict:
    """Host a (the launcher's: main, motor) and host b (sonar, compass) over the test's ssh."""
    a, b = hosts.hosts
    return {
        **extra,
        "hosts": {
            "a": {"address": a.address, "ssh": "local", "nodes": ["main", "motor"]},
            "b": {
                "address": b.address,
                "ssh": {"identity": str(hosts.identity), "options": hosts.ssh_options},
                "nodes": ["sonar", "compass"],
                "tokenring": TOKENRING,
                "store": str(tmp_path / "store-b"),
            },
        },
    }


@needs_ssh_hosts
@pytest.mark.slow
@pytest.mark.timeout(300)
def test_a_remote_node_that_dies_makes_the_run_exit_1_naming_host_and_node(procs, request, tmp_path):
    """Without ``--respawn`` a node killed on host b stays dead; when the run stops (SIGTERM)
    b's share exits 1 saying why, and the launcher's own exit code is 1, with one line naming
    the host and the node."""
    hosts = SshHosts(tmp_path / "hosts", count=2)
    request.addfinalizer(hosts.close)
    a, b = hosts.hosts
    ring = f"x{uuid.uuid4().hex[:8]}"
    path = inventory(tmp_path / "ring.yaml", json.dumps(two_hosts_spec(hosts, tmp_path), indent=2))
    log = tmp_path / "launcher.log"
    with log.open("w") as out:
        launcher = procs.start(
            hosts.run(a, TOKENRING, "up", "--hosts", str(path), "--ring", ring, "--no-programs"),
            stdout=out,
            env={"TOKENRING_EXTENSIONS": ""},
        )
    try:

        def whole() -> dict[int, dict] | None:
            nodes = status(hosts, a, ring)
            return nodes if one_ring(nodes, [10, 20, 30, 40]) else None

        nodes = wait_until(whole, 120, "the ring over two hosts")
        os.kill(nodes[30]["pid"], signal.SIGKILL)  # sonar, on host b (one PID space for the namespaces)
        wait_until(
            lambda: log_says(log, "b/up | node sonar (id 30) killed by SIGKILL"), 60, "b to report sonar"
        )
        wait_until(lambda: one_ring(status(hosts, a, ring), [10, 20, 40]), 60, "the ring without sonar")
    finally:
        launcher.send_signal(signal.SIGTERM)
        try:
            code = launcher.wait(60)
        except subprocess.TimeoutExpired:
            launcher.kill()
            code = None
    lines = log.read_text().splitlines()
    assert code == 1, "\n".join(lines[-30:])
    said = f"up | host b ({b.address}): node sonar (id 30) killed by SIGKILL (its share exited with code 1)"
    assert said in [line.strip() for line in lines], "\n".join(lines[-30:])
    assert lines[-1].endswith("up | stopped (exit code 1)")
    wait_until(lambda: not hosts.leftovers(), 30, "no process left in either namespace")


def two_hosts_up(
    procs, request, tmp_path: Path, lost_after: float
) -> tuple[SshHosts, str, Path, subprocess.Popen]:
    """Two hosts whose sshd never notices a silent client, and ``up --hosts`` run on host a
    (its output in ``launcher.log``): the hosts, the ring's name, the log and the launcher."""
    hosts = SshHosts(tmp_path / "hosts", count=2, client_alive=False)
    request.addfinalizer(hosts.close)
    ring = f"x{uuid.uuid4().hex[:8]}"
    spec = two_hosts_spec(hosts, tmp_path, lost_after=lost_after)
    path = inventory(tmp_path / "ring.yaml", json.dumps(spec, indent=2))
    log = tmp_path / "launcher.log"
    with log.open("w") as out:
        launcher = procs.start(
            hosts.run(hosts.hosts[0], TOKENRING, "up", "--hosts", str(path), "--ring", ring, "--no-programs"),
            stdout=out,
            env={"TOKENRING_EXTENSIONS": ""},
        )
    return hosts, ring, log, launcher


def interrupt(launcher: subprocess.Popen) -> int | None:
    """Ctrl-C to the launcher; its exit code (None: it did not stop within 60 s, and was killed)."""
    launcher.send_signal(signal.SIGINT)
    try:
        return launcher.wait(60)
    except subprocess.TimeoutExpired:
        launcher.kill()
        return None


@needs_ssh_hosts
@pytest.mark.slow
@pytest.mark.timeout(300)
def test_a_host_cut_off_stops_its_share_itself_and_comes_back(procs, request, tmp_path):
    """Host b's sshd has Debian's defaults (no ClientAlive: it keeps a silent session for hours).
    A long cut: host a re-forms without b, b's share stops by itself once it heard nothing from
    the launcher for ``lost_after``, the launcher, trying again at most 10 s apart, starts a new
    share once the cable is back and b's nodes rejoin. Cut again and Ctrl-C: the launcher gives
    up on b after 10 s, b's share stops by itself, and once the cable is back the ssh sessions
    end too: nothing is left in any namespace."""
    lost_after = 10
    hosts, ring, log, launcher = two_hosts_up(procs, request, tmp_path, lost_after)
    a, b = hosts.hosts
    everyone = [10, 20, 30, 40]

    def share_stops_by_itself(cut: float) -> float:
        # its last heartbeat came before the cut: it stops lost_after later, plus its nodes' leave
        wait_until(lambda: not hosts.besides_sshd(b), lost_after + 30, "host b's share to stop by itself")
        stopped = time.monotonic() - cut
        assert stopped >= lost_after - LAST_BEAT_S, f"host b's share stopped {stopped:.1f} s after the cut"
        assert hosts.leftovers().get(b.name), "b's sshd still holds the session it cannot tell is dead"
        return stopped

    try:
        wait_until(lambda: one_ring(status(hosts, a, ring), everyone), 120, "the ring over two hosts")
        assert hosts.besides_sshd(b), "host b runs its share"
        cut = time.monotonic()  # (before: the cut takes effect while the command runs)
        hosts.cut(b)
        wait_until(lambda: one_ring(status(hosts, a, ring), [10, 20]), 120, "host a re-formed without b")
        stopped = share_stops_by_itself(cut)
        wait_until(
            lambda: log_says(log, f"host b ({b.address}): lost (ssh exited with code 255"), 60, "b lost"
        )
        hosts.mend()
        mended = time.monotonic()
        wait_until(lambda: one_ring(status(hosts, a, ring), everyone), 120, "host b's nodes back in the ring")
        rejoined = time.monotonic() - mended
        cut = time.monotonic()  # (before: the cut takes effect while the command runs)
        hosts.cut(b)
        launcher.send_signal(signal.SIGINT)
        stopped_again = share_stops_by_itself(cut)
    finally:
        code = interrupt(launcher)
    text = log.read_text()
    assert code == 130, text[-3000:]
    assert f"host b ({b.address}) did not stop within 10 s: ending its ssh" in text
    hosts.mend()
    mended = time.monotonic()
    # b's sshd learns that its client is gone once its retransmissions reach host a again
    wait_until(lambda: not hosts.leftovers(), 120, "no process left in any namespace")
    print(
        f"host b's share stopped {stopped:.1f} s after the cut, its nodes rejoined {rejoined:.1f} s after "
        f"the mend; after Ctrl-C during a cut, stopped {stopped_again:.1f} s after it, its sshd sessions "
        f"{time.monotonic() - mended:.1f} s after the mend"
    )


@needs_ssh_hosts
@pytest.mark.slow
@pytest.mark.timeout(300)
def test_a_host_back_before_its_old_share_stopped_is_tried_again_until_it_has(procs, request, tmp_path):
    """Only host b's ssh traffic is cut (the ring's goes on): the launcher's ssh to b dies, and
    once it is back b's old share still runs (its sshd cannot tell that the session is dead, and
    the share has heard nothing from the launcher for less than ``lost_after``), so a new share
    is refused there. The launcher tries again, counting the loss once, and once the old share
    has stopped by itself a new one's nodes join."""
    lost_after = 30
    hosts, ring, log, launcher = two_hosts_up(procs, request, tmp_path, lost_after)
    a, b = hosts.hosts
    everyone = [10, 20, 30, 40]
    refusal = re.compile(rf"host b \({re.escape(b.address)}\): .*in use.*: connecting again in \d+ s")
    joined = re.compile(r"b/sonar \| .* node sonar \(id 30\) joined")
    try:
        wait_until(lambda: one_ring(status(hosts, a, ring), everyone), 120, "the ring over two hosts")
        cut = time.monotonic()  # (before: the cut takes effect while the command runs)
        hosts.cut(b, ssh_only=True)
        wait_until(
            lambda: log_says(log, f"host b ({b.address}): lost (ssh exited with code 255"), 60, "b lost"
        )
        hosts.mend()
        assert time.monotonic() - cut < lost_after - 5, "the old share may have stopped: not the case tested"
        wait_until(lambda: refusal.search(log.read_text()), 60, "a new share on b refused")
        assert len(joined.findall(log.read_text())) == 1  # the old share runs on: no new nodes yet
        wait_until(lambda: len(joined.findall(log.read_text())) == 2, lost_after + 60, "a new share's nodes")
        back = time.monotonic() - cut
        assert back >= lost_after - LAST_BEAT_S, f"a new share's nodes joined {back:.1f} s after the cut"
        wait_until(lambda: one_ring(status(hosts, a, ring), everyone), 120, "every node in one ring")
    finally:
        code = interrupt(launcher)
    text = log.read_text()
    assert code == 130, text[-3000:]
    # one loss, however many attempts it took: the refusals are said, not counted as failures
    assert len(re.findall(r"host b .*its nodes are out of the ring", text)) == 1, text[-3000:]
    wait_until(lambda: not hosts.leftovers(), 60, "no process left in either namespace")
    print(f"a new share's nodes joined {back:.1f} s after the cut (lost_after {lost_after} s)")
