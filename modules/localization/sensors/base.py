"""A sensor of the Localizer as one description (:class:`Sensor`) and the registry that holds them.

The seed's chapter 7 extended nine places for a new sensor (its IDs, the sensor handler, the data
buffer, the synchronised data, the user interface, the analyser and the converter); here one
:class:`Sensor` says all of it and :func:`register` makes it known: the synchronisation, the
configuration, the logs and their converters, ``tokenring analyze``, ``replay`` and the MCAP
conversion read the registry, never a list of names. See :mod:`modules.localization.sensors`.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

from modules.localization.records import Check, SeedContext, mapping

#: the source letters that are not sensors' (appendix B: the system, the Kalman filter)
RESERVED_LETTERS = {"S": "system", "K": "filter"}
#: what ``sensors.<name>`` holds for every sensor, and the defaults of a sensor that says nothing
#: (table B.1's [Sensors] row: use, synchronise, compute its position, the three logs, the filter)
STANDARD_SETTINGS: dict[str, Any] = {
    "use": False,
    "synchronise": True,
    "position": True,
    "log_raw": True,
    "log_sync": True,
    "log_position": False,
    "filter": False,
    "period_ms": 0,
}


def sensor_settings(**overrides: Any) -> dict[str, Any]:
    """A sensor's ``settings``: :data:`STANDARD_SETTINGS` with ``overrides`` (and its own keys
    after them), in that order — the order ``sensors.<name>`` is written in."""
    return {**STANDARD_SETTINGS, **overrides}


#: how a sensor's ``check_settings`` says a value is bad: ``raise fail(path, problem)``
Fail = Callable[[tuple[str, ...], str], Exception]


class Synchroniser(Protocol):
    """Turns the samples of one buffer half into the synchronised record at ``sync_ms`` (None:
    nothing to say this time)."""

    def synchronise(self, samples: list[Any], sync_ms: int) -> dict[str, Any] | None: ...


@dataclass
class SyncContext:
    """What a sensor's synchroniser is built from: the configuration, the odometry track (the
    dead-reckoned poses the samples are carried to the sync time along), whether the period
    trigger stamps the syncs at grid times, the synchronisers built before (in synchronisation
    order: odometry's first), and the sonar's wall detector and travel gauge (or None)."""

    config: dict[str, Any]
    track: Any
    on_grid: bool
    built: dict[str, Any] = field(default_factory=dict)
    detector: Any = None
    gauge: Any = None


Record = tuple[int, str, dict[str, Any]]  # (stamp_ms, kind R or C, payload) of one sensor


@dataclass(frozen=True)
class Analysis:
    """What ``tokenring analyze`` makes of a sensor (seed §9.2, one analyser module a sensor):
    ``collect`` turns the sensor's ``R`` and ``C`` records, in log order, into its data (None:
    nothing to show); ``summary`` gives the summary's entry under the sensor's name; ``plot``
    draws ``plot_file`` into matplotlib axes (``plot(data, axes, t0_ms)``, times from ``t0_ms``).
    Plain callables: the analyser on the PC imports the sensor, never the other way round."""

    collect: Callable[[list[Record]], Any]
    summary: Callable[[Any], dict[str, Any]] | None = None
    plot: Callable[[Any, Any, float], None] | None = None
    plot_file: str = ""
    figsize: tuple[float, float] = (9.0, 4.0)


@dataclass(frozen=True)
class Sensor:
    """Everything the Localizer and its tools know of one sensor.

    Identity and place: ``name`` (``sensors.<name>`` of the configuration, a sample's sensor),
    ``letter`` (its source in the logs, table B.6), ``title`` (what the logs' readers call the
    source), ``rank`` (synchronisers run in rising rank: odometry's, 0, first — the others carry
    their samples along its track). Input: ``channel`` (the token's data channel the Localizer
    reads it from; None: fed by other means), ``seq_field`` (the field numbering its samples),
    ``value_fields`` (the fields taken; empty: all but ``stamp_ms``). ``synchroniser`` builds its
    synchroniser from a :class:`SyncContext`. Configuration: ``settings`` (``sensors.<name>``'s
    defaults, :data:`STANDARD_SETTINGS` and any of its own), ``check_settings(config, fail)``
    (raise ``fail(path, problem)`` for a bad value), ``sets`` (the ``up --sensors`` sets that
    turn it on).

    Logs: ``raw`` and ``synchronised`` check an ``R`` record's values and a ``C`` record's
    payload; ``text(kind, values)`` is our line body of either (None: ``key=value``),
    ``seed_text(kind, values, context)`` the seed's (None: ours); ``position(core, record)`` the
    position it stores under its letter after a sync (``x``, ``y``, ``psi``, ``valid``; None: none);
    ``dat(payload or None)`` its columns of table B.8's ``data.dat``; ``csv_columns`` and
    ``csv(payload)`` its columns of ``data.csv``. Tools: ``position_name`` and ``colour`` (the
    analyser's), ``pose_topic`` (its MCAP pose), ``analysis`` (:class:`Analysis`). Filter:
    ``fuse(core, record, stamp_ms)`` corrects the core's EKF (``core.ekf``) with a synchronised
    record, after the built-in sensors' corrections, when ``sensors.<name>.filter`` is on.
    """

    name: str
    letter: str
    title: str
    rank: int
    synchroniser: Callable[[SyncContext], Synchroniser]
    channel: str | None = None
    seq_field: str | None = None
    value_fields: tuple[str, ...] = ()
    settings: Mapping[str, Any] = field(default_factory=lambda: dict(STANDARD_SETTINGS))
    check_settings: Callable[[dict[str, Any], Fail], None] | None = None
    sets: tuple[str, ...] = ()
    raw: Check = mapping
    synchronised: Check = mapping
    text: Callable[[str, dict[str, Any]], str] | None = None
    seed_text: Callable[[str, dict[str, Any], SeedContext], str] | None = None
    position: Callable[[Any, dict[str, Any] | None], dict[str, Any] | None] | None = None
    dat: Callable[[dict[str, Any] | None], str] | None = None
    csv_columns: tuple[str, ...] = ()
    csv: Callable[[dict[str, Any]], dict[str, Any]] | None = None
    position_name: str | None = None
    colour: str | None = None
    pose_topic: str | None = None
    analysis: Analysis | None = None
    fuse: Callable[[Any, dict[str, Any], int], None] | None = None

    def __post_init__(self) -> None:
        if not self.name.isidentifier():
            raise ValueError(f"sensor name {self.name!r} is not an identifier (a configuration key)")
        if len(self.letter) != 1 or not self.letter.isupper():
            raise ValueError(f"sensor {self.name}: letter {self.letter!r} is not one capital letter")
        missing = set(STANDARD_SETTINGS) - set(self.settings)
        if missing:
            raise ValueError(f"sensor {self.name}: settings lack {', '.join(sorted(missing))}")


# =============================================================================================
# the registry

_lock = threading.Lock()
_sensors: dict[str, Sensor] = {}
_ordered: tuple[Sensor, ...] = ()
_by_letter: dict[str, Sensor] = {}


def register(sensor: Sensor) -> Sensor:
    """Make ``sensor`` known to the Localizer and its tools; refuses a name or letter taken by
    another (the letters ``S`` and ``K`` are the system's and the filter's). Returns it."""
    global _ordered
    with _lock:
        same = _sensors.get(sensor.name)
        if same is not None and same != sensor:
            raise ValueError(f"sensor {sensor.name!r} is registered already")
        holder = _by_letter.get(sensor.letter)
        if sensor.letter in RESERVED_LETTERS or (holder is not None and holder.name != sensor.name):
            taken = holder.name if holder is not None else RESERVED_LETTERS[sensor.letter]
            raise ValueError(f"sensor {sensor.name}: letter {sensor.letter} is {taken}'s")
        _sensors[sensor.name] = sensor
        _by_letter[sensor.letter] = sensor
        _ordered = tuple(sorted(_sensors.values(), key=lambda s: (s.rank, s.name)))
    return sensor


def unregister(name: str) -> None:
    """Forget the sensor ``name`` (a test's made-up sensor); nothing if it is not known."""
    global _ordered
    with _lock:
        sensor = _sensors.pop(name, None)
        if sensor is not None:
            del _by_letter[sensor.letter]
            _ordered = tuple(sorted(_sensors.values(), key=lambda s: (s.rank, s.name)))


def registered() -> tuple[Sensor, ...]:
    """Every registered sensor in synchronisation order (rank, then name)."""
    return _ordered


def sensor_named(name: str) -> Sensor | None:
    """The sensor called ``name``, or None."""
    return _sensors.get(name)


def sensor_of_letter(letter: str) -> Sensor | None:
    """The sensor whose log source is ``letter``, or None (``S``, ``K``, an unknown letter)."""
    return _by_letter.get(letter)
