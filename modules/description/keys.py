"""The robot's Zenoh keys, beside the ring's (:mod:`tokenring.contract.keys`) under the same prefix.

=======================================  ========================================================
key                                      what travels on it
=======================================  ========================================================
``tokenring/<ring>/hw/<module>/<what>``  the simulated hardware of one module: ``hw/clock``,
                                         ``hw/motor/steps``, ``hw/motor/power``, ``hw/sonar/ping``,
                                         ``hw/compass/measure``, ``hw/charger/adc``,
                                         ``hw/charger/relay`` (see :mod:`modules.world.service`)
``tokenring/<ring>/world/<what>``        world simulator: ``world/truth`` (msgpack ground truth:
                                         pose mm/rad, batteries, time; logs/scoring only),
                                         ``world/state``, ``world/info``, ``world/control/*``,
                                         ``world/alive`` (liveliness: the world is up)
``tokenring/<ring>/lcd/<what>``          the LCD's screen and keypad (hardware, not the ring)
``tokenring/<ring>/robot/lops/<what>``   LOPS, the external positioning system beside the ring
                                         (:mod:`modules.lops`): ``robot/lops/packets`` (each put
                                         one packet of seed 000 tables 6.1/6.2, raw bytes, as
                                         the robot receives them over WLAN), ``robot/lops/alive``
                                         (liveliness: LOPS is up)
``tokenring/<ring>/robot/localization``  copro's localisation, beside the token (never in it):
                                         ``robot/localization/state`` (msgpack, at most five a
                                         second: :func:`modules.localization.liveview.snapshot`),
                                         ``robot/localization/message`` (each message as it is
                                         said: ``run``, ``n``, ``class``, ``stamp_ms``, ``text``),
                                         ``robot/localization/messages`` (queryable: the backlog,
                                         ``{run, messages}``); nothing without a localizer
``tokenring/<ring>/robot/incomplete/*``  liveliness ``<module>/<what>`` while a module runs
                                         without what it was to keep (``copro/logs``: a log that
                                         a full disk cut short); ``up`` then exits 1
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


def lops(ring: str, what: str) -> str:
    """``tokenring/<ring>/robot/lops/<what>``: LOPS's packets and its liveliness (``packets``, ``alive``)."""
    return f"{keys.PREFIX}/{ring}/robot/lops/{what}"


def localization(ring: str, what: str) -> str:
    """``tokenring/<ring>/robot/localization/<what>``: copro's localisation live (``state``,
    ``message``) and its messages so far (``messages``, a queryable)."""
    return f"{keys.PREFIX}/{ring}/robot/localization/{what}"


def incomplete(ring: str, module: str = "*", what: str = "*") -> str:
    """Liveliness while ``module`` runs without something it was to keep (``what``: ``logs``)."""
    return f"{keys.PREFIX}/{ring}/robot/incomplete/{module}/{what}"
