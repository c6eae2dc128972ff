"""The robot's part of the web view (:mod:`tokenring.web`): its panels (the room with the walls,
the map growing, the sonar beams, the true and estimated pose, the LCD; and the localisation as
the seed's operator's screen showed it: the sensors' raw data, the synchronisation, the position
store, main's action queue, the messages), its buttons (Explore 1, Explore 2, stop) and its keys
(seed table 8.2, :mod:`modules.pc.web.keys`), handed to the ring through ``RobotExtension``'s
``web_panels``, ``web_actions`` and ``web_keys``. The panels read the robot's feed topics
(:mod:`modules.pc.feed`)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from tokenring import WebAction, WebPanel

STATIC = Path(__file__).resolve().parent / "static"


def panels() -> list[WebPanel]:
    """The room and the localisation: ``static/panel.js`` and ``static/localisation.js`` (plain
    ES modules, no build step)."""
    return [
        WebPanel("robot", STATIC, "panel.js", "The robot"),
        WebPanel("localisation", STATIC, "localisation.js", "Localisation"),
    ]


def _explore(action: str) -> Callable[[Any, str], dict[str, Any]]:
    """What ``tokenring explore ACTION`` does, through main's PC link."""

    def run(session: Any, ring: str) -> dict[str, Any]:
        from modules.pc.mission import describe, request
        from tokenring.host import open_link

        state = request(open_link(session, ring), action)
        return {"summary": describe(state), "state": state}

    return run


def actions() -> list[WebAction]:
    """Start Explore 1 (avoid) or 2 (left wall), or stop."""
    return [
        WebAction("explore-1", "Explore 1 (avoid)", _explore("1")),
        WebAction("explore-2", "Explore 2 (left wall)", _explore("2")),
        WebAction("explore-stop", "Stop", _explore("stop")),
    ]
