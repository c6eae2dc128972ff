"""``tokenring web`` and ``up --web`` without a browser: the hub's folding, the HTTP API's answers
to bad and hostile requests, the verb's refusals (exit 2, one line), its stops, and ``up --web``
serving a live ring's token."""

from __future__ import annotations

import json
import re
import signal
import socket
import urllib.error
import urllib.request

import pytest

from tests.support.processes import run_tokenring
from tests.support.ringutil import control, launcher_pids, tap, wait_ring, wait_until
from tokenring.observe.feed import Message
from tokenring.transport.session import free_port
from tokenring.web.hub import Hub
from tokenring.web.server import STATIC


def test_the_hub_counts_passes_keeps_a_window_and_accumulates_scenes():
    hub = Hub(window=3)
    for i in range(5):
        hub.on_message(Message("/ring/frame", i, {"did": 20 + i, "sid": 10, "counter": i, "epoch": 1}))
    version, topics = hub.changes()
    assert topics["/web/token"]["frames"] == 5 and topics["/web/token"]["holder"] == 24
    assert "/ring/frame" not in topics
    for ms in (1.0, 2.0, 3.0, 4.0):
        hub.on_message(Message("/ring/roundtrip", 0, {"ms": ms, "node": 10}))
    line = lambda i: {"id": f"v{i}", "lines": [{"points": [{"x": i, "y": 0}]}]}  # noqa: E731
    hub.on_message(Message("/robot/map", 0, {"entities": [line(1)]}))
    hub.on_message(Message("/robot/map", 0, {"entities": [line(2)]}))
    hub.on_message(Message("/robot/map", 0, {"deletions": [{"type": 0, "id": "v1"}], "entities": [line(3)]}))
    later, changed = hub.changes(version)
    assert set(changed) == {"/ring/roundtrip", "/robot/map"}
    assert [s[1] for s in changed["/ring/roundtrip"]["samples"]] == [2.0, 3.0, 4.0]
    assert [e["id"] for e in changed["/robot/map"]["entities"]] == ["v2", "v3"]
    hub.on_message(Message("/robot/map", 0, {"deletions": [{"type": 1}]}))
    assert hub.changes(later)[1] == {"/robot/map": {"entities": []}}
    assert hub.changes(hub.version) == (hub.version, {})


def test_the_page_loads_nothing_from_the_network():
    from modules.pc.web import STATIC as ROBOT_STATIC

    for path in [*STATIC.rglob("*"), *ROBOT_STATIC.rglob("*")]:
        if path.suffix in (".html", ".js", ".css"):
            text = path.read_text()
            assert not re.search(r"""https?://|["'(]//""", text), path  # no absolute URL, no CDN


@pytest.mark.slow
def test_bad_ports_are_one_line_and_exit_2():
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        out = run_tokenring("web", "--port", str(port), "-e", f"tcp/127.0.0.1:{free_port()}", timeout=60)
        assert out.returncode == 2, out.stderr
        assert f"--port {port}: cannot listen on 127.0.0.1:{port} (in use)" in out.stderr
        assert "Traceback" not in out.stderr and len(out.stderr.strip().splitlines()) == 1
        up = run_tokenring("up", "--web", "--web-port", str(port), "--duration", "5", timeout=60)
        assert up.returncode == 2 and f"--web-port {port}: cannot listen" in up.stderr, up.stderr
        assert "Traceback" not in up.stderr and "starting" not in up.stdout
    for bad in ("70000", "-1", "http"):
        out = run_tokenring("web", "--port", bad, timeout=30)
        assert out.returncode == 2 and "--port" in out.stderr and "Traceback" not in out.stderr


@pytest.mark.slow
def test_help_has_examples():
    out = run_tokenring("web", "--help", timeout=30)
    assert out.returncode == 0 and "examples:" in out.stdout and "--port 0 --json" in out.stdout


def post(url: str, body: bytes, headers: dict[str, str]) -> tuple[int, dict]:
    request = urllib.request.Request(url, data=body, headers=headers, method="POST")
    try:
        with urllib.request.urlopen(request, timeout=30) as response:
            return response.status, json.loads(response.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read())


def start_web(procs, endpoint: str, ring: str):
    web = procs.tokenring("web", "--ring", ring, "-e", endpoint, "--port", "0", "--json")
    line = web.stdout.readline()
    assert line.startswith("{"), line + (web.stdout.read() if web.poll() is not None else "")
    return web, json.loads(line)["url"]


JSON = {"Content-Type": "application/json"}


@pytest.mark.slow
def test_the_api_refuses_bad_and_hostile_requests_and_stops_cleanly(procs, ring_name, endpoint):
    web, url = start_web(procs, endpoint, ring_name)
    with urllib.request.urlopen(url, timeout=30) as page:
        assert b'id="token-frames"' in page.read()
    with urllib.request.urlopen(url + "api/config", timeout=30) as answer:
        config = json.loads(answer.read())
    assert config["ring"] == ring_name and {n["name"] for n in config["nodes"]} >= {"main", "lcd"}
    with urllib.request.urlopen(url + "static/app.js", timeout=30) as script:
        assert b"WebSocket" in script.read()
    cases = [
        (b"not json", JSON, 400, "not JSON"),
        (b"[1, 2]", JSON, 400, "JSON object"),
        (b'{"node": "nemo", "kind": "crash"}', JSON, 400, "unknown node 'nemo'"),
        (b'{"node": "lcd", "kind": "explode"}', JSON, 400, "unknown fault kind"),
        (b'{"node": "lcd", "kind": "delay"}', JSON, 400, "delay needs a value"),
        (b'{"node": "lcd", "kind": "delay", "value": "1e9"}', JSON, 400, "outside 0..60000 ms"),
        (b'{"node": "lcd", "kind": "drop", "value": 7}', JSON, 400, "outside 0..1"),
        (b'{"node": "all", "kind": "partition"}', JSON, 400, "partition needs a value"),
        (b'{"node": "all", "kind": "partition", "value": "main|nemo"}', JSON, 400, "nemo"),
        (b'{"node": "lcd", "kind": "clear"}', {}, 415, "send JSON"),
        (b'{"node": "lcd", "kind": "clear"}', {**JSON, "Origin": "http://evil.example"}, 403, "not from this page"),
    ]  # fmt: skip
    for body, headers, status, text in cases:
        got, answer = post(url + "api/fault", body, headers)
        assert (got, answer["ok"]) == (status, False), (body, answer)
        assert text in answer["error"], (body, answer)
    got, answer = post(url + "api/action/launch-missiles", b"{}", JSON)
    assert got == 404 and "no action 'launch-missiles'" in answer["error"]
    web.send_signal(signal.SIGTERM)
    assert web.wait(30) == 0
    web2, _ = start_web(procs, endpoint, ring_name)
    web2.send_signal(signal.SIGINT)
    assert web2.wait(30) == 130


@pytest.mark.slow
def test_up_web_record_and_foxglove_share_one_watcher_serving_the_live_ring(
    procs, ring_name, endpoint, tmp_path
):
    """``up --web --record --foxglove``: one watcher process serves the page and the bridge and
    writes the recording (three would each decode every frame on the nodes' cores)."""
    from mcap.reader import make_reader

    port, fox_port = free_port(), free_port()
    recording = tmp_path / "run.mcap"
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor,sonar", "--no-world",
        "--duration", "90", "--web", "--web-port", str(port), "--record", str(recording),
        "--foxglove", "--foxglove-port", str(fox_port),
    )  # fmt: skip
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20, 30])
        procs.watch(launcher_pids(session, ring_name))
        status = control(session, ring_name, "launcher", "status")
        assert [s["name"] for s in status["services"]] == ["watch"], status["services"]

        def state() -> dict:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/state", timeout=5) as answer:
                    return json.loads(answer.read())["topics"]
            except OSError:
                return {}

        first = wait_until(
            lambda: state().get("/web/token", {}).get("frames"), 60, "the token on the page's API"
        )
        wait_until(lambda: state()["/web/token"]["frames"] > first + 50, 60, "the token to move on")
        nodes = wait_until(lambda: state().get("/ring/nodes", {}).get("nodes"), 60, "the nodes' stats")
        assert set(nodes) >= {"10", "20", "30"}
        with socket.create_connection(("127.0.0.1", fox_port), timeout=5):
            pass  # the bridge serves on its port (its messages: tests/ring/observe/test_foxglove_bridge.py)
    launcher.terminate()
    output, _ = launcher.communicate(timeout=60)
    assert launcher.returncode == 0, output[-3000:]
    assert "watch | Foxglove:" in output and f"watch | {recording}:" in output, output[-3000:]
    with open(recording, "rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None and summary.statistics is not None
    topics = {
        c.topic: summary.statistics.channel_message_counts.get(i, 0) for i, c in summary.channels.items()
    }
    assert topics["/ring/frame"] > 50 and topics["/ring/roundtrip"] > 0, topics


@pytest.mark.slow
def test_the_page_partitions_the_ring_and_heals_it(procs, ring_name, endpoint):
    """The page's partition goes to every node through the fault control keys, as
    ``tokenring fault all partition`` does; heal ends it."""
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor,sonar", "--no-world",
        "--no-programs",
    )  # fmt: skip
    with tap(endpoint) as session:
        wait_ring(session, ring_name, [10, 20, 30])
        procs.watch(launcher_pids(session, ring_name))
    web, url = start_web(procs, endpoint, ring_name)
    with urllib.request.urlopen(url + "api/config", timeout=30) as answer:
        assert {"partition", "heal"} <= set(json.loads(answer.read())["fault_kinds"])

    def partitions() -> dict[int, object]:
        listing = run_tokenring(
            "fault", "all", "list", "--ring", ring_name, "-e", endpoint, "--json", timeout=60
        )
        assert listing.returncode == 0, listing.stderr
        return {n["id"]: n["faults"].get("partition") for n in json.loads(listing.stdout)["results"]}

    got, answer = post(
        url + "api/fault", b'{"node": "all", "kind": "partition", "value": "main,motor|sonar"}', JSON
    )
    assert got == 200 and answer["ok"], answer
    found = wait_until(
        lambda: (p := partitions()) and all(p.get(i) for i in (10, 20, 30)) and p, 30, "the partition"
    )
    assert all(found[i]["groups"] == [[10, 20], [30]] for i in (10, 20, 30)), found
    got, answer = post(url + "api/fault", b'{"node": "all", "kind": "heal"}', JSON)
    assert got == 200 and answer["ok"], answer
    wait_until(lambda: (p := partitions()) and not any(p.values()), 30, "the partition healed")
    web.send_signal(signal.SIGTERM)
    assert web.wait(30) == 0
    launcher.send_signal(signal.SIGTERM)
    launcher.wait(60)


@pytest.mark.slow
@pytest.mark.parametrize("value", ["", " "])
def test_an_empty_host_is_refused(value):
    out = run_tokenring("web", "--host", value, timeout=30)
    assert out.returncode == 2 and "--host" in out.stderr and "Traceback" not in out.stderr
