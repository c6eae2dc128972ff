"""The simulated world: the robot's hardware and its environment.

The simulator process (``python -m modules.world``, started by ``tokenring up``) runs a room of
:mod:`modules.description`: tracked-robot kinematics driven by half-steps, sonar echo envelopes,
the magnetic field at the compass bridges, two batteries and one clock with a speed-up factor.
Programs reach it only through their hardware clients (:mod:`modules.world.clients`, handed to
them as ``self.hw``) on ``tokenring/<ring>/hw/...``; ground truth goes out on
``tokenring/<ring>/world/truth`` for logs and scoring only.
"""
