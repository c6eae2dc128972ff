"""``tokenring map --out FILE``: fetch the robot's vector map (GET_MAP through main) and write it.

The format follows the file's extension: ``.json`` (vectors in mm, plus the score when the true
walls are known), ``.dxf`` (ezdxf; layers MAP and TRUTH) or ``.png`` (matplotlib; the vectors
bold, the true walls faint, a 1 m scale bar). Ground truth comes from ``--world`` or, when the
ring runs a world simulator, from its ``world/info``; it is for comparison only. ``--from
MAP.json`` converts a saved map instead of asking the ring.
"""

from __future__ import annotations

import argparse

from tokenring import UsageError
from tokenring.cli import seconds

HELP = "fetch the robot's vector map and write it as DXF, PNG or JSON"

EXAMPLES = """examples:
  tokenring map --out office.dxf                       # the map of the running robot
  tokenring map --out office.png --world office        # drawn over the true room
  tokenring map --from office.json --out office.dxf    # convert a saved map, no ring
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli import add_ring_options, with_examples

    p = sub.add_parser(
        "map",
        **with_examples(EXAMPLES),
        help=HELP,
        description="Ask main for the map (GET_MAP to the map module) and write it; the format "
        "follows the extension of --out (.json, .dxf, .png).",
    )
    p.add_argument("--out", required=True, metavar="FILE", help="where to write the map (.json, .dxf, .png)")
    p.add_argument("--force", action="store_true", help="replace an existing --out file")
    p.add_argument("--world", metavar="NAME|FILE", help="the true room, drawn faintly for comparison")
    p.add_argument("--from", dest="source", metavar="MAP", help="convert a saved map (.json or .dxf)")
    p.add_argument("--timeout", type=seconds, default=60.0, help="seconds to wait for the map (default 60)")
    add_ring_options(p, listen=False)


def run(args: argparse.Namespace) -> int:
    from modules.pc.mapfiles import (
        check_out,
        fetch_map,
        live_world,
        load_map_file,
        load_truth,
        truth_from_info,
        write_map,
    )
    from tokenring.cli import tap_session

    check_out(args.out, "--out", force=args.force, inputs=(args.source,) if args.source else ())
    if args.timeout <= 0:
        raise UsageError("--timeout must be positive")
    world_name, truth = load_truth(args.world) if args.world else (None, None)
    if args.source:
        vectors = load_map_file(args.source)
    else:
        with tap_session(args) as session:
            print("fetching the map (GET_MAP through main) ...", flush=True)
            vectors = fetch_map(session, args.ring, args.timeout)
            if truth is None:
                info = live_world(session, args.ring)
                if info is not None:
                    world_name, truth = truth_from_info(info)
    score = write_map(vectors, args.out, truth, world_name, option="--out")
    line = f"wrote {len(vectors)} vectors to {args.out}"
    if score is not None:
        line += (
            f" (coverage {score['coverage']:.0%}, precision {score['precision']:.0%} against {world_name})"
        )
    print(line)
    return 0
