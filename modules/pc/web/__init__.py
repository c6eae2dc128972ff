"""The robot's part of the web view (:mod:`tokenring.web`): its panel (the room with the walls,
the map growing, the sonar beams, the true and estimated pose, the LCD) and its buttons
(Explore 1, Explore 2, stop), handed to the ring through ``RobotExtension.web_panels`` and
``web_actions``. The panel reads the robot's feed topics (:mod:`modules.pc.feed`)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from tokenring import WebAction, WebPanel

STATIC = Path(__file__).resolve().parent / "static"


def panels() -> list[WebPanel]:
    """The room panel: ``static/panel.js`` (a plain ES module, no build step)."""
    return [WebPanel("robot", STATIC, "panel.js", "The robot")]


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
