"""Random test drives that stay inside a room: action files nobody tuned the filter for (issue 21).

A drive starts at the room's start pose and is a chain of legs: turn on the spot by a whole
number of degrees, drive straight a whole number of mm. Every leg keeps ``clearance_mm`` from
every wall and obstacle along its whole length (checked every 50 mm against the room's
surfaces, so a leg can neither cross a wall nor graze one), which also keeps the drive inside
the room it started in. The same room and seed give the same drive.

    tokenring world drive --world room7.yaml --seed 3 --out drive3.txt
"""

from __future__ import annotations

import math

import numpy as np

from modules.description.room import World

#: the robot's radius is 190 mm; 450 keeps the front stop and the side sonars out of play
CLEARANCE_MM = 450.0
SAMPLE_MM = 50.0


class DriveError(ValueError):
    """No drive fits: the room has no free straight of ``min_leg_mm`` from where the drive is."""


def _leg_is_free(world: World, x: float, y: float, heading: float, length: float, clearance: float) -> bool:
    n = max(1, math.ceil(length / SAMPLE_MM))
    for i in range(n + 1):
        d = length * i / n
        if world.clearance(x + d * math.cos(heading), y + d * math.sin(heading)) < clearance:
            return False
    return True


def generate_drive(
    world: World,
    seed: int,
    legs: int = 8,
    min_leg_mm: float = 600.0,
    max_leg_mm: float = 3000.0,
    clearance_mm: float = CLEARANCE_MM,
) -> list[tuple[str, int]]:
    """``legs`` pairs of (``r``, degrees) and (``s``, mm) from the world's start pose."""
    rng = np.random.default_rng(seed)
    x, y, heading = world.start.x, world.start.y, world.start.theta
    if world.clearance(x, y) < clearance_mm:
        raise DriveError(
            f"the start pose has {world.clearance(x, y):.0f} mm clearance, under {clearance_mm:.0f}"
        )
    moves: list[tuple[str, int]] = []
    for _ in range(legs):
        for _attempt in range(200):
            turn = int(rng.choice([-1, 1]) * rng.integers(20, 181)) if rng.random() < 0.9 else 0
            length = int(rng.uniform(min_leg_mm, max_leg_mm))
            new_heading = heading + math.radians(turn)
            if _leg_is_free(world, x, y, new_heading, length, clearance_mm):
                break
        else:
            raise DriveError(f"no free leg of {min_leg_mm:.0f} mm or more from ({x:.0f}, {y:.0f})")
        if turn:
            moves.append(("r", turn))
        moves.append(("s", length))
        heading = new_heading
        x, y = x + length * math.cos(heading), y + length * math.sin(heading)
    return moves


def drive_text(moves: list[tuple[str, int]], title: str) -> str:
    """An action file (seed 000's syntax, :mod:`modules.navigation.actions`) for the moves."""
    return "\n".join([f"# {title}", "e", *(f"{kind} {amount}" for kind, amount in moves)]) + "\n"


def drive_end(world: World, moves: list[tuple[str, int]]) -> tuple[float, float, float]:
    """Where the moves end if driven exactly (x mm, y mm, heading rad)."""
    x, y, heading = world.start.x, world.start.y, world.start.theta
    for kind, amount in moves:
        if kind == "r":
            heading += math.radians(amount)
        else:
            x, y = x + amount * math.cos(heading), y + amount * math.sin(heading)
    return x, y, heading
