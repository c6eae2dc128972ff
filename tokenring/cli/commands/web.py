"""``tokenring web``: a live web view of a running ring, in any browser.

The nodes in ring order and who holds the token, the successor chain, the round trip as a
sparkline, each node's counters and faults (with buttons to inject and clear them, through the
same control keys as ``tokenring fault``), and the panels, buttons and keys the application adds
(the robot's room, its map and LCD, its localisation, Explore 1/2, the seed's keys while the page
has the focus). It joins the ring like any tool and never slows the token.
"""

from __future__ import annotations

import argparse

from tokenring.cli.args import int_within, seconds

HELP = "live web view of a running ring (open the printed address in a browser)"

EXAMPLES = """examples:
  tokenring web                               # http://127.0.0.1:8080/ for the default ring
  tokenring web --ring lab -e tcp/10.0.0.5:7447 --port 9000
  tokenring web --host 0.0.0.0                # open to the network (it can inject faults!)
  tokenring web --port 0 --json               # any free port; prints {"ring": ..., "url": ...}
  tokenring web --duration 600                # serve for ten minutes, then exit 0
  tokenring up --explore 2 --web              # the ring and its web view in one command
  tokenring web --action actions/square-3-laps.act   # the robot's key a runs this action file
"""

DEFAULT_PORT = 8080


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli.args import add_json_option, add_ring_options, with_examples

    p = sub.add_parser(
        "web",
        help=HELP,
        description=__doc__,
        **with_examples(EXAMPLES),
    )
    p.add_argument(
        "--port",
        type=int_within(0, 65535),
        default=DEFAULT_PORT,
        help="TCP port to serve on (default %(default)s; 0: any free port)",
    )
    p.add_argument(
        "--host", default="127.0.0.1", help="address to serve on (default %(default)s: this machine only)"
    )
    p.add_argument("--duration", type=seconds, metavar="S", help="stop after S seconds (default: Ctrl-C)")
    from tokenring import extensions  # the extensions' own options (what the page's keys run)

    extensions.add_web_options(p)
    add_json_option(p)
    add_ring_options(p, listen=False)


def run(args: argparse.Namespace) -> int:
    from tokenring.cli.output import print_json
    from tokenring.cli.watcher import Watch, serve
    from tokenring.contract import keys

    def announce(watch: Watch) -> None:
        if args.json:
            print_json({"ring": watch.ring, "url": watch.web_url})
        else:
            print(f"web view of ring {watch.ring!r}: {watch.web_url}  (Ctrl-C stops)")

    watch = Watch(
        ring=keys.check_ring_name(args.ring),
        web_port=args.port,
        host=args.host,
        web_port_option="--port",
        duration=args.duration,
        on_ready=announce,
    )
    return serve(args, watch)
