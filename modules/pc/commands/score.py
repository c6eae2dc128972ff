"""``tokenring score MAP --world WORLD``: how good a map is against the true walls.

coverage (true wall length within 5 cm and 5° of a mapped vector), precision (mapped length
within 5 cm of a true wall), mean orientation error, corners closed. MAP is a file written by
``tokenring map`` (.json) or a DXF.
"""

from __future__ import annotations

import argparse

HELP = "score a map against the true walls of a world"

EXAMPLES = """examples:
  tokenring score office.json --world office
  tokenring score room7.dxf --world room7.yaml --json
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli import add_json_option, with_examples

    p = sub.add_parser(
        "score",
        **with_examples(EXAMPLES),
        help=HELP,
        description="Coverage, precision, orientation error and closed corners of a map (.json or .dxf) "
        "against a world's true walls.",
    )
    p.add_argument("map", metavar="MAP", help="a map file (.json from tokenring map, or .dxf)")
    p.add_argument("--world", required=True, metavar="NAME|FILE", help="bundled room or world file")
    add_json_option(p)


def run(args: argparse.Namespace) -> int:
    from modules.pc.mapfiles import load_map_file, load_truth
    from modules.pc.mapscore import score_map
    from tokenring.cli import print_json

    world, truth = load_truth(args.world)
    vectors = load_map_file(args.map)
    score = {"map": args.map, "world": world, **score_map(vectors, truth)}
    if args.json:
        print_json(score)
        return 0
    orientation = score["orientation_error_deg"]
    print(f"map {args.map} against {world}: {score['vectors']} vectors, {score['map_length_m']:.2f} m mapped")
    print(f"  coverage           {score['coverage']:7.1%}  of {score['wall_length_m']:.2f} m of true walls")
    print(f"  precision          {score['precision']:7.1%}  of the mapped length")
    print(
        f"  orientation error  {orientation:7.2f}°"
        if orientation is not None
        else "  orientation error      -"
    )
    print(f"  corners closed     {score['corners_closed']:4d} / {score['corners_total']}")
    return 0
