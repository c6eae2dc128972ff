"""The ring in virtual time (``tokenring sim``): the same nodes as ``tokenring up``'s, one process,
one virtual clock, deterministic for a seed (issue 55)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from tokenring._face import lazy_face

if TYPE_CHECKING:
    from tokenring.sim.programs import LocalPcLink, program_errors, start_programs
    from tokenring.sim.ring import SimRing, SimSummary, run_ring
else:  # each name is imported on first use
    __getattr__, __dir__ = lazy_face(
        __name__,
        {
            "LocalPcLink": "tokenring.sim.programs",
            "program_errors": "tokenring.sim.programs",
            "run_ring": "tokenring.sim.ring",
            "SimRing": "tokenring.sim.ring",
            "SimSummary": "tokenring.sim.ring",
            "start_programs": "tokenring.sim.programs",
        },
    )

__all__ = ["LocalPcLink", "SimRing", "SimSummary", "program_errors", "run_ring", "start_programs"]
