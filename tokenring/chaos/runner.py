"""``tokenring chaos SCENARIO.yaml``: a timed list of faults against a ring, judged from the wire.

A scenario (strict YAML, see ``scenarios/``)::

    ring:                 # how to launch the ring (ignored with --ring: use a running one)
      nodes: all          # or a list of names/IDs (with --ring: the nodes to wait for; without,
                          # the running ring's own, as its nodes answer)
      bitrate: max
      ack: adaptive
      respawn: false
      workload: probe     # probe (numbered commands between all nodes) | modules | none
    settle: 2.0           # seconds after the last fault before the end state is judged
    faults:
      - {at: 1.0, node: sonar, kind: crash}
      - {at: 3.0, node: compass, kind: hang}
      - {at: 3.5, node: compass, kind: resume}
      - {at: 5.0, node: all, kind: partition, value: "main,motor,sonar,compass|copro,map,lcd,charger"}
      - {at: 6.0, node: all, kind: heal}

For every fault the report gives the time to recover (the token circulating again through every
node that should be in the ring, in one chain and one epoch — for a partition, through each
side), tokens regenerated, duplicates eliminated (stale tokens and repeated passes dropped),
frames rejected by CRC and commands lost or executed twice; at the end, whether exactly one
token circulates. Exit code 1 if any fault did not recover or an invariant broke.
"""

from __future__ import annotations

import bisect
import functools
import io
import itertools
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import zenoh

from tokenring._util.strict_yaml import read_yaml
from tokenring.chaos.checker import judge as ledger_judge
from tokenring.contract import keys
from tokenring.contract.faults import KINDS, NEEDS_VALUE, parse_partition, validate
from tokenring.contract.protocol import Protocol, default_protocol
from tokenring.errors import TokenRingError, UsageError
from tokenring.host.faults import FaultClient
from tokenring.host.launcher import Launcher, NodePlan
from tokenring.observe.capture import CapturedFrames, first_full_round, passes, settled
from tokenring.transport.session import free_port, query
from tokenring.transport.zenoh_config import make_config, open_session

RING_KEYS = {"nodes", "bitrate", "ack", "respawn", "workload", "downloads"}
#: the latest a fault may be scheduled, seconds from the start (a day, as chaos --duration)
MAX_AT_S = 86_400.0
FAULT_KEYS = {"at", "node", "kind", "value", "jitter", "count", "soft"}
LEDGER_ENV = "TOKENRING_PROBE_LEDGER"  # where the probe programs write their ledgers
INJECT_S = 5.0  # a starved node may take seconds to answer its fault query
FORM_S = 90.0  # eight interpreters starting on a loaded machine can take a minute
SETTLE_MAX_S = 30.0  # how much longer than the settle time a ring may take to converge
#: after a crash or hang takes effect (its answer says when), until its node has surely stopped
EFFECT_MARGIN_S = 0.02
STAT_KEYS = (
    "tokens_regenerated",
    "stale_tokens",
    "replayed_passes",
    "duplicate_passes",
    "rejected_crc",
    "pass_retries",
    "reconfigurations",
)


@dataclass
class FaultStep:
    at: float
    node: str
    kind: str
    request: dict[str, Any]
    line: int


@dataclass
class Scenario:
    source: str
    nodes: list[int]
    #: the scenario names its ring's nodes (else a running ring's are found by asking it)
    nodes_named: bool = False
    bitrate: str = "max"
    ack: str = "adaptive"
    respawn: bool = False
    workload: str = "probe"
    #: main downloads programs into the other nodes all along (virtual time only, so far)
    downloads: bool = False
    settle: float = 2.0
    faults: list[FaultStep] = field(default_factory=list)
    #: how ``tokenring sim`` ran it (``seed``, ``bitrate``, ``profile``): a replay file's; real
    #: processes have no seed to follow and ignore it
    sim: dict[str, Any] = field(default_factory=dict)

    @property
    def duration(self) -> float:
        return (self.faults[-1].at if self.faults else 0.0) + self.settle


def load_scenario(path: str | Path, protocol: Protocol | None = None) -> Scenario:
    """Read and check a scenario; every mistake names the file, line and entry (exit code 2)."""
    protocol = protocol or default_protocol()
    data, lines = read_yaml(path)
    source = str(path)

    def fail(entry: str, problem: str) -> UsageError:
        line = lines.get(entry)
        return UsageError(f"{source}:{line}: {entry}: {problem}" if line else f"{source}: {entry}: {problem}")

    if not isinstance(data, dict):
        raise UsageError(f"{source}: a scenario is a mapping with 'faults' (and optionally 'ring', 'settle')")
    unknown = set(data) - {"ring", "settle", "faults", "sim"}
    if unknown:
        raise fail(sorted(unknown)[0], "unknown key (allowed: ring, settle, faults, sim)")
    ring = data.get("ring") or {}
    if not isinstance(ring, dict):
        raise fail("ring", "expected a mapping")
    unknown = set(ring) - RING_KEYS
    if unknown:
        key = sorted(unknown)[0]
        raise fail(f"ring.{key}", f"unknown key (allowed: {', '.join(sorted(RING_KEYS))})")

    def resolve(item: Any, entry: str) -> int:
        try:
            return protocol.node(int(item) if str(item).isdigit() else str(item)).id
        except Exception:
            known = ", ".join(protocol.nodes)
            raise fail(entry, f"unknown node {item!r} (known: {known})") from None

    node_list = ring.get("nodes", "all")
    if node_list == "all":
        nodes = [n.id for n in protocol.default_nodes]
    elif isinstance(node_list, list) and node_list:
        nodes = sorted({resolve(item, "ring.nodes") for item in node_list})
    else:
        raise fail("ring.nodes", "expected 'all' or a list of node names/IDs")
    scenario = Scenario(source, nodes, nodes_named=node_list != "all")
    scenario.bitrate = str(ring.get("bitrate", "max"))
    from tokenring.contract.ring import parse_bitrate

    try:
        parse_bitrate(scenario.bitrate)
    except UsageError as exc:
        raise fail("ring.bitrate", str(exc)) from None
    scenario.ack = str(ring.get("ack", "adaptive"))
    if scenario.ack not in ("adaptive", "always", "never"):
        raise fail("ring.ack", f"{scenario.ack!r} is not adaptive, always or never")
    respawn = ring.get("respawn", False)
    if not isinstance(respawn, bool):
        raise fail("ring.respawn", f"{respawn!r} is not true or false")
    scenario.respawn = respawn
    downloads = ring.get("downloads", False)
    if not isinstance(downloads, bool):
        raise fail("ring.downloads", f"{downloads!r} is not true or false")
    scenario.downloads = downloads
    scenario.workload = str(ring.get("workload", "probe"))
    if scenario.workload not in ("probe", "modules", "none"):
        raise fail("ring.workload", f"{scenario.workload!r} is not probe, modules or none")
    settle = data.get("settle", 2.0)
    if not isinstance(settle, int | float) or isinstance(settle, bool) or not 0.2 <= settle <= 600:
        raise fail("settle", f"{settle!r} must be a number of seconds 0.2..600")
    scenario.settle = float(settle)
    scenario.sim = _sim_section(data.get("sim"), fail)
    faults = data.get("faults")
    if not isinstance(faults, list) or not faults:
        raise fail("faults", "expected a non-empty list of faults")
    last = 0.0
    by_name = {n.name: n.id for n in protocol.nodes.values()}
    for index, raw in enumerate(faults):
        entry = f"faults.{index}"
        if not isinstance(raw, dict):
            raise fail(entry, "expected a mapping like {at: 1.0, node: sonar, kind: crash}")
        unknown = set(raw) - FAULT_KEYS
        if unknown:
            key = sorted(unknown)[0]
            raise fail(f"{entry}.{key}", f"unknown key (allowed: {', '.join(sorted(FAULT_KEYS))})")
        at = raw.get("at")
        if not isinstance(at, int | float) or isinstance(at, bool) or not 0 <= at <= MAX_AT_S:
            raise fail(f"{entry}.at", f"{at!r} must be a time in seconds from the start, 0..{MAX_AT_S:.0f}")
        if at < last:
            raise fail(f"{entry}.at", f"{at} comes before the previous fault at {last}")
        last = float(at)
        kind = raw.get("kind")
        if kind not in KINDS or kind == "list":
            raise fail(
                f"{entry}.kind",
                f"unknown fault kind {kind!r} (kinds: {', '.join(k for k in KINDS if k != 'list')})",
            )
        node = str(raw.get("node", ""))
        if node != "all":
            resolve(node, f"{entry}.node")
        if kind in NEEDS_VALUE and raw.get("value") is None:
            raise fail(entry, f"{kind} needs a value ({NEEDS_VALUE[kind]})")
        request: dict[str, Any] = {"kind": kind}
        try:
            if kind == "delay":
                request.update(ms=raw["value"], jitter_ms=raw.get("jitter", 0.0))
            elif kind in ("drop", "corrupt"):
                request["p"] = raw["value"]
            elif kind == "partition":
                where = f"{entry}.value"
                request["groups"] = parse_partition(
                    str(raw["value"]), functools.partial(resolve, entry=where)
                )
            elif kind == "lose":
                request["count"] = raw.get("count", 1)
            elif kind == "hang":
                soft = raw.get("soft", False)
                if not isinstance(soft, bool):
                    raise UsageError(f"soft {soft!r} is not true or false")
                request["soft"] = soft
            request = validate(request)
        except UsageError as exc:
            raise fail(entry, str(exc)) from None
        if node != "all" and node not in by_name and not node.isdigit():
            raise fail(f"{entry}.node", f"unknown node {node!r}")
        scenario.faults.append(FaultStep(float(at), node, kind, request, lines.get(entry, 0)))
    return scenario


SIM_KEYS = {"seed", "bitrate", "profile", "frames_sha256"}


def _sim_section(raw: Any, fail: Any) -> dict[str, Any]:
    """The optional ``sim:`` mapping (seed, bitrate, profile) checked, or {} without one."""
    if raw is None:
        return {}
    if not isinstance(raw, dict):
        raise fail("sim", "expected a mapping with seed (and optionally bitrate, profile)")
    unknown = set(raw) - SIM_KEYS
    if unknown:
        key = sorted(unknown)[0]
        raise fail(f"sim.{key}", f"unknown key (allowed: {', '.join(sorted(SIM_KEYS))})")
    seed = raw.get("seed", 1)
    if not isinstance(seed, int) or isinstance(seed, bool) or not 0 <= seed < 2**32:
        raise fail("sim.seed", f"{seed!r} is not a whole number 0..{2**32 - 1}")
    out: dict[str, Any] = {"seed": seed}
    if "bitrate" in raw:
        from tokenring.contract.ring import parse_bitrate

        try:
            rate = parse_bitrate(str(raw["bitrate"]))
        except UsageError as exc:
            raise fail("sim.bitrate", str(exc)) from None
        if rate is None:
            raise fail("sim.bitrate", "max has no wire time: give a bitrate, e.g. 2.5M")
        out["bitrate"] = str(raw["bitrate"])
    profile = raw.get("profile")
    if profile not in (None, "arcnet"):
        raise fail("sim.profile", f"{profile!r} is not arcnet (or absent)")
    out["profile"] = profile
    digest = raw.get("frames_sha256")
    if digest is not None:
        if not (
            isinstance(digest, str) and len(digest) == 64 and all(c in "0123456789abcdef" for c in digest)
        ):
            raise fail("sim.frames_sha256", "expected the 64 hex digits of a SHA-256")
        out["frames_sha256"] = digest
    return out


class WireCapture(CapturedFrames):
    """Every frame on ``token/*`` with its arrival time (``perf_counter``)."""

    def __init__(self, session: zenoh.Session, ring: str) -> None:
        super().__init__()
        self._sub = session.declare_subscriber(keys.token(ring, "*"), self._on)

    def _on(self, sample: zenoh.Sample) -> None:
        self._add(time.perf_counter(), sample.payload.to_bytes())

    def close(self) -> None:
        self._sub.undeclare()


@dataclass
class Membership:
    """Who should be circulating after each fault, followed through the scenario."""

    present: set[int]
    groups: list[list[int]] | None = None

    def apply(self, step: FaultStep, targets: list[int], respawn: bool) -> None:
        kind = step.kind
        if (kind in ("crash",) and not respawn) or kind in ("hang", "leave"):
            self.present -= set(targets)
        elif kind in ("resume", "join"):
            self.present |= set(targets)
        elif kind == "partition":
            self.groups = step.request["groups"]
        elif kind in ("heal", "clear"):
            self.groups = None
            if kind == "clear":
                self.present |= set(targets)

    def expected(self) -> list[set[int]]:
        if self.groups:
            return [set(g) & self.present for g in self.groups if set(g) & self.present]
        return [set(self.present)]


def recovery_time(
    frames: list[tuple[float, bytes]],
    rings: list[set[int]],
    start: float,
    end: float,
    times: Sequence[float] | None = None,
) -> float | None:
    """Seconds from ``start`` until every expected ring has shown a full round (None if never).
    ``times``: the frames' times when they are in order, to find the window by bisection (a
    report judges every fault of a schedule: scanning all frames each time was the judge's
    largest cost in a seed campaign)."""
    if times is not None:
        window = frames[bisect.bisect_left(times, start) : bisect.bisect_left(times, end)]
    else:
        window = [f for f in frames if start <= f[0] < end]
    done = []
    for members in rings:
        if len(rings) > 1:
            sub = [(t, fr) for t, fr in window if fr[0] in members and fr[1] in members]
            seq, _ = passes(sub, drop_stale=False)
        else:
            seq, _ = passes(window)
        at = first_full_round(seq, members, after=start)
        if at is None:
            return None
        done.append(at)
    return max(done) - start


def end_state(
    frames: list[tuple[float, bytes]], rings: list[set[int]], now: float, since_last_fault: float
) -> tuple[list[Any], bool]:
    """Whether exactly one token goes round the expected ring at the end: the last second of
    passes, or the last 2 or 4 s where a round takes longer (a loaded machine), never reaching
    back to the last fault. Returns the passes judged and the verdict."""
    seq: list[Any] = []
    for window in (1.0, 2.0, 4.0):
        if window > since_last_fault and window > 1.0:
            break
        seq, _ = passes([f for f in frames if f[0] >= now - min(window, max(since_last_fault, 0.2))])
        if settled(seq) and len(rings) == 1 and first_full_round(seq[len(seq) // 2 :], rings[0]) is not None:
            return seq, True
    return seq, False


def episodes(
    frames: list[tuple[float, bytes]], steps: list[dict[str, Any]], finished: float
) -> list[tuple[int, int, float | None]]:
    """Faults grouped by overlap, each group judged against what should circulate after its last.

    A fault whose ring has not recovered when the next one lands is still in flight: the two are
    one episode, and the ring to expect is the one after both (two nodes hung at once make one
    ring without either, never the ring without the first alone). Returns ``(first, last,
    recovered_at)`` per episode, ``recovered_at`` a ``perf_counter`` time or None."""
    out = []
    first = 0
    times = [t for t, _ in frames]
    ordered = all(a <= b for a, b in itertools.pairwise(times))  # appends from two threads may not be
    while first < len(steps):
        last = first
        while True:
            start = steps[last]["effective"]
            end = steps[last + 1]["injected"] if last + 1 < len(steps) else finished
            rings = [set(r) for r in steps[last]["expected"]]
            took = (
                recovery_time(frames, rings, start, end, times if ordered else None)
                if rings and start < end
                else None
            )
            if took is not None or last + 1 >= len(steps):
                break
            last += 1
        out.append((first, last, None if took is None else start + took))
        first = last + 1
    return out


def collect_stats(
    session: zenoh.Session, ring: str, expect: set[int] | None = None
) -> dict[int, dict[str, int]]:
    """Every answering node's counters; stops waiting once all of ``expect`` answered, so a hung
    node (which answers nothing) does not hold up the scenario's schedule."""
    out = {}

    def enough(replies: list[tuple[str, Any]]) -> bool:
        answered = {r["result"]["id"] for _, r in replies if r.get("ok")}
        return expect is not None and expect <= answered

    for _, reply in query(session, keys.control(ring, "*", "stats"), timeout=1.5, enough=enough):
        if reply.get("ok"):
            result = reply["result"]
            out[result["id"]] = {k: result["stats"].get(k, 0) for k in STAT_KEYS}
            out[result["id"]]["pid"] = int(result.get("pid", 0))  # which process answered
    return out


def stat_delta(before: dict[int, dict[str, int]], after: dict[int, dict[str, int]], key: str) -> int:
    return sum(
        after[i][key] - before.get(i, {}).get(key, 0)
        for i in after
        if after[i][key] >= before.get(i, {}).get(key, 0)
    )


def collect_probes(session: zenoh.Session, ring: str, nodes: list[int]) -> dict[int, dict[str, Any]]:
    out = {}
    for node_id in nodes:
        replies = query(session, keys.control(ring, node_id, "program"), timeout=1.5)
        if replies and replies[0][1].get("ok"):
            report = replies[0][1]["result"].get("report") or {}
            if "acked" in report:
                out[node_id] = report
    return out


def command_losses(probes: dict[int, dict[str, Any]], protocol: Protocol) -> tuple[int, int]:
    """(lost, duplicated) from the probes' live reports (a ring chaos did not launch, so no
    ledgers): acknowledged numbers missing from what the target took, judged only within the
    span of numbers the target still reports (its memory keeps the last 4000), and numbers
    taken twice."""
    lost = 0
    duplicated = sum(p.get("duplicates", 0) for p in probes.values())
    for sender, report in probes.items():
        for target, n in report.get("acked", []):
            if target not in probes:
                continue  # the target died: its memory of what it took is gone with it
            taken = probes[target]["taken"].get(f"{sender}:{report.get('run')}", [])
            if taken and taken[0] <= n <= taken[-1] and n not in set(taken):
                lost += 1
    return lost, duplicated


def run_scenario(
    scenario: Scenario,
    *,
    ring: str | None = None,
    endpoint: str | None = None,
    progress: Any = None,
    protocol: Protocol | None = None,
    log_file: str | None = None,
    ledger_dir: str | None = None,
) -> dict[str, Any]:
    """Run a scenario against a launched ring (or an existing one) and judge it.

    A launched ring runs the probe with a ledger (``ledger_dir``, else a temporary directory);
    its commands are judged from the ledgers once every node has stopped. A running ring
    (``ring``) is judged from its probes' reports, if it runs the probe."""
    protocol = protocol or default_protocol()
    if scenario.downloads:
        raise UsageError(
            f"{scenario.source}: ring.downloads runs in virtual time only so far: "
            f"tokenring sim --chaos {scenario.source}"
        )
    say = progress or (lambda text: None)
    launcher = None
    scratch = None
    ledger: Path | None = None
    if ring is None:
        port = free_port()
        ring = f"chaos{port}"
        endpoint = f"tcp/127.0.0.1:{port}"
        program = str(Path(__file__).with_name("probe.py")) if scenario.workload == "probe" else None
        if scenario.workload == "probe":
            if ledger_dir is None:
                scratch = tempfile.TemporaryDirectory(prefix="tokenring-ledger-")
                ledger_dir = scratch.name
            ledger = Path(ledger_dir)
            ledger.mkdir(parents=True, exist_ok=True)
        plans = []
        for node_id in scenario.nodes:
            spec = protocol.by_id[node_id]
            path = program
            if scenario.workload == "modules":
                from tokenring import extensions

                directory = extensions.programs_dir()
                candidate = directory / f"{spec.name}.py" if directory is not None else None
                path = str(candidate) if candidate is not None and candidate.exists() else None
            plans.append(NodePlan(node_id, spec.name, path))
        launcher = Launcher(
            plans,
            ring=ring,
            bitrate=scenario.bitrate,
            ack_mode=scenario.ack,
            listen=[endpoint],
            respawn=scenario.respawn,
            output=open(log_file, "w") if log_file else io.StringIO(),  # noqa: SIM115 - the launcher owns it
            log_level="info" if log_file else "warning",
            env={LEDGER_ENV: str(ledger)} if ledger is not None else None,
        )
        say(
            f"launching {len(plans)} nodes on ring {ring} ({endpoint}), bitrate {scenario.bitrate}, ack {scenario.ack}"
        )
        launcher.start()
    connect = [endpoint] if endpoint else [keys.default_endpoint()]
    try:
        try:
            with open_session(make_config(connect=connect)) as session:
                report = _run(session, ring, scenario, protocol, say, launcher, ledger)
        finally:
            if launcher is not None:
                launcher.stop()
        if ledger is not None:
            add_ledger_verdict(report, ledger_judge(ledger))
        return report
    finally:
        if scratch is not None:
            scratch.cleanup()


def add_ledger_verdict(report: dict[str, Any], verdict: Any) -> None:
    """Fill the report's command figures from the ledgers' verdict."""
    for step in report["faults"]:
        step["commands_lost"] = verdict.lost_between(step["wall_from"], step["wall_to"])
        step["commands_duplicated"] = None  # a duplicate is judged over the whole run
    report["commands"] = verdict.as_dict()
    report["end"]["commands_lost"] = len(verdict.lost)
    report["end"]["commands_duplicated"] = len(verdict.duplicated)
    invariants = report["invariants"]
    invariants["no_command_executed_twice"] = not verdict.duplicated
    invariants["no_acknowledged_command_lost"] = not verdict.lost
    invariants["no_command_taken_unsent"] = not verdict.phantom
    report["ok"] = all(invariants.values())


def _quiesce(session: Any, ring: str, ledger: Path, nodes: set[int], say: Any) -> bool:
    """Stop the workload and let the last commands land: every live probe writes 'quiesced'
    once it sends no more and knows the fate of everything it sent."""
    (ledger / "quiesce").touch()
    deadline = time.monotonic() + 10.0
    waiting = set(nodes)
    while waiting and time.monotonic() < deadline:
        latest: dict[int, tuple[float, Path]] = {}
        for path in ledger.glob("ledger-*.jsonl"):
            node = int(path.name.split("-")[1])
            mtime = path.stat().st_mtime
            if node not in latest or mtime > latest[node][0]:
                latest[node] = (mtime, path)
        waiting = {n for n in nodes if n not in latest or '"ev":"quiesced"' not in latest[n][1].read_text()}
        if waiting:
            time.sleep(0.1)
    if waiting:
        say(f"probes on {sorted(waiting)} did not quiesce in 10 s")
    time.sleep(0.3)  # the receivers write down the last commands they took
    return not waiting


def ring_nodes(session: zenoh.Session, ring: str, timeout: float = FORM_S) -> list[int]:
    """The nodes of a running ring: those that answer, once every node any of them sees live
    answers too, the same twice in a row (a ring across hosts is whatever its inventory
    placed, not protocol.yaml's)."""
    deadline = time.monotonic() + timeout
    answering: set[int] = set()
    seen: set[int] = set()
    before: set[int] = set()
    while time.monotonic() < deadline:
        answering, seen = set(), set()
        for _, reply in query(session, keys.control(ring, "*", "stats"), timeout=1.5):
            if reply.get("ok"):
                answering.add(int(reply["result"]["id"]))
                seen.update(int(i) for i in reply["result"].get("live", []))
        if answering and seen <= answering and answering == before:
            return sorted(answering)
        before = answering if seen <= answering else set()
        time.sleep(0.2)
    if not answering:
        raise TokenRingError(
            f"ring {ring}: no node answered in {timeout:.0f} s (is it running, is --ring right?)"
        )
    raise TokenRingError(
        f"ring {ring}: nodes {sorted(seen - answering)} are live but did not answer in {timeout:.0f} s "
        "(name the ring's nodes in the scenario's ring.nodes to wait for them)"
    )


def check_faults_on(scenario: Scenario, ring: str, nodes: list[int], protocol: Protocol) -> None:
    """Refuse a fault on a node the running ring does not have, naming its line."""
    for index, step in enumerate(scenario.faults):
        if step.node == "all":
            continue
        spec = protocol.node(int(step.node) if step.node.isdigit() else step.node)
        if spec.id not in nodes:
            names = ", ".join(protocol.by_id[i].name if i in protocol.by_id else str(i) for i in nodes)
            raise UsageError(
                f"{scenario.source}:{step.line}: faults.{index}.node: {spec.name} is not a node of "
                f"ring {ring} (its nodes: {names})"
            )


def _run(session, ring, scenario, protocol, say, launcher, ledger=None) -> dict[str, Any]:
    if launcher is None and not scenario.nodes_named:
        scenario.nodes = ring_nodes(session, ring)
        check_faults_on(scenario, ring, scenario.nodes, protocol)
        names = ", ".join(protocol.by_id[i].name if i in protocol.by_id else str(i) for i in scenario.nodes)
        say(f"ring {ring}: {len(scenario.nodes)} nodes ({names})")
    deadline = time.monotonic() + FORM_S
    live: dict[int, dict] = {}
    while time.monotonic() < deadline:
        live = collect_stats(session, ring)
        if set(scenario.nodes) <= set(live) and all(live[i]["tokens_regenerated"] >= 0 for i in live):
            break
        time.sleep(0.2)
    else:
        raise TokenRingError(f"ring {ring} did not form in {FORM_S:.0f} s (answering: {sorted(live)})")
    present = set(live) if launcher is None else set(scenario.nodes)
    capture = WireCapture(session, ring)
    time.sleep(1.0)  # a calm second to start from
    client = FaultClient(session, ring, timeout=INJECT_S)
    membership = Membership(set(present))
    known: dict[int, dict[str, int]] = {}  # each node's latest counters
    t0 = time.perf_counter()
    steps: list[dict[str, Any]] = []
    restarting: set[int] = set()  # crashed, respawn on, its new process not heard from yet
    crashed_pid: dict[int, int] = {}  # the process each crash was sent to
    owed: dict[int, list[dict[str, Any]]] = {}  # repairs a hung node missed, sent as it resumes
    hung: set[int] = set()
    for step in scenario.faults:
        wait = t0 + step.at - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
        # only the nodes that can answer are waited for: a hung one keeps its last counters (it
        # is stopped: they cannot move), so the next step's deltas stay its own; a crashed one
        # is restarting until its new process answers
        answering = membership.present - restarting
        fresh = collect_stats(session, ring, answering)
        # back once a *new* process answers: the crashed one answers for a moment after its
        # crash was acknowledged (it exits just after the answer left)
        restarting -= {i for i in fresh if fresh[i]["pid"] != crashed_pid.get(i)}
        known.update(fresh)
        before = dict(known)
        targets = (
            sorted(present - hung - restarting)  # "all": every node that can take a fault now
            if step.node == "all"
            else [protocol.node(int(step.node) if step.node.isdigit() else step.node).id]
        )
        injected, wall = time.perf_counter(), time.time()
        errors, skipped = [], []
        effect_in = 0.0
        if step.node == "all" and step.kind in ("heal", "clear"):
            # a hung node cannot take it now, but the network is healed for it too: it gets
            # the repair as it resumes (else it stays partitioned for good and the ring, which
            # sees it live, keeps trying to pass to it)
            for node_id in hung:
                owed.setdefault(node_id, []).append(step.request)
        for node_id in targets:
            if node_id in restarting:
                # crashed and not back yet: its faults died with its process, and it answers nothing
                skipped.append(f"{node_id}: still restarting after its crash")
                continue
            try:
                answer = client.inject(node_id, step.request)
                effect_in = max(effect_in, float(answer.get("effective_in_s", 0.0)))
            except TokenRingError as exc:  # FaultClient already asked twice where that is harmless
                errors.append(f"{node_id}: {exc}")
            if step.kind == "crash" and scenario.respawn:
                restarting.add(node_id)
                crashed_pid[node_id] = known.get(node_id, {}).get("pid", -1)
            elif step.kind == "hang":
                hung.add(node_id)
            elif step.kind == "resume":
                hung.discard(node_id)
                for request in owed.pop(node_id, []):
                    try:
                        client.inject(node_id, request)
                    except TokenRingError as exc:
                        errors.append(f"{node_id}: {request['kind']} owed since its hang: {exc}")
        # the wire may still carry passes of a node that was told to crash or hang until it
        # acts (its answer says when: tokenring.node.faults.AFTER_REPLY_S): recovery counts from then
        stops = step.kind in ("crash", "hang")
        effective = time.perf_counter() + (effect_in + EFFECT_MARGIN_S if stops else 0.0)
        membership.apply(step, targets, scenario.respawn)
        say(
            f"{injected - t0:6.2f} s  {step.kind:9s} on {step.node}"
            + (f"  ({'; '.join(errors + skipped)})" if errors or skipped else "")
        )
        steps.append(
            {
                "at": step.at,
                "node": step.node,
                "kind": step.kind,
                "targets": targets,
                "injected": injected,
                "effective": effective,
                "wall": wall,
                "expected": [sorted(r) for r in membership.expected()],
                "before": before,
                "errors": errors,
                "skipped": skipped,
            }
        )
    # settle after the last fault has actually landed (a slow step, e.g. a resume, delays it);
    # then, while the ring has not converged yet, wait for it up to SETTLE_MAX_S more: on a
    # loaded machine a respawned node may take seconds to start, and a verdict taken before it
    # could would fail a healthy ring
    time.sleep(
        max(0.0, max(t0 + scenario.duration, steps[-1]["injected"] + scenario.settle) - time.perf_counter())
    )
    rings = membership.expected()
    give_up = time.perf_counter() + SETTLE_MAX_S
    while True:
        frames = capture.snapshot()
        finished, finished_wall = time.perf_counter(), time.time()
        seq, one_token = end_state(frames, rings, finished, finished - steps[-1]["effective"])
        if one_token or finished > give_up:
            break
        time.sleep(0.25)
    if finished - steps[-1]["injected"] > scenario.settle + 1.5:
        say(f"the ring converged {finished - steps[-1]['injected']:.1f} s after the last fault")
    known.update(collect_stats(session, ring, membership.present))
    end_stats = dict(known)
    # commands: the workload stops and its last commands land before anything is compared
    end_probes: dict[int, dict[str, Any]] = {}
    if ledger is not None:
        _quiesce(session, ring, ledger, set(membership.present), say)
    elif scenario.workload == "probe":
        end_probes = collect_probes(session, ring, sorted(membership.present))
    capture.close()
    lost, duplicated = command_losses(end_probes, protocol) if end_probes else (0, 0)
    return build_report(
        ring=ring,
        source=scenario.source,
        frames=frames,
        steps=steps,
        t0=t0,
        finished=finished,
        finished_wall=finished_wall,
        end_stats=end_stats,
        end_passes=len(seq),
        one_token=one_token,
        commands_lost=lost,
        commands_duplicated=duplicated,
        judged_by="ledger" if ledger is not None else ("reports" if end_probes else "none"),
    )


def build_report(
    *,
    ring: str,
    source: str,
    frames: list[tuple[float, bytes]],
    steps: list[dict[str, Any]],
    t0: float,
    finished: float,
    finished_wall: float,
    end_stats: dict[int, dict[str, int]],
    end_passes: int,
    one_token: bool,
    commands_lost: int,
    commands_duplicated: int,
    judged_by: str,
) -> dict[str, Any]:
    """The report of a run (real processes or virtual time): each fault's recovery from the
    frames and its counters' deltas, the end state and the invariants. ``steps`` are the faults
    as applied (``injected``/``effective`` on the frames' clock, ``wall`` on the ledgers')."""
    report_steps = []
    recovered_at: dict[int, tuple[float | None, int]] = {}
    for first, last, at in episodes(frames, steps, finished):
        for index in range(first, last + 1):
            recovered_at[index] = (at, first)
    for index, step in enumerate(steps):
        start = step["injected"]
        after = steps[index + 1]["before"] if index + 1 < len(steps) else end_stats
        at, episode = recovered_at[index]
        report_steps.append(
            {
                "at": step["at"],
                "injected_s": round(start - t0, 3),  # when it really landed (the schedule's "at")
                "node": step["node"],
                "kind": step["kind"],
                "recovered_ms": None if at is None else (at - start) * 1e3,
                "episode": episode,  # faults still in flight together are judged together
                "expected_rings": step["expected"],
                "tokens_regenerated": stat_delta(step["before"], after, "tokens_regenerated"),
                "duplicates_eliminated": stat_delta(step["before"], after, "stale_tokens")
                + stat_delta(step["before"], after, "replayed_passes")
                + stat_delta(step["before"], after, "duplicate_passes"),
                "crc_rejects": stat_delta(step["before"], after, "rejected_crc"),
                "pass_retries": stat_delta(step["before"], after, "pass_retries"),
                "commands_lost": 0,
                "commands_duplicated": 0,
                "wall_from": step["wall"],
                "wall_to": steps[index + 1]["wall"] if index + 1 < len(steps) else finished_wall + 3600,
                "errors": step["errors"],
                "skipped": step["skipped"],
            }
        )
    invariants = {
        "exactly_one_token_at_end": one_token,
        "every_fault_recovered": all(s["recovered_ms"] is not None for s in report_steps),
        "no_command_executed_twice": commands_duplicated == 0,
        "no_acknowledged_command_lost": commands_lost == 0,
        "no_injection_failed": not any(s["errors"] for s in report_steps),
    }
    return {
        "ring": ring,
        "scenario": source,
        "frames_captured": len(frames),
        "faults": report_steps,
        "end": {
            "passes_judged": end_passes,
            "converged_after_last_fault_s": round(finished - steps[-1]["injected"], 3) if one_token else None,
            "commands_lost": commands_lost,
            "commands_duplicated": commands_duplicated,
        },
        "commands_judged_by": judged_by,
        "invariants": invariants,
        "ok": all(invariants.values()),
    }


def format_report(report: dict[str, Any]) -> str:
    """The report as a table per fault, the commands' verdict and the invariants."""
    from tokenring._util.tables import format_table

    rows = []
    modelled = any("model_ms" in s for s in report["faults"])  # virtual time: tokenring.chaos.virtual
    for s in report["faults"]:
        rows.append(
            [
                f"{s['at']:.2f}",
                s["node"],
                s["kind"],
                "-" if s["recovered_ms"] is None else f"{s['recovered_ms']:.1f}",
                s.get("episode", ""),
                s["tokens_regenerated"],
                s["duplicates_eliminated"],
                s["crc_rejects"],
                s["commands_lost"],
            ]
            + ([_model_cell(s)] if modelled else [])
        )
    headers = ["at s", "node", "fault", "recover ms", "episode", "regen", "dup elim", "crc rej", "cmd lost"]
    table = format_table(rows, headers + (["model ms"] if modelled else []))
    commands = report.get("commands")
    summary = ""
    if commands:
        summary = (
            f"\ncommands (from the probes' ledgers, after the workload stopped): sent {commands['sent']}, "
            f"acknowledged {commands['acked']}, not acknowledged {commands['unacked']}, "
            f"not transmitted {commands['untransmitted']}, taken {commands['taken']}; "
            f"lost {commands['lost']}, duplicated {commands['duplicated']}, never sent {commands['phantom']}"
            + (
                f", {commands['lost_at_receiver_crash']} acknowledged to a program killed before it logged them"
                if commands["lost_at_receiver_crash"]
                else ""
            )
            + "\n"
        )
    verdict = "\n".join(
        f"  {'ok  ' if ok else 'FAIL'} {name.replace('_', ' ')}" for name, ok in report["invariants"].items()
    )
    return f"{table}\n{summary}\ninvariants:\n{verdict}\n"


def _model_cell(step: dict[str, Any]) -> str:
    """The timing model's window for a fault it covers, and whether the recovery lay in it."""
    if "model_ms" not in step:
        return ""
    low, high = step["model_ms"]
    return f"{low:.0f}..{high:.0f} {'ok' if step['within_model'] else 'OUT'}"
