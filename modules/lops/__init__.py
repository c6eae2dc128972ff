"""LOPS, the Darmstadt robot's external positioning system (seed 000 §3.5, §6.2.5), on a PC beside the ring.

The MCU triggers a measurement every 98 ms by radio; the robot's transmitter answers with
ultrasound; three receivers in the room time its arrival. ``lopscpp`` on the stationary LOPS PC
turns the times into distances, trilaterates, filters outliers and sends each measurement to the
robot over WLAN. Here:

* :mod:`modules.lops.config` — the seed's ``[LOPS]`` configuration section;
* :mod:`modules.lops.mcu` — the hardware: times of flight from the room's geometry (the world);
* :mod:`modules.lops.lopscpp` — the LOPS PC's processing: distances, trilateration, the filter;
* :mod:`modules.lops.packets` — tables 6.1 and 6.2, the packets on the wire (imports nothing else:
  a reader on the robot's side may import it alone);
* :mod:`modules.lops.wlan` — the WLAN link's delay, so that the cycle seen on the robot is the seed's;
* :mod:`modules.lops.system` — the chain in one piece, and the seed's test drive;
* :mod:`modules.lops.service` — ``python -m modules.lops``: the chain as a Zenoh process.
* :mod:`modules.lops.receiver` — the robot's side: copro's WLAN receiver of the packets.

This package imports nothing at its top, so that importing the packets pulls in no world.
"""
