"""``tokenring load``: the seed's LOAD.EXE — scan the ring, download programs, start/stop them.

    tokenring load                      # just the scan: name, ID, time stamp of every node
    tokenring load -i                   # only programs newer than the node's time stamp
    tokenring load -a                   # every program
    tokenring load -s modules/motor.py  # one program (its node from ``module`` or the file name)
    tokenring load --stop [NODE]        # ARCNET_STOP_SYSTEM, or ARCNET_STOP_PROGRAM of one node
    tokenring load --start [NODE]       # ARCNET_START_SYSTEM, or ARCNET_START_PROGRAM of one node
    tokenring load -u map.dxf           # the robot's: upload the map (.dxf, .png or .json)

Order within one call: scan, stop, downloads, start, then an application's step (the robot's
map upload, ``-u``, added through :mod:`tokenring.extensions`). A node whose program was running
is restarted with its new program (without ``--start``, nodes that were stopped stay stopped).
Exit 0 when everything worked, 1 when a node failed (named with the reason), 2 on bad input.
"""

from __future__ import annotations

import argparse

from tokenring.errors import UsageError

HELP = "download programs over the ring (LOAD.EXE): -i, -a, -s FILE, --start, --stop"

EXAMPLES = """examples:
  tokenring load                      # just the scan: name, ID, time stamp of every node
  tokenring load -i                   # only programs newer than the node's time stamp
  tokenring load -a --start           # every program, then ARCNET_START_SYSTEM
  tokenring load -s modules/motor.py  # one program (its node from ``module`` or the file name)
  tokenring load --stop motor         # ARCNET_STOP_PROGRAM of one node
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli.args import add_json_option, add_ring_options, with_examples

    p = sub.add_parser(
        "load",
        help=HELP,
        description="Scan the ring through main's PC link (name, ID, time stamp of every node), "
        "download programs through the token with a progress bar, start or stop them (and what "
        "an installed application adds, e.g. the robot's map upload -u).",
        **with_examples(EXAMPLES),
    )
    what = p.add_mutually_exclusive_group()
    what.add_argument("-i", "--incremental", action="store_true", help="programs newer than the node's")
    what.add_argument("-a", "--all", action="store_true", help="every program, whatever its age")
    what.add_argument("-s", "--single", metavar="FILE", help="one program file")
    p.add_argument(
        "--start",
        "-start",  # as the seed's LOAD.EXE spelled it (seed 001 §3.5)
        nargs="?",
        const=True,
        default=False,
        metavar="NODE",
        help="start all programs, or NODE's (also -start, the seed's spelling)",
    )
    p.add_argument(
        "--stop", nargs="?", const=True, default=False, metavar="NODE", help="stop all programs, or NODE's"
    )
    p.add_argument(
        "--programs", metavar="DIR", help="program directory for -i/-a (default: the installed application's)"
    )
    p.add_argument("--no-compress", action="store_true", help="send programs as they are (not zlib)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    from tokenring import extensions

    for extension in extensions.loaded():
        extension.add_load_options(p)
    add_json_option(p)
    add_ring_options(p, listen=False)


def _node_arg(value: bool | str, option: str) -> bool | str:
    if value is True or value is False:
        return value
    from tokenring.contract.protocol import default_protocol

    try:
        default_protocol().node(int(value) if value.isdigit() else value)
    except Exception as exc:
        raise UsageError(f"{option} {value}: {exc}") from None
    return value


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from tokenring import extensions
    from tokenring.cli.args import tap_session
    from tokenring.cli.output import print_json
    from tokenring.host.loader import Loader, run_load
    from tokenring.host.pclink import open_link

    mode = "incremental" if args.incremental else "all" if args.all else "single" if args.single else None
    default = extensions.programs_dir()
    programs = Path(args.programs) if args.programs else default
    if mode in ("incremental", "all") and (programs is None or not programs.is_dir()):
        if programs is None:
            raise UsageError("-i/-a need --programs DIR (no installed application has programs)")
        raise UsageError(f"--programs {programs}: no such directory")
    file = Path(args.single) if args.single else None
    if file is not None:
        from tokenring.host.loader import check_program_file

        check_program_file(file)  # a bad file is refused before anything is sent
    start, stop = _node_arg(args.start, "--start"), _node_arg(args.stop, "--stop")
    for extension in extensions.loaded():
        extension.check_load(args)
    with tap_session(args) as session:
        link = open_link(session, args.ring, wait=5.0)
        loader = Loader(
            link,
            progress=False if args.no_progress or args.json else None,
            compress=not args.no_compress,
            say=(lambda text: None) if args.json else None,
        )
        result = run_load(loader, mode=mode, programs_dir=programs, file=file, start=start, stop=stop)
        for extension in extensions.loaded():
            result.update(extension.after_load(args, session, loader.say))
    if args.json:
        result["outcomes"] = [o.as_dict() for o in result["outcomes"]]
        print_json(result)
    return 1 if result["failed"] else 0
