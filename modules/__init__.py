"""The robot: an application of the ring (which knows nothing of it).

* ``<module>.py`` — the eight programs, one per node of protocol.yaml; each defines
  ``class Program(UserProgram)``. They talk to each other only through the token (``self.os``)
  and to their hardware only through ``self.hw``;
* ``common/`` — what the programs share (sync + EKF, walls, vector map, navigation, the LCD UI);
* ``description/`` — what the programs and the world both read: the robot's geometry, rooms;
* ``world/`` — the simulated hardware and rooms (never imported by a program);
* ``pc/`` — the robot's PC-side verbs and their library (drive, explore, map, score, lcd, log,
  replay, analyze);
* ``plugin.py`` — how all this plugs into ``tokenring`` (entry point ``tokenring.extensions``).
"""
