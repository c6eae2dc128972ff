"""What every navigator shares: the ``navigator`` state enum of protocol.yaml, the sonar areas'
edges the strategies stop at, and the base class main drives (:meth:`Navigator.plan`)."""

from __future__ import annotations

from modules.mapping.vectorgen import SonarLayout
from modules.navigation.pilot import FORWARD, REVERSE, TURN_LEFT, TURN_RIGHT, Move, Outcome, Sensors
from tokenring import default_protocol

NAV = default_protocol().enums["navigator"]
CLOSE_CM = 12  # the CLOSE area's upper edge
DIAGONAL_STOP_CM = 8  # the ±45° sonars stop a wall-following move only this close (passing a pillar)


class Navigator:
    """Base: the state (``navigator`` enum) and what main needs to know."""

    mode = 0
    #: the pilot keeps this navigator's straight moves clear of remembered echoes (issue 57).
    #: Explore 2 not yet: with it, the reacquire round a small pillar was blocked by echoes of
    #: the pillar's corner placed off it, and the island was never gone round
    keeps_clear = False
    #: main switches a drive that is off on before this navigator's first move: its own jobs are
    #: the Hamburg robot's, whose drive has no switch. An action file does it with its own ``e``
    powers_the_drive = True

    def __init__(self, layout: SonarLayout) -> None:
        self.layout = layout
        self.state = NAV["ENTRY"]
        self.steps = 0
        self.commands: list[tuple[str, str, dict[str, int]]] = []  # extra commands for main to send
        self.note = ""

    def plan(self, last: Outcome | None, sensors: Sensors, alert_lock: int) -> list[Move] | None:
        raise NotImplementedError

    @staticmethod
    def escape(alert_lock: int) -> list[Move]:
        """A small move in the only direction the pilot's ALERT lock allows."""
        if alert_lock in (TURN_LEFT, TURN_RIGHT):
            return [Move(alert_lock, 15, label="escape turn")]
        if alert_lock == FORWARD:
            return [Move(FORWARD, 40, label="escape forward")]
        return [Move(REVERSE, 60, label="escape back")]
