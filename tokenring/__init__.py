"""tokenring: an emulator of a distributed mobile robot whose modules pass one 512-byte token
around a ring of OS processes over Zenoh (after the Hamburg ARCNET robot, 2001, and the
Darmstadt sensor synchronisation and EKF program, 2004)."""

__version__ = "0.1.0"
