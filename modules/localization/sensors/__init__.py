"""The Localizer's sensors, one file each (seed 000, chapter 7, made good).

Each module in this folder describes one sensor as a :class:`~modules.localization.sensors.base.Sensor`
and registers it (:func:`register`); importing this package imports every module here, so the
folder is the list — as python-can's ``can/interfaces/`` is a family of buses on one base. A
sensor's file brings its ID (``name``), its log letter, its data channel, its synchroniser, its
default settings, the checks and text formats of its ``R`` and ``C`` records, its position, its
columns of ``data.dat`` and ``data.csv``, its MCAP pose and its analyser plot and summary entry.
Whatever names a sensor elsewhere (:func:`names`, ``logs.SENSOR_SOURCE``, ``config.DEFAULTS``
...) is worked out from the registry, so adding a sensor touches no other file.

=============  ======  ====  ===========================================================
sensor         letter  rank  file
=============  ======  ====  ===========================================================
odometry       O       0     ``odometry.py`` — drives the odometry track and the EKF's prediction
compass        M       10    ``compass.py``
gyro           G       20    ``gyro.py`` (Darmstadt)
correlator     C       30    ``correlator.py`` (Darmstadt)
sonar          W       40    ``sonar.py`` — the walls; its ``sonar.dat`` stays in the logs
battery        B       50    ``battery.py``
truth          T       60    ``truth.py`` — the world's, the analyser's judge, never fused
lops           L       70    ``lops.py`` (Darmstadt)
=============  ======  ====  ===========================================================

What stays in the core (:class:`~modules.localization.localizer.LocalizationCore`) is the
fusion of the eight: the EKF's prediction from the odometry (with the correlator's distance),
the corrections by gyro, compass, LOPS and the sonar's walls, in that order, and their
``filter.*`` and ``lops.*`` settings; a new sensor corrects the filter through its ``fuse`` hook.
The analyser's own plots (paths, errors, steps, heading, sonar, time) stay in
:mod:`modules.pc.analysis`. Adding a sensor: ``docs/darmstadt-sensors.md``, "Adding a sensor".
"""

from __future__ import annotations

import importlib
import pkgutil

from modules.localization.sensors.base import (
    STANDARD_SETTINGS,
    Analysis,
    Fail,
    Sensor,
    SyncContext,
    Synchroniser,
    register,
    registered,
    sensor_named,
    sensor_of_letter,
    sensor_settings,
    unregister,
)

__all__ = [
    "STANDARD_SETTINGS",
    "Analysis",
    "Fail",
    "Sensor",
    "SyncContext",
    "Synchroniser",
    "names",
    "register",
    "registered",
    "sensor_named",
    "sensor_of_letter",
    "sensor_settings",
    "unregister",
]


def names() -> tuple[str, ...]:
    """The registered sensors' names in synchronisation order."""
    return tuple(s.name for s in registered())


def _discover() -> None:
    """Import every sensor module of this folder (each registers its sensor)."""
    for module in pkgutil.iter_modules(__path__):
        if module.name != "base" and not module.name.startswith("_"):
            importlib.import_module(f"{__name__}.{module.name}")


_discover()
