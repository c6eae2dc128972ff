"""``tokenring bench --sim``: the round trip and the recovery times from the timing model alone.

The ring runs in virtual time (:func:`tokenring.sim.run_ring`: the node OS on the memory hub, one
task at a time on a simulated clock that only the wire's hop time moves), so what it measures is
what the model makes of the node's rules, the same on any host and for the same seed bit for bit.
One run per ring size: the ring forms, its rounds are timed (every node's time between two of its
visits, pooled), then three faults follow one another, each timed from the fault to the ring
circulating without it (every surviving node visited again, a crashed or frozen node out of every
survivor's active set):

* **lost token** — the next frame on the wire is lost: the highest live ID regenerates the token
  one reconfiguration timeout after it last saw it;
* **crashed node** — a node in the middle vanishes (its liveliness drops at once on the hub): its
  predecessor passes to the next one;
* **frozen node** — another one hangs, live but handling nothing: the token it holds is lost,
  regenerated after the reconfiguration timeout, and the hung node skipped once three passes to it
  go unacknowledged.

Beside each figure, what the model says (:func:`model`), from the constants and rules of
:mod:`tokenring.contract.ring` (``hop_time``, ``Timing._derive``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from tokenring.contract.protocol import Protocol
from tokenring.contract.ring import (
    ARCNET_BITRATE,
    ARCNET_BITS_PER_BYTE,
    ARCNET_ITT_S,
    ARCNET_PACKET_BYTES,
    ARCNET_RECON_TIMEOUT_S,
    ARCNET_RESPONSE_TIMEOUT_S,
    hop_time,
    sorted_percentiles,
)
from tokenring.node.node_os import NodeOS
from tokenring.runtime import SimRuntime
from tokenring.sim import run_ring
from tokenring.sim.model import model
from tokenring.sim.ring import SimRing

SIZES = (2, 8, 32, 128, 255)
FAULTS = ("lost_token", "crash", "freeze")
#: round samples wanted per run, pooled over the nodes (at least :data:`MIN_ROUNDS` rounds)
ROUND_SAMPLES = 1000
MIN_ROUNDS = 3


class SimModelError(RuntimeError):
    """The simulated ring did not do what a run needs (form, recover) in its virtual-time budget."""


def arcnet_figures(bitrate: float) -> dict[str, float]:
    """The ARCNET constants of the timing model (:mod:`tokenring.contract.ring`) at ``bitrate``."""
    scale = ARCNET_BITRATE / bitrate
    return {
        "bitrate": bitrate,
        "packet_bytes": ARCNET_PACKET_BYTES,
        "packet_ms": ARCNET_PACKET_BYTES * ARCNET_BITS_PER_BYTE / bitrate * 1e3,
        "token_pass_us": ARCNET_ITT_S * scale * 1e6,
        "hop_ms": hop_time(bitrate) * 1e3,
        "response_timeout_us": ARCNET_RESPONSE_TIMEOUT_S * scale * 1e6,
        "lost_token_timer_ms": ARCNET_RECON_TIMEOUT_S * scale * 1e3,
    }


def measure(
    protocol: Protocol,
    ids: Sequence[int],
    *,
    bitrate: float,
    profile: str | None = None,
    seed: int = 1,
) -> dict[str, Any]:
    """One ring of ``ids`` in virtual time: its rounds and its recovery from each fault (ms)."""
    n = len(ids)
    expect = model(n, bitrate)
    summary = run_ring(
        protocol,
        ids,
        seed=seed,
        duration_s=0.0,
        bitrate=bitrate,
        profile=profile,
        scenario=_scenario(n, bitrate, expect),
    )
    facts = summary.extra
    return {
        "nodes": n,
        "ids": list(ids),
        "seed": seed,
        "model": expect,
        **facts,
        "regenerations": summary.regenerations,
        "frames": summary.frames,
        "frames_sha256": summary.frames_sha256,
        "simulated_s": round(summary.simulated_s, 6),
        # the scheduler's hand-overs of the baton: the same for a seed, like the figures above
        "switches": summary.switches,
        "real_s": summary.real_s,  # the only host-dependent figure
    }


def _scenario(
    n: int, bitrate: float, expect: dict[str, Any]
) -> Callable[[SimRuntime, SimRing], dict[str, Any]]:
    hop = hop_time(bitrate)
    round_s = n * hop
    # virtual-time budgets: a fault's recovery gets three of its model's upper bounds
    boot_budget = 30.0 + 2 * n * 0.5
    step = hop  # the scenario looks every hop; the times it reports are the nodes' own

    def scenario(sim: SimRuntime, ring: SimRing) -> dict[str, Any]:
        nodes = ring.nodes

        def wait(done: Callable[[], bool], budget: float, what: str) -> None:
            until = sim.monotonic() + budget
            while not done():
                if sim.monotonic() > until:
                    raise SimModelError(f"{n} nodes: {what} not within {budget:.1f} simulated s")
                sim.sleep(step)

        def visited_again(
            survivors: list[int], gone: int | None
        ) -> tuple[Callable[[], bool], dict[int, float]]:
            """A check that every survivor has been visited since now (and none counts ``gone`` as
            active), and the virtual time of each one's first visit since."""
            counts = {i: nodes[i].stats.visits for i in survivors}
            first: dict[int, float] = {}

            def done() -> bool:
                for i in survivors:
                    if i not in first and nodes[i].stats.visits > counts[i]:
                        first[i] = _visit_time(nodes[i], sim)
                if len(first) < len(survivors):
                    return False
                return gone is None or all(gone not in nodes[i].membership.active for i in survivors)

            return done, first

        # the ring forms: every node visited twice
        wait(lambda: all(node.stats.visits >= 2 for node in nodes.values()), boot_budget, "the ring to form")
        formed_at = sim.monotonic()
        # the rounds: every node's own time between two visits, pooled
        rounds = max(MIN_ROUNDS, -(-ROUND_SAMPLES // n))
        start = {i: len(node.timing.rounds) for i, node in nodes.items()}
        sim.sleep(rounds * round_s)
        samples = sorted(s for i, node in nodes.items() for s in node.timing.rounds.as_list()[start[i] :])
        median, p99 = sorted_percentiles(samples, (50, 99), default=float("nan"))
        facts: dict[str, Any] = {
            "formed_s": round(formed_at, 6),
            "round_samples": len(samples),
            "round_median_ms": round(median * 1e3, 6),
            "round_p99_ms": round(p99 * 1e3, 6),
            "round_max_ms": round(samples[-1] * 1e3, 6) if samples else None,
        }
        live = sorted(nodes)
        order = [live[len(live) // 2], live[len(live) // 2 - 1]] if n >= 3 else []
        for kind in FAULTS:
            if kind != "lost_token" and not order:
                facts[f"{kind}_ms"] = None  # a ring of two has no one left to circulate
                continue
            victim = None if kind == "lost_token" else order.pop(0)
            survivors = [i for i in live if i != victim]
            regenerated = sum(node.stats.tokens_regenerated for node in nodes.values())
            done, first = visited_again(survivors, victim)
            at = sim.monotonic()
            if kind == "lost_token":
                ring.hub.drop_frames(1)
            elif kind == "crash":
                assert victim is not None
                ring.hub.crash(victim)
            else:
                assert victim is not None
                nodes[victim].paused = True
                ring.hub.freeze(victim, True)
            upper = expect[f"{kind}_ms"][1] / 1e3
            wait(done, 3 * upper + 10 * round_s + 1.0, f"the ring to recover from a {kind.replace('_', ' ')}")
            facts[f"{kind}_ms"] = round((max(first.values()) - at) * 1e3, 6)
            facts[f"{kind}_regenerations"] = (
                sum(node.stats.tokens_regenerated for node in nodes.values()) - regenerated
            )
            facts[f"{kind}_victim"] = victim
            live = survivors
            sim.sleep(3 * round_s)  # the re-formed ring settles before the next fault
        for node in nodes.values():
            if node.paused:  # thawed, so that it closes like the others
                node.paused = False
                ring.hub.freeze(node.node_id, False)
        return facts

    return scenario


def _visit_time(node: NodeOS, sim: SimRuntime) -> float:
    """When ``node``'s latest visit began (the token path stamps it on the node's clock, the
    simulation's); the scenario's own clock if the node does not say."""
    stamp = getattr(node, "_last_visit", 0.0)
    return float(stamp) if stamp else sim.monotonic()


def _speed(run: dict[str, Any]) -> str:
    """How fast the simulation ran (simulated seconds per real second, the ring's set-up
    included) and the scheduler's hand-overs per frame."""
    real, frames = run["real_s"], run["frames"]
    speed = f"{run['simulated_s'] / real:.0f}x real time" if real > 0 else "no real time"
    return f"{speed}, {run['switches'] / frames:.2f} switches a frame" if frames else speed


def run_sizes(
    protocol: Protocol,
    sizes: Sequence[int],
    ids_for: Callable[[int], list[int]],
    *,
    bitrate: float,
    profile: str | None = None,
    seed: int = 1,
    say: Callable[[str], None] = lambda text: None,
) -> dict[str, Any]:
    """:func:`measure` for each ring size, with the ARCNET figures of the model (``--json``)."""
    runs = []
    for k, n in enumerate(sizes, 1):
        say(f"[{k}/{len(sizes)}] {n} nodes in virtual time ...")
        run = measure(protocol, ids_for(n), bitrate=bitrate, profile=profile, seed=seed)
        say(
            f"        round median {run['round_median_ms']:.3f} ms; {run['simulated_s']:.1f} simulated s "
            f"in {run['real_s']:.1f} real s ({_speed(run)})"
        )
        runs.append(run)
    return {
        "mode": "sim",
        "bitrate": bitrate,
        "profile": profile,
        "seed": seed,
        "arcnet": arcnet_figures(bitrate),
        "runs": runs,
    }
