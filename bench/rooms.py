"""Generated rooms for the mapping and localisation benchmarks, with tuning and evaluation apart.

Issue 21 asks for figures on rooms nobody tuned for. The generator's seeds are split once, here:
**tuning rooms** (seeds 101-130) are the ones to run while changing the navigator, the vector
generation or the filter; **evaluation rooms** (seeds 1-30) are the ones the benchmarks report.
A change judged on the evaluation rooms while it is being made is tuning on them; don't.
Seeds 131-160 (localisation) and 161-190 (mapping) were tuned on too, as fresh rooms for a
second look; the evaluation rooms stay 1-30.
"""

from __future__ import annotations

from pathlib import Path

from modules.description.generate import generate_room, room_yaml

TUNING_SEEDS = tuple(range(101, 131))
EVALUATION_SEEDS = tuple(range(1, 31))


def room_seeds(spec: str) -> list[int]:
    """``tuning``, ``evaluation``, ``evaluation:10`` (the first ten), or seeds like ``1,4,7-9``."""
    name, _, count = spec.partition(":")
    sets = {"tuning": TUNING_SEEDS, "evaluation": EVALUATION_SEEDS}
    if name in sets:
        seeds = list(sets[name])
        return seeds[: int(count)] if count else seeds
    seeds: list[int] = []
    for part in spec.split(","):
        lo, _, hi = part.partition("-")
        seeds += list(range(int(lo), int(hi or lo) + 1))
    return seeds


def generated_room(seed: int, directory: Path) -> Path:
    """The world file of generated room ``seed`` in ``directory`` (written once, then reused)."""
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"generated-{seed}.yaml"
    text = room_yaml(generate_room(seed))
    if not path.exists() or path.read_text() != text:
        path.write_text(text)
    return path
