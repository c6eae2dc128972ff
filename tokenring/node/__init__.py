"""Everything a node process runs: the node OS and its token path, recovery, channels, the
program host, the system commands (``system/``) and main's PC link (``pclink/``). It imports no
host, observer, chaos or benchmark code, so what a node loads at boot is visible from here."""

from __future__ import annotations

from typing import TYPE_CHECKING

from tokenring._face import lazy_face

if TYPE_CHECKING:
    from tokenring.node.pacing import PROFILES
    from tokenring.node.tokenpath import NATIVE
else:  # each name is imported on first use
    __getattr__, __dir__ = lazy_face(
        __name__,
        {
            "NATIVE": "tokenring.node.tokenpath",
            "PROFILES": "tokenring.node.pacing",
        },
    )

__all__ = [
    "NATIVE",
    "PROFILES",
]
