"""The ``tokenring`` command line.

Exit codes: 0 success; 1 the run failed (a node died, an invariant broke, a benchmark aim was
missed where asked to fail); 2 bad input (options, files, protocol.yaml); 130 stopped by Ctrl-C.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Callable
from pathlib import Path

from tokenring.errors import TokenRingError, UsageError

Runner = Callable[[argparse.Namespace], int]
_COMMANDS: dict[str, Runner] = {}


def _setup_logging(level: str) -> None:
    logging.basicConfig(
        level=getattr(logging, level.upper(), logging.INFO),
        format="%(asctime)s.%(msecs)03d %(levelname)-5s %(message)s",
        datefmt="%H:%M:%S",
        stream=sys.stderr,
    )


def default_programs_dir() -> Path:
    """The ``modules/`` directory holding the eight user programs."""
    import modules

    return Path(modules.__file__).resolve().parent


# ---------------------------------------------------------------------------------------------
# up


def _add_up(sub: argparse._SubParsersAction) -> None:
    from tokenring.cliutil import add_ring_options

    p = sub.add_parser(
        "up",
        help="launch the whole ring (every node its own process)",
        description="Launch every node of protocol.yaml as its own OS process on one Zenoh network "
        "and supervise them until Ctrl-C, SIGTERM or --duration.",
    )
    p.add_argument("--nodes", help="comma-separated subset of nodes (names or IDs); default all")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    p.add_argument(
        "--bitrate",
        default="2.5M",
        help="emulated ARCNET bitrate, e.g. 2.5M, 10M or max (default %(default)s)",
    )
    p.add_argument(
        "--ack",
        default="adaptive",
        choices=("adaptive", "always", "never"),
        help="pass acknowledgement policy",
    )
    p.add_argument(
        "--programs",
        metavar="DIR",
        help="directory of user programs (default: the modules package)",
    )
    p.add_argument("--no-programs", action="store_true", help="start the nodes with the OS only")
    p.add_argument("--respawn", action="store_true", help="restart nodes that die, like a supervisor")
    add_ring_options(p)
    _COMMANDS["up"] = _run_up


def _run_up(args: argparse.Namespace) -> int:
    from tokenring.launcher import Launcher, install_signal_handlers, plans_from_protocol
    from tokenring.protocol import load_protocol
    from tokenring.ring import parse_bitrate

    protocol = load_protocol(args.protocol)
    parse_bitrate(args.bitrate)  # refuse a bad value before anything starts
    if args.duration is not None and args.duration <= 0:
        raise UsageError("--duration must be positive")
    selection = [s.strip() for s in args.nodes.split(",") if s.strip()] if args.nodes else None
    programs = None if args.no_programs else (args.programs or default_programs_dir())
    if programs is not None and not Path(programs).is_dir():
        raise UsageError(f"--programs {programs}: no such directory")
    plans = plans_from_protocol(protocol, selection, programs)
    launcher = Launcher(
        plans,
        ring=args.ring,
        bitrate=args.bitrate,
        ack_mode=args.ack,
        connect=args.connect or [],
        listen=args.listen or [],
        zenoh_config=args.zenoh_config,
        protocol_path=args.protocol,
        log_level=args.log_level,
        respawn=args.respawn,
    )
    install_signal_handlers(launcher)
    launcher.start()
    code = launcher.run(args.duration)
    launcher.say("stopped (interrupted)" if code == 130 else f"stopped (exit code {code})")
    return code


# ---------------------------------------------------------------------------------------------
# node


def _add_node(sub: argparse._SubParsersAction) -> None:
    from tokenring.cliutil import add_ring_options
    from tokenring.nodeproc import add_node_arguments

    p = sub.add_parser(
        "node",
        help="run one node (what `up` starts per module)",
        description="Run one node of the ring in this process until SIGINT/SIGTERM.",
    )
    add_node_arguments(p)
    p.add_argument("--bitrate", default="2.5M", help="emulated ARCNET bitrate or max (default %(default)s)")
    p.add_argument("--ack", default="adaptive", choices=("adaptive", "always", "never"))
    add_ring_options(p)
    _COMMANDS["node"] = _run_node


def _run_node(args: argparse.Namespace) -> int:
    from tokenring.nodeproc import run_node

    return run_node(args)


# ---------------------------------------------------------------------------------------------
# status


def _add_status(sub: argparse._SubParsersAction) -> None:
    from tokenring.cliutil import add_json_option, add_ring_options

    p = sub.add_parser("status", help="membership and counters of a running ring")
    p.add_argument("--timeout", type=float, default=2.0, help="seconds to wait for answers")
    add_json_option(p)
    add_ring_options(p, listen=False)
    _COMMANDS["status"] = _run_status


def _run_status(args: argparse.Namespace) -> int:
    from tokenring import keys
    from tokenring.cliutil import format_table, print_json, query, tap_session

    with tap_session(args) as session:
        replies = query(session, keys.control(args.ring, "*", "stats"), timeout=args.timeout)
    nodes = sorted((r["result"] for _, r in replies if r.get("ok")), key=lambda n: n["id"])
    if args.json:
        print_json({"ring": args.ring, "nodes": nodes})
        return 0 if nodes else 1
    if not nodes:
        print(f"no node of ring {args.ring!r} answered", file=sys.stderr)
        return 1
    rows = [
        [
            n["id"],
            n["name"],
            n["successor"],
            n["counter"],
            f"{n['round_ms']['median']:.3f}",
            f"{n['round_ms']['p99']:.3f}",
            f"{n['handler_us']['median']:.1f}",
            n["stats"]["rejected_crc"],
            n["stats"]["reconfigurations"],
            n["program"] or "-",
        ]
        for n in nodes
    ]
    print(
        format_table(
            rows,
            [
                "id",
                "name",
                "next",
                "counter",
                "rtt ms",
                "p99 ms",
                "handler us",
                "crc rej",
                "reconf",
                "program",
            ],
        )
    )
    return 0


# ---------------------------------------------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="tokenring",
        description="An emulated ARCNET token ring robot: eight processes pass one 512-byte token over Zenoh.",
    )
    parser.add_argument("--log-level", default="info", choices=("debug", "info", "warning", "error"))
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for add in _ADDERS:
        add(sub)
    return parser


def _add_sniff(sub: argparse._SubParsersAction) -> None:
    from tokenring import sniff

    sniff.add_parser(sub)
    _COMMANDS["sniff"] = sniff.run


def _add_bench(sub: argparse._SubParsersAction) -> None:
    from tokenring import bench

    bench.add_parser(sub)
    _COMMANDS["bench"] = bench.run


_ADDERS: list[Callable[[argparse._SubParsersAction], None]] = [
    _add_up,
    _add_node,
    _add_status,
    _add_sniff,
    _add_bench,
]


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not args.command:
        parser.print_help()
        return 2
    _setup_logging(args.log_level)
    try:
        return _COMMANDS[args.command](args)
    except TokenRingError as exc:
        print(f"tokenring {args.command}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        return 0


if __name__ == "__main__":
    sys.exit(main())
