"""Faults on a running ring, Jepsen's way: the scenario runner, the seeded nemesis, the
checker of commands, and the probe program the nodes run as workload."""

from __future__ import annotations

from typing import TYPE_CHECKING

from tokenring._face import lazy_face

if TYPE_CHECKING:
    from tokenring.chaos.runner import WireCapture, recovery_time
else:  # each name is imported on first use
    __getattr__, __dir__ = lazy_face(
        __name__,
        {
            "recovery_time": "tokenring.chaos.runner",
            "WireCapture": "tokenring.chaos.runner",
        },
    )

__all__ = [
    "WireCapture",
    "recovery_time",
]
