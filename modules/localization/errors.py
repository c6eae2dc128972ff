"""What the localisation's two configuration readers share: the error they raise and the bound
on a setting's numbers (:mod:`~modules.localization.config` reads the YAML and lays the seed's
file over it, :mod:`~modules.localization.seedconfig` reads the seed's file: neither imports the
other's module for these)."""

from __future__ import annotations

from tokenring import UsageError

#: the largest number a setting may have: every one is a distance, angle, time, count or
#: sigma of a room-sized robot (the defaults are at most 1400), and 1e300 is a typo
MAX_VALUE = 1e9


class ConfigError(UsageError):
    """A bad localisation configuration; the message names file, line and key."""
