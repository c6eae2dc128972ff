"""``tokenring sim``: the ring in virtual time, one process, deterministic for a seed.

The nodes are the very ones ``tokenring up`` starts (the node OS with its Python token path, its
recovery and membership) on an in-memory wire, run one task at a time by a simulated runtime whose
clock jumps whenever every task waits: a minute of the ring takes a couple of real seconds, and the
same command and seed print the same hash of the whole frame stream (``frames_sha256``), on any
host. The wire's time per hop (``--bitrate``, ``--profile``) is what moves the clock.

``--fault KIND[:NODE[:VALUE]]@T`` applies a kind of ``tokenring fault`` at virtual time T: the
node's own fault injector where the fault acts inside the node (its draws from the seed), the
in-memory wire where the real one acts on the process (crash, hang, resume). The summary lists
each fault with the time until the ring circulated again and the regenerations it cost.

``--chaos SCENARIO`` runs a ``tokenring chaos`` scenario file in virtual time, judged by the same
invariants and ledgers; ``--random A..B`` runs a campaign of seeded schedules (on ``--jobs``
processes), writes each failing seed as a replay file with a shrunk one beside it, and
``--replay FILE`` runs such a file exactly again.
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, Any

from tokenring.cli.args import seconds

if TYPE_CHECKING:
    from tokenring.sim.ring import SimSummary

HELP = "run the ring in virtual time: deterministic, faster than real time"

EXAMPLES = """examples:
  tokenring sim --duration 60                           # the default nodes, a minute of ARCNET
  tokenring sim --nodes 10,20,30 --seed 7 --json run.json
  tokenring sim --profile arcnet --duration 10          # the seed robot's per-visit timing
  tokenring sim --bitrate 10M --duration 600 --json -   # the summary on standard output
  tokenring sim --nodes 10,20,30 --fault crash:20@2 --duration 5   # node 20 dies at 2 s
  tokenring sim --fault hang:sonar@2 --fault resume:sonar@4 --fault drop:main:0.1@6
  tokenring sim --fault 'partition:all:10,20|30,40@2' --fault heal@4 --json -
  tokenring sim --chaos scenarios/compound.yaml          # a chaos scenario, judged in virtual time
  tokenring sim --random 1..1000 --jobs 2                # a campaign of 1000 seeded schedules
  tokenring sim --replay sim-seed17-min.yaml             # a failing seed's schedule, exactly again
"""

DEFAULT_BITRATE = "2.5M"


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli.args import int_within, with_examples

    p = sub.add_parser("sim", help=HELP, description=__doc__, **with_examples(EXAMPLES))
    p.add_argument(
        "--nodes",
        help="comma-separated nodes (names or IDs); default protocol.yaml's nodes but the optional ones",
    )
    p.add_argument(
        "--duration", type=seconds, default=60.0, metavar="S", help="simulated seconds (default %(default)s)"
    )
    p.add_argument("--seed", type=int_within(0, 2**32 - 1), default=1, help="the schedule's seed (default 1)")
    p.add_argument(
        "--bitrate",
        default=DEFAULT_BITRATE,
        help=f"the emulated wire, e.g. 2.5M or 10M; not max: the wire's time moves the clock (default {DEFAULT_BITRATE})",
    )
    p.add_argument(
        "--profile", choices=("arcnet",), help="the seed robot's per-visit timing on top of the wire"
    )
    p.add_argument(
        "--fault",
        action="append",
        default=[],
        metavar="KIND[:NODE[:VALUE]]@T",
        help="apply a fault of 'tokenring fault' at T simulated seconds (repeatable); NODE: a name, "
        "an ID or all (the default); VALUE: delay MS, drop/corrupt/duplicate P, lose COUNT, partition A,B|C,D",
    )
    p.add_argument(
        "--no-world",
        action="store_true",
        help="the ring alone: no world, no programs (the default without the robot's options)",
    )
    p.add_argument(
        "--json", metavar="FILE", help="write the run's summary as JSON to FILE (- for standard output)"
    )
    p.add_argument("--force", action="store_true", help="replace an existing --json FILE")
    p.add_argument("--protocol", metavar="FILE", help="protocol.yaml to use (also $TOKENRING_PROTOCOL)")
    from tokenring.cli import simchaos  # chaos scenarios and seed campaigns: their own module

    simchaos.add_arguments(p)
    # an application's part of the run (the robot's world, programs and mission): its options
    from tokenring import extensions

    for extension in extensions.loaded():
        extension.add_sim_options(p)


def run(args: argparse.Namespace) -> int:
    import json

    from tokenring.cli import simchaos

    if simchaos.wanted(args):
        return simchaos.run(args)

    from tokenring import (
        ChannelError,
        UsageError,
        check_output,
        load_protocol,
        option_error,
        parse_bitrate,
        write_atomically,
    )
    from tokenring.sim import run_ring
    from tokenring.sim.faults import fault_scenario, parse_fault

    if args.json and args.json != "-":
        check_output(args.json, (), force=args.force, error=option_error("--json"))
    protocol = load_protocol(args.protocol)
    if args.nodes:
        try:
            ids = sorted({protocol.node(part.strip()).id for part in args.nodes.split(",") if part.strip()})
        except ChannelError as exc:
            raise UsageError(f"--nodes {args.nodes}: {exc}") from None
    else:
        ids = [n.id for n in protocol.default_nodes]
    if len(ids) < 2:
        raise UsageError(f"--nodes {args.nodes}: a ring needs two nodes at least")
    faults = [parse_fault(text, protocol, ids) for text in args.fault]
    plan = application_plan(args, protocol)
    if plan is not None:
        return run_application(args, protocol, ids, faults, plan)
    summary = run_ring(
        protocol,
        ids,
        seed=args.seed,
        duration_s=args.duration,
        bitrate=parse_bitrate(args.bitrate),
        profile=args.profile,
        scenario=fault_scenario(faults, args.duration) if faults else None,
    )
    data = summary.as_dict()
    if args.json == "-":
        print(json.dumps(data, indent=2))
    else:
        if args.json:
            write_atomically(args.json, json.dumps(data, indent=2) + "\n")
        median = summary.round_median_ms
        print(
            f"{summary.simulated_s:.3f} simulated s in {summary.real_s:.2f} real s ({summary.speedup:.0f}x), "
            f"seed {summary.seed}, nodes {','.join(map(str, summary.nodes))}: {summary.frames} frames, "
            f"round median {'?' if median is None else f'{median:.3f} ms'}, "
            f"{regenerated(summary)}"
        )
        for fault in summary.faults:
            took = fault["recovered_s"]
            print(
                f"  {fault['fault']}: "
                + (
                    "not circulating again by the end"
                    if took is None
                    else f"circulating again after {took * 1000:.3f} ms"
                )
                + ("" if took is None else f", {fault['regenerations']} regeneration(s)")
                + (f" (no answer from {','.join(map(str, fault['skipped']))})" if fault["skipped"] else "")
            )
        print(f"frames_sha256 {summary.frames_sha256}")
    sys.stdout.flush()
    return 0


# -- an application in virtual time (tokenring.extensions.SimPlan: the robot's world and programs) --
def application_plan(args: argparse.Namespace, protocol: Any) -> Any:
    """The first extension's :class:`~tokenring.extensions.SimPlan` for these options, or None."""
    from tokenring import extensions

    for extension in extensions.loaded():
        plan = extension.plan_sim(args, protocol)
        if plan is not None:
            return plan
    return None


def run_application(
    args: argparse.Namespace, protocol: Any, ids: list[int], faults: list[Any], plan: Any
) -> int:
    """Run the ring with an application's scenario (its world, programs and job) in virtual time:
    its nodes added, the wire ``plan.speedup`` times faster, its environment set for the run; the
    ``--fault`` schedule runs beside it. Exit 1 if the application's job failed."""
    import json
    import os

    from tokenring import UsageError, parse_bitrate, write_atomically
    from tokenring.sim import run_ring
    from tokenring.sim.faults import fault_scenario

    if not args.nodes and plan.nodes:
        ids = sorted({*ids, *(protocol.node(name).id for name in plan.nodes)})
    bitrate = parse_bitrate(args.bitrate)
    if bitrate is None:
        raise UsageError("--bitrate max has no wire time: give a bitrate, e.g. 2.5M")
    profile = args.profile or (plan.profile if args.bitrate == DEFAULT_BITRATE else None)
    wire = bitrate * plan.speedup
    schedule = fault_scenario(faults, args.duration) if faults else None
    application = plan.scenario

    def scenario(sim: Any, ring: Any) -> dict[str, Any]:
        fault_facts: dict[str, Any] = {}
        faulting = None
        if schedule is not None:  # the faults on their own task, the application on this one
            faulting = sim.spawn(lambda: fault_facts.update(schedule(sim, ring)), "faults")
        facts = application(sim, ring) if application is not None else {}
        if faulting is not None:  # the schedule runs its --duration out, whenever the job ended
            faulting.join()
        return {**fault_facts, **facts}

    before = {key: os.environ.get(key) for key in plan.env}
    os.environ.update(plan.env)
    try:
        summary = run_ring(
            protocol,
            ids,
            seed=args.seed,
            duration_s=args.duration,
            bitrate=wire,
            profile=profile,
            scenario=scenario,
        )
    finally:
        for key, value in before.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
    data = summary.as_dict()
    for key in [k for k in summary.extra if k.endswith("_sha256")]:  # beside frames_sha256
        data[key] = data["extra"].pop(key)
    if args.json == "-":
        print(json.dumps(data, indent=2))
    else:
        if args.json:
            write_atomically(args.json, json.dumps(data, indent=2) + "\n")
        median = summary.round_median_ms
        print(
            f"{summary.simulated_s:.3f} simulated s in {summary.real_s:.2f} real s ({summary.speedup:.1f}x), "
            f"seed {summary.seed}, nodes {','.join(map(str, summary.nodes))}: {summary.frames} frames, "
            f"round median {'?' if median is None else f'{median:.3f} ms'}, "
            f"{regenerated(summary)}"
        )
        for line in plan.report(summary.extra | data) if plan.report is not None else []:
            print(line)
        print(f"frames_sha256 {summary.frames_sha256}")
    sys.stdout.flush()
    failure = plan.failure(summary.extra) if plan.failure is not None else None
    if failure:
        print(f"failed: {failure}", file=sys.stderr)
        return 1
    return 0


def regenerated(summary: SimSummary) -> str:
    """The tokens the nodes made, the ring's first told apart from the ones that replaced one."""
    first = summary.regenerations - summary.reconfigurations
    made = f"{summary.reconfigurations} regeneration(s)"
    return made + (
        " after the first token" if first == 1 else f" and {first} first token(s)" if first else ""
    )
