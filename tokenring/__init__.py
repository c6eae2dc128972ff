"""tokenring: an ARCNET-style token ring of OS processes passing one 512-byte token over Zenoh,
after the Hamburg robot's fieldbus (2001). This package is the ring alone and knows nothing of
robots; the robot that runs on it (its programs, its simulated world, its PC tools) lives in
``modules/`` and plugs in through :mod:`tokenring.extensions`."""

__version__ = "0.1.0"
