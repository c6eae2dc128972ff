"""``tokenring world generate``: a random but plausible room as a world file, one per seed;
``tokenring world drive``: a random action file that stays inside a room."""

from __future__ import annotations

import argparse
import re

from tokenring.cli import int_within

HELP = "world files: generate a random room, or a drive inside one"

EXAMPLES = """\
examples:
  tokenring world generate --seed 7 --out room7.yaml
  tokenring world generate --seed 7 --size 6200x4600 --out office.yaml
  tokenring up --world room7.yaml --explore 2 --map-out m.json
  tokenring world drive --world room7.yaml --seed 3 --out drive3.txt
  tokenring up --world room7.yaml --actions drive3.txt
"""


#: the sides a generated room may have, in mm (``--size``)
SIDE_MM = (2000, 20000)


def size(text: str) -> tuple[int, int]:
    """An argparse type: ``WIDTHxHEIGHT`` in mm, each within :data:`SIDE_MM`."""
    low, high = SIDE_MM
    match = re.fullmatch(r"(\d{1,9})[xX](\d{1,9})", text.strip())
    if not match:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not WIDTHxHEIGHT in whole mm, each {low}..{high} (e.g. 6200x4600)"
        )
    width, height = int(match.group(1)), int(match.group(2))
    if not (low <= width <= high and low <= height <= high):
        raise argparse.ArgumentTypeError(f"{text!r}: width and height must each be within {low}..{high} mm")
    return width, height


seed = int_within(0, 2**32 - 1)  # argparse types
legs = int_within(1, 100)


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli import with_examples

    p = sub.add_parser(
        "world",
        help=HELP,
        description="World files for the simulated robot.",
        **with_examples(EXAMPLES),
    )
    verbs = p.add_subparsers(dest="world_verb", metavar="VERB", required=True)
    generate = verbs.add_parser(
        "generate",
        help="a random but plausible room (5-14 walls, stubs, pillars), the same for the same seed",
        **with_examples(EXAMPLES),
    )
    generate.add_argument("--seed", type=seed, required=True, help="which room")
    generate.add_argument(
        "--size",
        type=size,
        metavar="WxH",
        help=f"bounding box in mm, each side {SIDE_MM[0]}..{SIDE_MM[1]} (default: drawn, 4000..8000 x 3000..6000)",
    )
    generate.add_argument("--out", metavar="FILE", help="write the world file here (default: print it)")
    generate.add_argument("--force", action="store_true", help="replace an existing --out file")
    drive = verbs.add_parser(
        "drive",
        help="a random action file whose legs keep 450 mm from every wall, the same for the same seed",
        **with_examples(EXAMPLES),
    )
    drive.add_argument("--world", required=True, help="bundled room or world file the drive stays in")
    drive.add_argument("--seed", type=seed, required=True, help="which drive")
    drive.add_argument("--legs", type=legs, default=8, help="turn-and-drive legs, 1..100 (default 8)")
    drive.add_argument("--out", metavar="FILE", help="write the action file here (default: print it)")
    drive.add_argument("--force", action="store_true", help="replace an existing --out file")


def run(args: argparse.Namespace) -> int:
    if args.world_verb == "drive":
        return run_drive(args)
    from modules.description.generate import generate_room, room_yaml
    from modules.description.roomfile import parse_world_yaml
    from tokenring import check_output, option_error, write_atomically

    if args.out:
        check_output(args.out, force=args.force, error=option_error("--out"))
    text = room_yaml(generate_room(args.seed, args.size))
    parse_world_yaml(text, f"generated room {args.seed}")  # the loader's checks, as for any file
    if args.out:
        write_atomically(args.out, text, option_error("--out"))
    else:
        print(text, end="")
    return 0


def run_drive(args: argparse.Namespace) -> int:
    from modules.description import WorldError, load_world
    from modules.description.drives import DriveError, drive_text, generate_drive
    from tokenring import UsageError, check_output, option_error, write_atomically

    if args.out:
        check_output(args.out, force=args.force, error=option_error("--out"))
    try:
        world = load_world(args.world)
        moves = generate_drive(world, args.seed, legs=args.legs)
    except WorldError as exc:
        raise UsageError(f"--world {args.world}: {exc}") from None
    except DriveError as exc:
        raise UsageError(f"--world {args.world}: no drive fits: {exc}") from None
    text = drive_text(moves, f"a random drive (seed {args.seed}, {args.legs} legs) in {world.name}")
    if args.out:
        write_atomically(args.out, text, option_error("--out"))
    else:
        print(text, end="")
    return 0
