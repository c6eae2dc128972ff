"""``tokenring chaos --ring``: a scenario that names no nodes learns the running ring's own (three
here, not protocol.yaml's eight; a ring across hosts is what its inventory placed), and a fault on
a node that ring lacks is refused in one line naming the scenario's line, exit code 2."""

from __future__ import annotations

import json
import signal

from tests.support.processes import run_tokenring
from tests.support.ringutil import tap, wait_ring


def test_chaos_on_a_running_ring_learns_its_nodes(procs, ring_name, endpoint, tmp_path):
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", "main,motor,sonar", "--no-programs",
        "--bitrate", "10M", env={"TOKENRING_EXTENSIONS": ""},
    )  # fmt: skip
    try:
        with tap(endpoint) as session:
            wait_ring(session, ring_name, [10, 20, 30], timeout=120)
        scenario = tmp_path / "hang-sonar.yaml"
        scenario.write_text(
            "settle: 1.0\nfaults:\n  - {at: 0.5, node: sonar, kind: hang}\n  - {at: 1.5, node: sonar, kind: resume}\n"
        )
        done = run_tokenring(
            "chaos", str(scenario), "--ring", ring_name, "-e", endpoint, "--json", "-", timeout=180
        )
        assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
        report = json.loads(done.stdout)
        assert report["ok"] and [f["recovered_ms"] is not None for f in report["faults"]] == [True, True], (
            report
        )
        assert f"chaos | ring {ring_name}: 3 nodes (main, motor, sonar)" in done.stderr

        elsewhere = tmp_path / "hang-copro.yaml"
        elsewhere.write_text("faults:\n  - {at: 0.5, node: copro, kind: hang}\n")
        refused = run_tokenring(
            "chaos", str(elsewhere), "--ring", ring_name, "-e", endpoint, "--quiet", timeout=120
        )
        assert refused.returncode == 2
        assert refused.stderr.strip().splitlines() == [
            f"tokenring chaos: error: {elsewhere}:2: faults.0.node: copro is not a node of ring {ring_name} "
            "(its nodes: main, motor, sonar)"
        ], refused.stderr
    finally:
        launcher.send_signal(signal.SIGINT)
        launcher.communicate(timeout=60)
    assert launcher.returncode == 130
