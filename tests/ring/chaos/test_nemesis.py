"""The randomized nemesis: schedules from a seed, shrinking, and the ledger checker's rules."""

from __future__ import annotations

import itertools
import json

import pytest

from tests.support.processes import REPO
from tokenring.chaos.checker import judge
from tokenring.chaos.nemesis import OPERATIONS, Operation, generate, scenario_document, shrink
from tokenring.chaos.runner import load_scenario
from tokenring.contract.protocol import default_protocol

NAMES = [n.name for n in default_protocol().default_nodes]


def test_the_same_seed_gives_the_same_schedule_and_another_seed_another():
    assert generate(11, NAMES, duration=60) == generate(11, NAMES, duration=60)
    assert generate(11, NAMES, duration=60) != generate(12, NAMES, duration=60)


def test_a_schedule_is_a_valid_scenario_with_every_fault_ended_before_the_settle(tmp_path):
    ops = generate(5, NAMES, duration=60, settle=3.0)
    kinds = {step["kind"] for op in ops for step in op.steps}
    assert {"crash", "hang", "partition", "heal", "resume"} <= kinds
    path = tmp_path / "s.yaml"
    path.write_text(scenario_document(ops, settle=3.0))
    scenario = load_scenario(path)  # the chaos loader's own checks: nodes, kinds, values, order
    assert scenario.respawn and scenario.workload == "probe"
    assert len(scenario.faults) == sum(len(op.steps) for op in ops)
    assert all(step.at <= 57.0 for step in scenario.faults)
    # every fault that lasts is ended by its own operation
    for op in ops:
        first = op.steps[0]["kind"]
        closing = {"hang": "resume", "leave": "join", "partition": "heal"}.get(first, "clear")
        if first not in ("crash", "lose"):
            assert op.steps[-1]["kind"] == closing, op


def test_schedules_overlap_faults_and_reach_main_and_neighbours():
    """Over a few seeds: faults land on main, several at once, and crash loops occur."""
    ops = [op for seed in range(5) for op in generate(seed, NAMES, duration=60)]
    nodes = {op.steps[0]["node"] for op in ops}
    assert "main" in nodes and len(nodes - {"all"}) == len(NAMES)
    starts = sorted(op.start for op in ops)
    assert any(b - a < 0.1 for a, b in itertools.pairwise(starts))  # several at once
    assert any(sum(1 for s in op.steps if s["kind"] == "crash") >= 2 for op in ops)  # crash loops


def test_kinds_restrict_the_operations():
    ops = generate(3, NAMES, duration=60, kinds=["lose"])
    assert ops and {step["kind"] for op in ops for step in op.steps} == {"lose"}
    assert set(OPERATIONS) >= {"crash", "crashloop", "partition"}


def test_shrinking_finds_the_two_operations_that_fail_together():
    ops = [Operation(({"at": float(i), "node": "main", "kind": "lose"},)) for i in range(16)]
    calls = []

    def fails(candidate: list[Operation]) -> bool:
        calls.append(len(candidate))
        return ops[3] in candidate and ops[11] in candidate

    smallest, runs = shrink(ops, fails, max_runs=100)
    assert smallest == [ops[3], ops[11]]
    assert runs == len(calls) <= 100


def test_shrinking_stops_at_its_budget_with_a_schedule_that_still_failed():
    ops = [Operation(({"at": float(i), "node": "main", "kind": "lose"},)) for i in range(16)]
    smallest, runs = shrink(ops, lambda c: ops[7] in c, max_runs=3)
    assert runs == 3 and ops[7] in smallest and len(smallest) < 16


def _ledger(directory, node, run, pid, lines, stop=True):
    entries = [{"ev": "start", "node": node, "run": run, "pid": pid, "t": lines[0]["t"] - 1 if lines else 0}]
    entries += lines
    if stop:
        entries.append({"ev": "stop", "t": entries[-1]["t"] + 1})
    (directory / f"ledger-{node}-{pid}.jsonl").write_text("".join(json.dumps(e) + "\n" for e in entries))


def test_the_ledger_checker_finds_lost_duplicated_and_phantom_commands(tmp_path):
    send = lambda n, t: {"ev": "send", "to": 20, "run": 5, "n": n, "t": t}  # noqa: E731
    outcome = lambda n, r, t: {"ev": "outcome", "to": 20, "n": n, "result": r, "t": t}  # noqa: E731
    take = lambda n, t, run=5: {"ev": "take", "from": 10, "run": run, "n": n, "t": t}  # noqa: E731
    _ledger(
        tmp_path, 10, 5, 100,
        [send(1, 10), outcome(1, "acked", 11), send(2, 12), outcome(2, "acked", 13),
         send(3, 14), outcome(3, "unacked", 15), send(4, 16), outcome(4, "acked", 17)],
    )  # fmt: skip
    # the receiver's first incarnation takes 1 and 3, a second one takes 1 again, 4, and a phantom
    _ledger(tmp_path, 20, 8, 200, [take(1, 10.5), take(3, 14.5)], stop=False)
    _ledger(tmp_path, 20, 9, 201, [take(1, 16.0), take(4, 16.8), take(9, 16.9, run=6)])
    verdict = judge(tmp_path)
    assert (verdict.sent, verdict.acked, verdict.unacked, verdict.taken) == (4, 3, 1, 5)
    assert verdict.duplicated == [(10, 5, 1)]
    assert verdict.lost == [(10, 5, 2)]  # acked at 13, receiver 8 lived on to 14.5+1
    assert verdict.phantom == [(10, 6, 9)]
    assert not verdict.ok
    assert verdict.lost_between(12.5, 13.5) == 1 and verdict.lost_between(0, 12) == 0


def test_an_ack_to_a_program_killed_right_after_is_reported_apart(tmp_path):
    _ledger(
        tmp_path, 10, 5, 100,
        [{"ev": "send", "to": 20, "run": 5, "n": 1, "t": 10.0},
         {"ev": "outcome", "to": 20, "n": 1, "result": "acked", "t": 10.2}],
    )  # fmt: skip
    _ledger(tmp_path, 20, 8, 200, [{"ev": "take", "from": 30, "run": 1, "n": 1, "t": 10.1}], stop=False)
    _ledger(tmp_path, 30, 1, 300, [{"ev": "send", "to": 20, "run": 1, "n": 1, "t": 9.0}])
    verdict = judge(tmp_path)
    assert verdict.lost == [] and verdict.lost_at_receiver_crash == [(10, 5, 1)]
    assert verdict.ok


@pytest.mark.slow
def test_bad_chaos_input_is_one_line_and_exit_2(tmp_path):
    import subprocess

    from tests.support.processes import TOKENRING

    used = tmp_path / "used"
    used.mkdir()
    (used / "ledger-10-1.jsonl").write_text("")
    a_file = tmp_path / "file"
    a_file.write_text("")
    cases = [
        ([], "give a scenario file or --random SEED"),
        (["scenarios/compound.yaml", "--random", "1"], "give a scenario file or --random SEED"),
        (["--random", "-1"], "-1 is not within 0..4294967295"),
        (["--random", "1", "--kinds", "crash,fly"], "unknown operation 'fly'"),
        (["--random", "1", "--duration", "2"], "seconds from 5"),
        (["--random", "1", "--out", str(a_file)], "not a directory"),
        (["--random", "1", "--ring", "r1"], "drop --ring"),
        (["scenarios/compound.yaml", "--ledger", str(used)], "holds ledgers of an earlier run"),
    ]
    for args, message in cases:
        result = subprocess.run(
            [*TOKENRING, "chaos", *args], capture_output=True, text=True, timeout=60, cwd=REPO
        )
        assert result.returncode == 2, (args, result.stderr)
        assert message in result.stderr and "Traceback" not in result.stderr, (args, result.stderr)
        assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file", "used"]  # nothing written
