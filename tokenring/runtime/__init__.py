"""The runtime every wait of the ring goes through: its clock, sleeps, events, locks, conditions,
queues and threads (issue 55).

The real runtime (the default) is the operating system's; the simulated one
(:class:`~tokenring.runtime.sim.SimRuntime`) runs the same code one task at a time on a virtual
clock that jumps whenever every task waits, deterministic for a seed. Code asks for the runtime
in force with :func:`current` where it waits.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from tokenring._face import lazy_face

if TYPE_CHECKING:
    from tokenring.runtime.active import current, using
    from tokenring.runtime.real import RealRuntime
    from tokenring.runtime.sim import Deadlock, SimRuntime
else:  # each name is imported on first use
    __getattr__, __dir__ = lazy_face(
        __name__,
        {
            "current": "tokenring.runtime.active",
            "Deadlock": "tokenring.runtime.sim",
            "RealRuntime": "tokenring.runtime.real",
            "SimRuntime": "tokenring.runtime.sim",
            "using": "tokenring.runtime.active",
        },
    )

__all__ = ["Deadlock", "RealRuntime", "SimRuntime", "current", "using"]
