"""The ring in virtual time (``tokenring sim``): the same nodes as ``tokenring up``'s, one process,
one virtual clock, deterministic for a seed (issue 55)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from tokenring._face import lazy_face

if TYPE_CHECKING:
    from tokenring.sim.ring import SimRing, SimSummary, run_ring
else:  # each name is imported on first use
    __getattr__, __dir__ = lazy_face(
        __name__,
        {
            "run_ring": "tokenring.sim.ring",
            "SimRing": "tokenring.sim.ring",
            "SimSummary": "tokenring.sim.ring",
        },
    )

__all__ = ["SimRing", "SimSummary", "run_ring"]
