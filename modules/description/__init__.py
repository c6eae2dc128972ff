"""What the robot and its world both read: the robot's description and the rooms.

* :mod:`modules.description.robot` — the robot's geometry: wheel base, step length, sonar
  mounts, compass axes, the sonar's timing;
* :mod:`modules.description.room` and :mod:`~modules.description.roomfile` — rooms: walls,
  round obstacles, floors, magnetic anomalies, the start pose; ``load_world(name_or_path)``
  reads a bundled room (``empty``, ``office``, ``square``, ``slanted``), a YAML world file or the
  seed's wall file;
* :mod:`modules.description.keys` — the robot's Zenoh keys beside the ring's (hardware, world,
  LCD).

The simulator (:mod:`modules.world`) makes a room real; the programs may be *told* a room (the
known walls a localiser matches against) but never see the simulator. Nothing here imports
either of them.
"""

from modules.description.room import Anomaly, Batteries, Circle, Floor, Pose, Wall, World
from modules.description.roomfile import DEFAULT_WORLD, WorldError, bundled_worlds, load_world

__all__ = [
    "DEFAULT_WORLD",
    "Anomaly",
    "Batteries",
    "Circle",
    "Floor",
    "Pose",
    "Wall",
    "World",
    "WorldError",
    "bundled_worlds",
    "load_world",
]
