"""The PC side that acts on a running ring: the launcher and its children, the other hosts of a
ring across hosts (the inventory, their shares over ssh), program download, the PC link to
main, fault requests, the deployment's certificates."""

from __future__ import annotations

from typing import TYPE_CHECKING

from tokenring._face import lazy_face

if TYPE_CHECKING:
    from tokenring._util.process import die_with_parent
    from tokenring.host.faults import FaultClient
    from tokenring.host.launcher import Launcher, NodePlan, plans_from_protocol
    from tokenring.host.loader import Loader
    from tokenring.host.pclink import PcLink, open_link
    from tokenring.host.regeneration import format_rates, ring_rates
    from tokenring.host.services import ServicePlan
    from tokenring.node.regeneration import per_hour
else:  # each name is imported on first use
    __getattr__, __dir__ = lazy_face(
        __name__,
        {
            "die_with_parent": "tokenring._util.process",
            "FaultClient": "tokenring.host.faults",
            "format_rates": "tokenring.host.regeneration",
            "Launcher": "tokenring.host.launcher",
            "Loader": "tokenring.host.loader",
            "NodePlan": "tokenring.host.launcher",
            "open_link": "tokenring.host.pclink",
            "PcLink": "tokenring.host.pclink",
            "per_hour": "tokenring.node.regeneration",
            "plans_from_protocol": "tokenring.host.launcher",
            "ring_rates": "tokenring.host.regeneration",
            "ServicePlan": "tokenring.host.services",
        },
    )

__all__ = [
    "FaultClient",
    "Launcher",
    "Loader",
    "NodePlan",
    "PcLink",
    "ServicePlan",
    "die_with_parent",
    "format_rates",
    "open_link",
    "per_hour",
    "plans_from_protocol",
    "ring_rates",
]
