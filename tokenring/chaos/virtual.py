"""Chaos in virtual time: a ``tokenring chaos`` scenario run on the simulated ring (issue 55).

The scenario files of ``tokenring chaos`` run against :mod:`tokenring.sim`'s ring: the same
nodes, the same probe program on each (:mod:`tokenring.chaos.probe`), the faults applied at
their virtual instants by the nodes' own fault injectors, and the same judges, kept apart from
the system as before: the wire's frames give each fault's recovery and the end state
(:func:`tokenring.chaos.runner.build_report`), the probes' ledgers the commands' fate
(:mod:`tokenring.chaos.checker`). What the launcher and the kernel do to processes is done to the
simulated ones: a crash kills a node at once (its program writes nothing more), respawn boots a
new one after the launcher's delay plus a process start drawn from the seed, a hang freezes it
(SIGSTOP), resume thaws it. The same scenario and seed give the same frames and ledgers.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import math
import os
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tokenring.chaos.checker import judge as ledger_judge
from tokenring.chaos.runner import (
    LEDGER_ENV,
    SETTLE_MAX_S,
    STAT_KEYS,
    Membership,
    Scenario,
    add_ledger_verdict,
    build_report,
    end_state,
)
from tokenring.errors import TokenRingError, UsageError

if TYPE_CHECKING:
    from tokenring.contract.protocol import Protocol
    from tokenring.runtime import SimRuntime
    from tokenring.sim.ring import SimRing, SimSummary

#: a respawned node's process start, from the launcher's respawn until its node runs (seconds,
#: drawn per respawn from the seed): an interpreter and the node's imports on a busy host
BOOT_S = (0.3, 1.2)
#: the ring has formed once every node has seen the token this often
VISITS_FORMED = 3
FORM_S = 30.0  # simulated seconds for the ring to form before the scenario starts
CALM_S = 1.0  # a calm second to start from, as on real processes
QUIESCE_S = 10.0  # for the probes to stop sending and learn the fate of their last commands
LAND_S = 0.3  # then for the receivers to write down the last commands they took
SETTLE_STEP_S = 0.25  # how often the end state is looked at while the ring converges
#: ``ring.downloads``: a download that has not ended by then is stuck (seconds; a whole program
#: moves in a round per chunk, well under a second on eight nodes)
DOWNLOAD_TIMEOUT_S = 30.0
DOWNLOAD_PAUSE_S = 0.2  # between two downloads
DOWNLOAD_BYTES = (200, 6000)  # a downloaded program's size, drawn per download


@dataclass(frozen=True)
class VirtualRun:
    """A scenario's report and the simulation's summary (its frame hash, speed)."""

    report: dict[str, Any]
    summary: SimSummary


@contextlib.contextmanager
def _ledger_env(directory: Path | None) -> Iterator[None]:
    """The probe finds its ledger directory in the environment, as in a node process."""
    before = os.environ.get(LEDGER_ENV)
    if directory is not None:
        os.environ[LEDGER_ENV] = str(directory)
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(LEDGER_ENV, None)
        else:
            os.environ[LEDGER_ENV] = before


@contextlib.contextmanager
def _quiet(logs: str | None) -> Iterator[None]:
    """The simulated nodes' log lines to ``logs`` (a file) or nowhere: a campaign runs thousands."""
    root = logging.getLogger()
    handler: logging.Handler = (
        logging.FileHandler(logs, mode="a", encoding="utf-8") if logs else logging.NullHandler()
    )
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)-7s %(name)s: %(message)s"))
    saved = (root.handlers[:], root.level)
    root.handlers[:] = [handler]
    root.setLevel(logging.INFO if logs else logging.CRITICAL)
    try:
        yield
    finally:
        root.handlers[:], level = saved
        root.setLevel(level)
        handler.close()


def run_virtual(
    scenario: Scenario,
    protocol: Protocol,
    *,
    seed: int,
    bitrate: float,
    profile: str | None = None,
    ledger_dir: str | Path | None = None,
    logs: str | None = None,
    progress: Callable[[str], None] | None = None,
) -> VirtualRun:
    """Run ``scenario`` on a simulated ring from ``seed`` and judge it as ``tokenring chaos`` does.

    The probes' ledgers go to ``ledger_dir`` (else a temporary directory, removed after)."""
    from tokenring.node.program import load_program_file
    from tokenring.sim import run_ring

    if scenario.workload == "modules":
        raise UsageError(
            f"{scenario.source}: ring.workload modules needs the robot's programs and world, which "
            "tokenring sim --chaos does not run yet: use probe or none"
        )
    say = progress or (lambda text: None)
    program = None
    if scenario.workload == "probe":
        program, _ = load_program_file(Path(__file__).with_name("probe.py"))
    with contextlib.ExitStack() as stack:
        if ledger_dir is None and program is not None:
            ledger_dir = stack.enter_context(tempfile.TemporaryDirectory(prefix="tokenring-ledger-"))
        ledger = Path(ledger_dir) if ledger_dir is not None and program is not None else None
        if ledger is not None:
            ledger.mkdir(parents=True, exist_ok=True)
            if any(ledger.glob("ledger-*.jsonl")) or (ledger / "quiesce").exists():
                raise UsageError(f"{ledger}: holds ledgers of an earlier run; give an empty or new directory")
        stack.enter_context(_ledger_env(ledger))
        stack.enter_context(_quiet(logs))
        body = _Body(scenario, program, ledger, say)
        summary = run_ring(
            protocol,
            scenario.nodes,
            seed=seed,
            duration_s=scenario.duration,
            bitrate=bitrate,
            profile=profile,
            scenario=body,
            ack_mode=scenario.ack,
        )
        report = summary.extra.pop("report")
        if ledger is not None:
            add_ledger_verdict(report, ledger_judge(ledger))
    report["virtual"] = {
        "seed": seed,
        "bitrate": bitrate,
        "profile": profile,
        "simulated_s": round(summary.simulated_s, 6),
        "real_s": summary.real_s,
        "speedup": round(summary.speedup, 2),
        "frames": summary.frames,
        "frames_sha256": summary.frames_sha256,
    }
    return VirtualRun(report, summary)


class _Body:
    """The scenario inside the simulation (a :func:`tokenring.sim.run_ring` scenario)."""

    def __init__(
        self, scenario: Scenario, program: type | None, ledger: Path | None, say: Callable[[str], None]
    ):
        self.scenario = scenario
        self.program = program
        self.ledger = ledger
        self.say = say

    def __call__(self, sim: SimRuntime, ring: SimRing) -> dict[str, Any]:
        self.sim, self.ring = sim, ring
        self.frames: list[tuple[float, bytes]] = []
        ring.hub.on_frame = lambda sender, receiver, frame: self.frames.append((sim.now, frame))
        self.rng = sim.rng()  # the respawns' process starts
        self.restarting: dict[int, float] = {}  # killed, respawn on: when its new process starts
        self.booting: set[int] = set()  # its new process started, its node not running yet
        self.dead: set[int] = set()  # killed, respawn off
        for node in ring.nodes.values():
            self._start_program(node)
        self._form()
        self.downloads = _Downloads(self) if self.scenario.downloads else None
        return {"report": self._run()}

    # -- the processes ------------------------------------------------------------------------
    def _start_program(self, node: Any) -> None:
        if self.program is not None:
            node.start_program(self.program)

    def _form(self) -> None:
        deadline = self.sim.now + FORM_S
        nodes = self.ring.nodes
        while not all(n.stats.visits >= VISITS_FORMED for n in nodes.values()):
            if self.sim.now > deadline:
                seen = sorted(i for i, n in nodes.items() if n.stats.visits >= VISITS_FORMED)
                raise TokenRingError(
                    f"the simulated ring did not form in {FORM_S:.0f} s (circulating: {seen})"
                )
            self.sim.sleep(0.01)
        self.sim.sleep(CALM_S)

    def _kill(self, node_id: int) -> None:
        program = self.ring.nodes[node_id].program
        crash = getattr(program, "crash", None)
        if crash is not None:
            crash()  # the ledger ends here: a killed process writes nothing more
        self.ring.kill(node_id)

    def _advance(self, until: float) -> None:
        """Let virtual time run to ``until``, respawning the nodes whose new process is due."""
        while True:
            due = min(self.restarting.values(), default=math.inf)
            if due > until:
                break
            self.sim.sleep(max(0.0, due - self.sim.now))
            for node_id in sorted(i for i, t in self.restarting.items() if t <= self.sim.now):
                del self.restarting[node_id]
                self.booting.add(node_id)
                self.sim.spawn(functools.partial(self._respawn, node_id), f"respawn-{node_id}")
        self.sim.sleep(max(0.0, until - self.sim.now))

    def _respawn(self, node_id: int) -> None:
        """The new process starts its node (which joins the ring) and then its program."""
        self._start_program(self.ring.respawn(node_id))
        self.booting.discard(node_id)

    @property
    def away(self) -> set[int]:
        """Crashed nodes whose new process is not running yet (they answer nothing)."""
        return set(self.restarting) | self.booting

    def _stats(self, ids: set[int]) -> dict[int, dict[str, int]]:
        return {
            i: {key: int(getattr(self.ring.nodes[i].stats, key, 0)) for key in STAT_KEYS}
            for i in sorted(ids)
            if i not in self.dead
        }

    # -- the scenario -------------------------------------------------------------------------
    def _run(self) -> dict[str, Any]:
        sim, ring, scenario = self.sim, self.ring, self.scenario
        protocol = ring.protocol
        present = set(scenario.nodes)
        membership = Membership(set(present))
        known = self._stats(present)
        hung: set[int] = set()
        frozen: set[int] = set()  # hung hard (SIGSTOP): the wire stands still for it
        owed: dict[int, list[dict[str, Any]]] = {}  # repairs a hung node missed, given as it resumes
        steps: list[dict[str, Any]] = []
        t0 = sim.now
        for step in scenario.faults:
            self._advance(t0 + step.at)
            # a hung node answers nothing: it keeps its last counters, as on real processes
            known.update(self._stats(membership.present - self.away - hung))
            before = dict(known)
            targets = (
                sorted(present - hung - self.away)
                if step.node == "all"
                else [protocol.node(int(step.node) if step.node.isdigit() else step.node).id]
            )
            errors: list[str] = []
            skipped: list[str] = []
            if step.node == "all" and step.kind in ("heal", "clear"):
                for node_id in hung:
                    owed.setdefault(node_id, []).append(step.request)
            for node_id in targets:
                if node_id in self.away:
                    skipped.append(f"{node_id}: still restarting after its crash")
                    continue
                if node_id in self.dead:
                    errors.append(f"{node_id}: no answer (crashed, respawn off)")
                    continue
                if node_id in frozen and step.kind != "resume":
                    errors.append(f"{node_id}: no answer (hung)")
                    continue
                self._apply(step.kind, step.request, node_id, hung, frozen, owed)
            in_ring = len(membership.present) if not membership.groups else 0
            membership.apply(step, targets, scenario.respawn)
            self.say(f"{sim.now - t0:6.2f} s  {step.kind:9s} on {step.node}" + (
                f"  ({'; '.join(errors + skipped)})" if errors or skipped else ""
            ))  # fmt: skip
            steps.append(
                {
                    "at": step.at,
                    "node": step.node,
                    "kind": step.kind,
                    "targets": targets,
                    "injected": sim.now,
                    "effective": sim.now,  # the simulated process stops at once
                    "wall": sim.time(),
                    "expected": [sorted(r) for r in membership.expected()],
                    "before": before,
                    "errors": errors,
                    "skipped": skipped,
                    "in_ring": in_ring,  # the nodes circulating as it landed (0: a partition)
                    "request": step.request,
                }
            )
        self._advance(max(t0 + scenario.duration, steps[-1]["injected"] + scenario.settle))
        rings = membership.expected()
        give_up = sim.now + SETTLE_MAX_S
        while True:
            finished = sim.now
            seq, one_token = end_state(self.frames, rings, finished, finished - steps[-1]["effective"])
            if one_token or finished > give_up:
                break
            self._advance(finished + SETTLE_STEP_S)
        finished_wall = sim.time()
        known.update(self._stats(membership.present - self.away - hung))
        end_stats = dict(known)
        frames = list(self.frames)
        if self.downloads is not None:
            self.downloads.stop()
        if self.ledger is not None:
            self._quiesce(membership.present - hung)
        if self.downloads is not None:
            self.downloads.last_round(sorted(membership.present - hung - self.away))
        ring.hub.on_frame = None
        report = build_report(
            ring=f"sim seed {sim.seed}",
            source=scenario.source,
            frames=frames,
            steps=steps,
            t0=t0,
            finished=finished,
            finished_wall=finished_wall,
            end_stats=end_stats,
            end_passes=len(seq),
            one_token=one_token,
            commands_lost=0,
            commands_duplicated=0,
            judged_by="ledger" if self.ledger is not None else "none",
        )
        against_model(report, steps, scenario.respawn, ring.bitrate)
        if self.downloads is not None:
            self.downloads.judge(report)
        return report

    def _apply(
        self,
        kind: str,
        request: dict[str, Any],
        node_id: int,
        hung: set[int],
        frozen: set[int],
        owed: dict[int, list[dict[str, Any]]],
    ) -> None:
        ring = self.ring
        node = ring.nodes[node_id]
        if kind == "crash":
            self._kill(node_id)
            hung.discard(node_id)
            frozen.discard(node_id)
            if self.scenario.respawn:
                # the launcher's respawn delay, then the new process's start
                from tokenring.host.children import RESPAWN_DELAY_S

                self.restarting[node_id] = self.sim.now + RESPAWN_DELAY_S + self.rng.uniform(*BOOT_S)
            else:
                self.dead.add(node_id)
        elif kind == "hang" and not request.get("soft"):
            hung.add(node_id)
            frozen.add(node_id)
            node.paused = True
            ring.hub.freeze(node_id)
        elif kind == "resume":
            if node_id in frozen:
                frozen.discard(node_id)
                node.paused = False
                ring.hub.freeze(node_id, False)
            hung.discard(node_id)
            ring.faults[node_id].handle(request)  # ends a soft hang too
            for repair in owed.pop(node_id, []):
                ring.faults[node_id].handle(repair)
        else:
            if kind == "hang":
                hung.add(node_id)  # soft: the node's own injector holds its token path
            ring.faults[node_id].handle(request)

    def _quiesce(self, nodes: set[int]) -> None:
        """Stop the workload and let the last commands land, as on real processes."""
        assert self.ledger is not None
        (self.ledger / "quiesce").touch()
        deadline = self.sim.now + QUIESCE_S
        waiting = set(nodes)
        while waiting and self.sim.now < deadline:
            waiting = {
                i
                for i in waiting
                if i in self.ring.nodes and not getattr(self.ring.nodes[i].program, "quiesced", True)
            }
            if waiting:
                self._advance(self.sim.now + 0.05)
        if waiting:
            self.say(f"probes on {sorted(waiting)} did not quiesce in {QUIESCE_S:.0f} simulated s")
        self._advance(self.sim.now + LAND_S)


#: faults the timing model covers when they land alone (tokenring.sim.model): a lost token, a
#: frozen node, a crash that nothing restarts
MODELLED = {"lose": "lost_token_ms", "hang": "freeze_ms", "crash": "crash_ms"}


def against_model(report: dict[str, Any], steps: list[dict[str, Any]], respawn: bool, bitrate: float) -> None:
    """Put the timing model's window beside each fault it covers that landed alone (its own
    episode, the whole ring circulating, one token lost): ``model_ms`` and ``within_model``.

    The chaos judge's recovery ends once a whole round went through the ring, the model's once
    every node was visited again: up to one round later, which the window's top gets added."""
    from tokenring.sim.model import model

    judged = within = 0
    for index, (fault, step) in enumerate(zip(report["faults"], steps, strict=True)):
        key = MODELLED.get(fault["kind"])
        alone = fault["episode"] == index and (
            index + 1 == len(steps) or report["faults"][index + 1]["episode"] != index
        )
        if (
            key is None
            or not alone
            or not step["in_ring"]
            or step["node"] == "all"
            or (fault["kind"] == "crash" and respawn)
            or (fault["kind"] == "lose" and step["request"].get("count", 1) != 1)
            or (fault["kind"] == "hang" and step["request"].get("soft"))
            or fault["recovered_ms"] is None
        ):
            continue
        figures = model(step["in_ring"], bitrate)
        low, high = figures[key]
        window = [round(low, 3), round(high + figures["round_ms"], 3)]
        fault["model_ms"] = window
        fault["within_model"] = window[0] <= fault["recovered_ms"] <= window[1]
        judged += 1
        within += fault["within_model"]
    report["timing_model"] = {"judged": judged, "within": within}


class _Downloads:
    """``ring.downloads``: the lowest node (main) downloads programs into the others all along,
    one after another, through the faults, as ``tokenring load`` and ``up`` move programs.

    Judged: a download that says it completed installed exactly the bytes sent; none is stuck
    (every one ends, done or failed, within :data:`DOWNLOAD_TIMEOUT_S`); once the faults are over
    one download into every node in the ring succeeds. One that fails under a fault is allowed:
    the issuer reports it, as the loader does."""

    def __init__(self, body: _Body) -> None:
        self.body = body
        self.issuer = min(body.scenario.nodes)
        self.rng = body.sim.rng()
        self.attempted = self.completed = 0
        self.failed: list[str] = []
        self.corrupted: list[str] = []
        self.stuck: list[str] = []
        self.abandoned = 0  # the issuer itself crashed meanwhile
        self.final: dict[int, str | None] = {}
        self._stopping = False
        self._task = body.sim.spawn(self._loop, "downloads")

    def _loop(self) -> None:
        body = self.body
        while not self._stopping:
            if self.issuer in body.away or self.issuer in body.dead:
                body.sim.sleep(0.1)
                continue
            target = self.rng.choice(sorted(i for i in body.ring.nodes if i != self.issuer))
            self.once(target)
            body.sim.sleep(DOWNLOAD_PAUSE_S)

    def stop(self) -> None:
        """No new download; the one under way ends first."""
        self._stopping = True
        self._task.join()

    def once(self, target: int) -> str | None:
        """One download into ``target``: None if it completed and installed what was sent, else
        why not."""
        from tokenring.node.program import program_sha256

        body = self.body
        system = body.ring.systems[self.issuer]
        source = self._source()
        self.attempted += 1
        stamp_ms = int(body.sim.time() * 1000)
        tx = system.submit(system.download_steps(target, source, stamp_ms), f"download into {target}")
        deadline = body.sim.now + DOWNLOAD_TIMEOUT_S
        while not tx.done.wait(0.5):
            issuer_gone = self.issuer in body.away or self.issuer in body.dead
            if issuer_gone or body.ring.systems.get(self.issuer) is not system:
                self.abandoned += 1  # its issuer died with it: nobody is left to finish it
                return "the issuer crashed"
            if body.sim.now > deadline:
                tx.cancelled = True
                self.stuck.append(f"{target} at {body.sim.now:.3f} s ({tx.what}, step {tx.index})")
                return "stuck"
        if tx.error is not None:
            self.failed.append(f"{target}: {tx.error}")
            return str(tx.error)
        self.completed += 1
        installed = body.ring.systems[target].installed
        digest = program_sha256(source)
        if installed is None or installed.digest != digest:
            got = "nothing" if installed is None else installed.digest.hex()[:12]
            self.corrupted.append(f"{target}: sent {digest.hex()[:12]}, installed {got}")
            return "installed other bytes"
        return None

    def last_round(self, targets: list[int]) -> None:
        """Once the faults are over: one download into every node in the ring."""
        for target in targets:
            if target != self.issuer:
                self.final[target] = self.once(target)

    def _source(self) -> bytes:
        size = self.rng.randint(*DOWNLOAD_BYTES)
        padding = "".join(f"# {self.rng.getrandbits(240):060x}\n" for _ in range(max(1, size // 63)))
        return (
            '"""A program moved by tokenring sim\'s ring.downloads."""\n\n'
            "from tokenring.node.program import UserProgram\n\n\n"
            "class Program(UserProgram):\n    pass\n\n" + padding
        ).encode()

    def judge(self, report: dict[str, Any]) -> None:
        report["downloads"] = {
            "attempted": self.attempted,
            "completed": self.completed,
            "failed": len(self.failed),
            "abandoned_at_issuer_crash": self.abandoned,
            "examples": {"failed": self.failed[:5], "corrupted": self.corrupted[:5], "stuck": self.stuck[:5]},
            "after_the_faults": {str(k): v or "ok" for k, v in self.final.items()},
        }
        invariants = report["invariants"]
        invariants["no_download_installed_other_bytes"] = not self.corrupted
        invariants["no_download_stuck"] = not self.stuck
        invariants["downloads_succeed_after_the_faults"] = bool(self.final) and all(
            v is None for v in self.final.values()
        )
        report["ok"] = all(invariants.values())
