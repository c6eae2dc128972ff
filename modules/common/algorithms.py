"""Which algorithms each module runs: the 2001 robot's (``seed``) or today's (``ours``).

``tokenring up --algorithms seed`` shows the Hamburg robot as it was, flaws included;
``--algorithms sonar=seed`` switches one module alone, to see what its improvement buys. The
choice reaches every program through its environment (:data:`ENV`), so a program reads it
once at start with :func:`algorithm`; nothing else in the ring knows of it.

Grammar: comma-separated items, each ``seed``/``ours`` (every module) or ``MODULE=seed|ours``;
later items override earlier ones (``seed,copro=ours``: the seed's robot with our copro).
"""

from __future__ import annotations

import os

from tokenring.errors import UsageError

#: the modules that have both the seed's algorithm and ours
MODULES = ("sonar", "copro", "main", "motor")
CHOICES = ("seed", "ours")
ENV = "TOKENRING_ALGORITHMS"
OPTION = "--algorithms"


def parse_algorithms(text: str) -> dict[str, str]:
    """``seed``, ``ours`` or ``MODULE=seed|ours`` items as a choice per module (one clear
    :class:`UsageError` naming the bad item otherwise)."""
    choice = dict.fromkeys(MODULES, "ours")
    items = [item.strip() for item in text.split(",")]
    if not any(items):
        raise UsageError(f"{OPTION}: give seed, ours or MODULE=seed|ours (modules: {', '.join(MODULES)})")
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
            choice = dict.fromkeys(MODULES, value)
        elif module in MODULES:
            choice[module] = value
        else:
            raise UsageError(
                f"{OPTION} {item!r}: no module {module!r} with a seed algorithm (modules: {', '.join(MODULES)})"
            )
    return choice


def format_algorithms(choice: dict[str, str]) -> str:
    """The canonical text of a choice (``sonar=seed,copro=ours,...``), as :data:`ENV` carries it."""
    return ",".join(f"{module}={choice[module]}" for module in MODULES)


def all_seed(choice: dict[str, str]) -> bool:
    """Every module runs the seed's algorithm: the 2001 robot as it was."""
    return all(choice[module] == "seed" for module in MODULES)


def algorithm(module: str, environ: dict[str, str] | None = None) -> str:
    """``seed`` or ``ours`` for ``module`` in this program (``ours`` unless the ring chose the
    seed's). The launcher checked the text; a program started by hand with a bad one runs ours."""
    text = (os.environ if environ is None else environ).get(ENV, "")
    if not text:
        return "ours"
    try:
        return parse_algorithms(text)[module]
    except (UsageError, KeyError):
        return "ours"
