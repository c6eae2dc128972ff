"""The simulated world: the robot's hardware and its environment.

``load_world(name_or_path)`` reads a room (bundled: ``empty``, ``office``, ``square``, ``slanted``;
or a YAML world file, or the seed's wall file). The simulator process (``python -m
tokenring.world``, started by ``tokenring up``) runs the room: tracked-robot kinematics driven by
half-steps, sonar echo envelopes, the magnetic field at the compass bridges, two batteries and
one clock with a speed-up factor. Modules reach it only through their hardware clients
(:mod:`tokenring.hw`) on ``tokenring/<ring>/hw/...``; ground truth goes out on
``tokenring/<ring>/world/truth`` for logs and scoring only.
"""

from tokenring.world.loader import DEFAULT_WORLD, WorldError, bundled_worlds, load_world
from tokenring.world.model import Anomaly, Batteries, Circle, Floor, Pose, Wall, World

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
