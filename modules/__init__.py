"""The robot: an application of the ring (which knows nothing of it).

* ``<module>.py`` — the eight programs, one per node of protocol.yaml; each defines
  ``class Program(UserProgram)``. They talk to each other only through the token (``self.os``)
  and to their hardware only through ``self.hw``;
* what the programs share, by subject: ``localization/`` (sync, EKF, walls, config, logs, pose
  correction), ``mapping/`` (vector generation, the vector store, GET_MAP), ``navigation/``
  (navigators, pilot, action files, the compass's turn, frontiers), ``sensors/`` (sonar, compass,
  motor and charger arithmetic), ``display/`` (the LCD's screen, menus and boot menu), and
  ``units.py`` (the wire's units), ``variants.py`` (seed or ours per module);
* ``description/`` — what the programs and the world both read: the robot's geometry, rooms;
* ``world/`` — the simulated hardware and rooms (never imported by a program);
* ``pc/`` — the robot's PC-side verbs and their library (drive, explore, map, score, lcd, log,
  replay, analyze, calibrate);
* ``sim/`` — the robot without a ring, on one simulated clock in one process (tests, benchmarks);
* ``plugin.py`` — how all this plugs into ``tokenring`` (entry point ``tokenring.extensions``).
"""
