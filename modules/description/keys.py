"""The robot's Zenoh keys, beside the ring's (:mod:`tokenring.contract.keys`) under the same prefix.

=======================================  ========================================================
key                                      what travels on it
=======================================  ========================================================
``tokenring/<ring>/hw/<module>/<what>``  the simulated hardware of one module: ``hw/clock``,
                                         ``hw/motor/steps``, ``hw/sonar/ping``,
                                         ``hw/compass/measure``, ``hw/charger/adc``,
                                         ``hw/charger/relay`` (see :mod:`modules.world.service`)
``tokenring/<ring>/world/<what>``        world simulator: ``world/truth`` (msgpack ground truth:
                                         pose mm/rad, batteries, time; logs/scoring only),
                                         ``world/state``, ``world/info``, ``world/control/*``,
                                         ``world/alive`` (liveliness: the world is up)
``tokenring/<ring>/lcd/<what>``          the LCD's screen and keypad (hardware, not the ring)
=======================================  ========================================================
"""

from __future__ import annotations

from tokenring import keys


def hardware(ring: str, module: str, what: str) -> str:
    return f"{keys.PREFIX}/{ring}/hw/{module}/{what}"


def world(ring: str, what: str) -> str:
    return f"{keys.PREFIX}/{ring}/world/{what}"


def lcd(ring: str, what: str) -> str:
    return f"{keys.PREFIX}/{ring}/lcd/{what}"
