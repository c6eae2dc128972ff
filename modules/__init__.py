"""The eight user programs of the robot (one file per module) and what they share (``common``).

Each ``<module>.py`` defines ``class Program(UserProgram)``; ``tokenring up`` runs it on the
node of the same name. Programs talk to each other only through the token (``self.os``) and to
their hardware only through ``self.hw``.
"""
