"""The live web view of a running ring (``tokenring web``, ``tokenring up --web``): the ring's
nodes, the token, round trips and faults, and the panels an application adds (the robot's room)."""
