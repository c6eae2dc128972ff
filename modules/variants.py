"""Which algorithms each module runs: the 2001 robot's (``seed``) or today's (``ours``).

``tokenring up --algorithms seed`` shows the Hamburg robot as it was, flaws included;
``--algorithms sonar=seed`` switches one module alone, to see what its improvement buys. The
choice reaches every program through its environment (:data:`ENV`), so a program reads it
once at start with :func:`algorithm`; nothing else in the ring knows of it.

Grammar: comma-separated items, each ``seed``/``ours`` (every part) or ``PART=seed|ours``;
later items override earlier ones (``seed,copro=ours``: the seed's robot with our copro). The
parts are the modules with two algorithms and the robot's ``body``: the seed's has its side sonar
pairs 10 cm apart, ours 16 cm (:func:`modules.description.robot.sonar_mounts`); the world
simulator builds the chosen body and the modules that place sonar readings use its mounts.
"""

from __future__ import annotations

import os

from modules.description.robot import SonarMount, sonar_mounts
from tokenring import UsageError

#: the modules that have both the seed's algorithm and ours
MODULES = ("sonar", "copro", "main", "motor")
#: what ``--algorithms`` chooses for: those modules and the robot's body
PARTS = (*MODULES, "body")
CHOICES = ("seed", "ours")
ENV = "TOKENRING_ALGORITHMS"
OPTION = "--algorithms"


def parse_algorithms(text: str) -> dict[str, str]:
    """``seed``, ``ours`` or ``MODULE=seed|ours`` items as a choice per module (one clear
    :class:`UsageError` naming the bad item otherwise)."""
    choice = dict.fromkeys(PARTS, "ours")
    items = [item.strip() for item in text.split(",")]
    if not any(items):
        raise UsageError(f"{OPTION}: give seed, ours or PART=seed|ours (parts: {', '.join(PARTS)})")
    for item in items:
        if not item:
            raise UsageError(f"{OPTION} {text!r}: an empty item")
        module, sep, value = item.partition("=")
        module, value = module.strip(), value.strip()
        if not sep:
            module, value = "", module
        if value not in CHOICES:
            raise UsageError(f"{OPTION} {item!r}: {value!r} is not seed or ours")
        if not module:
            choice = dict.fromkeys(PARTS, value)
        elif module in PARTS:
            choice[module] = value
        else:
            raise UsageError(
                f"{OPTION} {item!r}: no part {module!r} with a seed version (parts: {', '.join(PARTS)})"
            )
    return choice


def format_algorithms(choice: dict[str, str]) -> str:
    """The canonical text of a choice (``sonar=seed,copro=ours,...``), as :data:`ENV` carries it."""
    return ",".join(f"{part}={choice[part]}" for part in PARTS)


def all_seed(choice: dict[str, str]) -> bool:
    """Every part is the seed's: the 2001 robot as it was."""
    return all(choice[part] == "seed" for part in PARTS)


def algorithm(module: str, environ: dict[str, str] | None = None) -> str:
    """``seed`` or ``ours`` for ``module`` (or ``body``) in this program (``ours`` unless the ring
    chose the seed's). The launcher checked the text; a program started by hand with a bad one
    runs ours."""
    text = (os.environ if environ is None else environ).get(ENV, "")
    if not text:
        return "ours"
    try:
        return parse_algorithms(text)[module]
    except (UsageError, KeyError):
        return "ours"


def body_mounts(environ: dict[str, str] | None = None) -> tuple[SonarMount, ...]:
    """The sonar mounts of the body this ring's robot has (``--algorithms body=seed|ours``)."""
    return sonar_mounts(algorithm("body", environ))
