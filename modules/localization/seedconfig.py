"""The seed's configuration files (seed 000 §6.5, appendix B.1): sections, values by position.

:func:`read_sections` reads the format every ``ConfigurationFile`` of the seed shares: ``[Name]``
sections (any case: the seed writes ``[Main]`` and ``[MAIN]``), values separated by whitespace and
known only by their place in their section, ``"..."`` around a value with spaces, ``#`` a comment
to the end of the line, ``#`` and ``[`` never inside a value. :class:`Values` takes one section's
values in order, each checked. Every error is a :class:`~modules.localization.config.ConfigError`
naming ``file:line``, the value and what was expected (the YAML's
:class:`~modules.localization.errors.ConfigError`).

:func:`read_seed_config` reads syncaria's file (table B.1) into a :class:`SeedConfig`:
:meth:`SeedConfig.localization_layer` is what the Localizer takes of it, in
``config/localization.yaml``'s shape; :meth:`SeedConfig.notes` lists the values that do not apply
here and why (:meth:`SeedConfig.note_lines`: one line each, ``file:line: [Section] option: why``,
what the commands that take such a file print: :func:`modules.localization.config.seed_notes`); a
value the emulator cannot do as the seed did is refused. ``load_config`` takes such a file (a
``.cfg``, or text that starts with a section) as it takes YAML. docs/seed-config.md maps every
option.
"""

from __future__ import annotations

import math
import os
import re
import unicodedata
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

from modules.localization.errors import MAX_VALUE, ConfigError
from modules.localization.logs import DEFAULT_LOG_DIRECTORY
from modules.localization.sensors import registered, sensor_named

WHITESPACE = " \t\n\r\f\v"
#: a decimal number as the seed's C++ streams read one (no comma, no ``nan``, no ``inf``)
NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d{1,4})?", re.ASCII)
WHOLE = re.compile(r"[+-]?\d{1,15}", re.ASCII)
YES_NO = {"yes": True, "no": False, "ja": True, "nein": False}
#: the first token of a seed file: a section name
_SECTION_START = re.compile(r"\[[ \t]*[A-Za-z][^\[\]#\",\n]*\]")


class Value(NamedTuple):
    """One value of a section: its text (without the quotes) and the line it stands on."""

    text: str
    line: int
    quoted: bool = False


@dataclass(frozen=True)
class Section:
    """One ``[Name]`` section: its name as written, its heading's line and its values in order."""

    name: str
    line: int
    values: tuple[Value, ...]

    @property
    def key(self) -> str:
        """The name to look the section up by: the seed's names are not case-sensitive."""
        return self.name.casefold()


def looks_like_seed_config(text: str) -> bool:
    """Whether the first token of ``text`` that is no comment is a ``[Section]`` heading."""
    for raw in text.removeprefix("\ufeff").splitlines():
        line = raw.strip(WHITESPACE)
        if line and not line.startswith("#"):
            return _SECTION_START.match(line) is not None
    return False


def read_sections(text: str, source: str) -> list[Section]:
    """Every section of a seed configuration file, in file order (the format of appendix B.1;
    the meaning of the values is the reader's: :class:`Values`). ``source`` names the file in
    errors. Refuses a value before the first section, an unclosed quote or section name, and
    ``#``, ``[``, ``"`` or a control character inside a value."""
    text = text.removeprefix("\ufeff").replace("\r\n", "\n").replace("\r", "\n")
    sections: list[Section] = []
    name: str | None = None
    heading_line = 0
    values: list[Value] = []
    i, line, n = 0, 1, len(text)

    def fail(at: int, problem: str) -> ConfigError:
        return ConfigError(f"{source}:{at}: {problem}")

    while i < n:
        c = text[i]
        if c == "\n":
            line += 1
            i += 1
        elif c in WHITESPACE:
            i += 1
        elif c == "#":
            end = text.find("\n", i)
            i = n if end < 0 else end
        elif c == "[":
            end = _scan(text, i + 1, "]")
            if end >= n or text[end] != "]":
                raise fail(line, "a section name opened with '[' has no ']' on its line")
            heading = text[i + 1 : end].strip(WHITESPACE)
            if not heading:
                raise fail(line, "[] names no section")
            for ch in heading:
                if ch in '#["' or _has_control(ch):
                    raise fail(line, f"[{heading!r}]: {ch!r} may not be in a section name")
            if name is not None:
                sections.append(Section(name, heading_line, tuple(values)))
            name, heading_line, values = heading, line, []
            i = end + 1
        elif c == '"':
            end = _scan(text, i + 1, '"')
            if end >= n or text[end] != '"':
                raise fail(line, "a value opened with '\"' is not closed on its line")
            body = text[i + 1 : end]
            for bad, why in (("#", "it starts a comment"), ("[", "it starts a section name")):
                if bad in body:
                    raise fail(line, f"{body!r}: {bad!r} may not be in a value ({why})")
            if _has_control(body):
                raise fail(line, f"{body!r}: a control character may not be in a value")
            if end + 1 < n and text[end + 1] not in WHITESPACE + "#":
                raise fail(line, f"{text[i : end + 2]!r}: a quoted value ends at its closing quote")
            if name is None:
                raise fail(line, f"{body!r} stands before the first section ([Name])")
            values.append(Value(body, line, True))
            i = end + 1
        else:
            end = i
            while end < n and text[end] not in WHITESPACE and text[end] != "#":
                end += 1
            token = text[i:end]
            for bad, why in (("[", "it starts a section name"), ('"', "quotes go around a whole value")):
                if bad in token:
                    raise fail(line, f"{token!r}: {bad!r} may not be in a value ({why})")
            if _has_control(token):
                raise fail(line, f"{token!r}: a control character may not be in a value")
            if name is None:
                raise fail(line, f"{token!r} stands before the first section ([Name])")
            values.append(Value(token, line))
            i = end
    if name is not None:
        sections.append(Section(name, heading_line, tuple(values)))
    return sections


def _scan(text: str, start: int, closing: str) -> int:
    """The index of ``closing`` or of the line's end (or the text's), from ``start``."""
    i = start
    while i < len(text) and text[i] not in (closing, "\n"):
        i += 1
    return i


def _has_control(text: str) -> bool:
    """A control character, a lone surrogate or a line break of Unicode's own (never in a value:
    a path could not take it, an error line could not show it)."""
    return any(unicodedata.category(ch) in ("Cc", "Cs", "Zl", "Zp") for ch in text)


class Values:
    """One section's values, taken in the order its table lists them: each taker checks the next
    value and records its line in :attr:`lines` under ``key`` (default: the option's name)."""

    def __init__(self, section: Section, source: str) -> None:
        self.section = section
        self.source = source
        self.lines: dict[str, int] = {}
        self._next = 0
        self._last: str | None = None

    @property
    def last(self) -> Value:
        """The value taken last."""
        return self.section.values[self._next - 1]

    def fail(self, line: int, problem: str) -> ConfigError:
        """An error at ``line`` of this section."""
        return ConfigError(f"{self.source}:{line}: [{self.section.name}] {problem}")

    def more(self) -> bool:
        """Whether values are left (an optional value at the section's end is given)."""
        return self._next < len(self.section.values)

    def take(self, option: str, expected: str, key: str | None = None) -> Value:
        """The next value, the ``option`` of the table; an error names what is missing."""
        if not self.more():
            line = self.section.values[-1].line if self.section.values else self.section.line
            after = f" after {self._last}" if self._last else ""
            raise self.fail(line, f"ends{after}: {option} ({expected}) is missing")
        value = self.section.values[self._next]
        self._next += 1
        self._last = option
        self.lines[key or option] = value.line
        return value

    def bad(self, value: Value, option: str, expected: str) -> ConfigError:
        """The error for ``value``, which is not the ``expected`` of ``option``."""
        return self.fail(value.line, f"{option}: expected {expected}, got {value.text!r}")

    def text(self, option: str, key: str | None = None) -> str:
        """A name or a file name: any text but an empty one."""
        value = self.take(option, "a name", key)
        if not value.text.strip(WHITESPACE):
            raise self.bad(value, option, "a name, not an empty value")
        return value.text

    def yes_no(self, option: str, key: str | None = None) -> bool:
        """yes or no (any case; ja and nein as lopscpp's reader takes them)."""
        value = self.take(option, "yes or no", key)
        answer = YES_NO.get(value.text.casefold())
        if answer is None:
            raise self.bad(value, option, "yes or no")
        return answer

    def whole(self, option: str, low: int, high: int, key: str | None = None) -> int:
        """A whole number from ``low`` to ``high``."""
        expected = f"a whole number {low}-{high}" if high < MAX_VALUE else f"a whole number >= {low}"
        value = self.take(option, expected, key)
        if WHOLE.fullmatch(value.text) is None or not low <= int(value.text) <= high:
            raise self.bad(value, option, expected)
        return int(value.text)

    def number(
        self,
        option: str,
        low: float = -MAX_VALUE,
        high: float = MAX_VALUE,
        key: str | None = None,
        *,
        positive: bool = False,
    ) -> float:
        """A finite decimal number from ``low`` to ``high`` (``positive``: above 0)."""
        if positive:
            expected = "a number > 0"
        elif low == 0 and high >= MAX_VALUE:
            expected = "a number >= 0"
        elif low > -MAX_VALUE or high < MAX_VALUE:
            expected = f"a number {low:g}-{high:g}"
        else:
            expected = "a number"
        value = self.take(option, expected, key)
        if NUMBER.fullmatch(value.text) is None:
            raise self.bad(value, option, f"{expected} (a point for decimals)")
        number = float(value.text)
        if not math.isfinite(number) or not low <= number <= high or (positive and number <= 0):
            raise self.bad(value, option, expected)
        return number

    def choice(self, option: str, choices: Mapping[str, str], key: str | None = None) -> str:
        """One of ``choices`` (any case), as the value it maps to."""
        expected = " or ".join(dict.fromkeys(choices))
        value = self.take(option, expected, key)
        chosen = choices.get(value.text.casefold())
        if chosen is None:
            raise self.bad(value, option, expected)
        return chosen

    def end(self) -> None:
        """Refuse a value beyond the table's last."""
        if self.more():
            value = self.section.values[self._next]
            after = f"the section ends after {self._last}" if self._last else "the section has none"
            raise self.fail(value.line, f"{value.text!r} is one value too many: {after}")


# =============================================================================================
# syncaria's file, table B.1

#: table B.1's sections and values in their order (``*``: repeated; ``?``: optional, at the end)
TABLE_B1: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("Main", ("Anbindung", "Benutzerschnittstelle", "Trigger", "Triggeranzahl", "Kalmanfilter",
              "Positionsinitialisierung", "Datenlogdatei", "Debuglevel", "Fehlerlog", "Fehlerlogdatei?")),
    ("Sensors", ("Sensorname*", "Synchronisieren*", "Position*", "Rohdatenlogging*",
                 "Synchronisation loggen*", "Positionslogging*", "Kalmanfilter*")),
    ("Odometry", ("Kreisberechnung",)),
    ("Gyroscop", ("Schnittstelle",)),
    ("Walls", ("Wanderkennung", "Historienlänge", "max. Distanz", "min. Punkte (Seite)",
               "min. Punkte (Paare)", "max. σ_d (Seite)", "max. σ_d (Paare)", "max. σ_α (Seite)",
               "max. Δd (oben / unten)", "max. Δα (oben / unten)", "Wanddatei", "max. Δd (Zuordnung)",
               "max. Δα (Zuordnung)")),
    ("Lops", ("Robotername", "Port", "Schnittstelle", "Steigung n*", "Offset n*", "X-Position n*",
              "Y-Position n*", "Gewichten", "Positionsfilter", "Historienlänge", "Grundwert?")),
    ("Offline", ("Ergebnisdatei", "Fehlerdatei", "Synchronisierte Daten")),
    ("Action", ("Auto", "Datei n*?")),
)  # fmt: skip

#: the names a section may be written under (any case)
SECTION_NAMES = {
    "main": "Main",
    "sensors": "Sensors",
    "odometry": "Odometry",
    "gyroscop": "Gyroscop",
    "gyroscope": "Gyroscop",
    "walls": "Walls",
    "lops": "Lops",
    "offline": "Offline",
    "action": "Action",
    "actions": "Action",
}
#: the seed's sensor names (its SensorID::set) and ours; any registered sensor's name also goes
SEED_SENSOR_NAMES = {
    "odo": "odometry",
    "odometry": "odometry",
    "gyro": "gyro",
    "gyroscop": "gyro",
    "gyroscope": "gyro",
    "walls": "sonar",
    "sonar": "sonar",
    "lops": "lops",
}
#: which sensor's section a listed sensor needs
SENSOR_SECTIONS = {"odometry": "Odometry", "gyro": "Gyroscop", "sonar": "Walls", "lops": "Lops"}
CONNECTIONS = {"robot": "robot", "real": "robot", "sim": "sim"}
UIS = {"stdout": "stdout", "ncurses": "ncurses", "none": "none"}
#: what the LOPS ``tokenring up --sensors darmstadt`` starts converts and filters with: the
#: defaults of modules/lops/config.py's LopsConfig (the programs may not import LOPS's PC; a test
#: keeps the two equal)
LOPSCPP_DEFAULTS: dict[str, Any] = {
    "slopes": (0.330, 0.330, 0.330),
    "offsets": (-42.0, -37.0, -45.0),
    "weighting": False,
    "position_filter": True,
    "history_length": 10,
    "grundwert": 0.1,
}
#: how far a receiver of the file may stand from the one the started LOPS has, mm
RECEIVER_TOLERANCE_MM = 0.5


class Note(NamedTuple):
    """A value read and accepted that does not apply here: its line, the option, and why."""

    line: int
    option: str
    why: str


@dataclass(frozen=True)
class MainSection:
    """``[Main]``, table B.1's order."""

    connection: str  # Anbindung: robot (the seed also wrote "real") or sim
    ui: str  # Benutzerschnittstelle: stdout, ncurses or none
    trigger: str  # Trigger: the sensor whose samples start a synchronisation (our name)
    trigger_count: int  # Triggeranzahl
    kalman_filter: bool  # Kalmanfilter
    position_init: bool  # Positionsinitialisierung (by LOPS)
    data_log: str  # Datenlogdatei
    debug_level: int  # Debuglevel, 0 (F only) .. 4 (also D)
    error_log: bool  # Fehlerlog
    error_log_file: str | None  # Fehlerlogdatei (optional: the section's last value)
    line: int = 0
    lines: Mapping[str, int] = field(default_factory=dict, compare=False, repr=False)  # each value's line


@dataclass(frozen=True)
class SensorRow:
    """One sensor's seven values of ``[Sensors]``."""

    name: str  # our name (sensors.<name>)
    spelled: str  # Sensorname as the file writes it
    synchronise: bool  # Synchronisieren
    position: bool  # Position
    log_raw: bool  # Rohdatenlogging
    log_sync: bool  # Synchronisation loggen
    log_position: bool  # Positionslogging
    filter: bool  # Kalmanfilter
    line: int = 0
    lines: Mapping[str, int] = field(default_factory=dict, compare=False, repr=False)  # each value's line


@dataclass(frozen=True)
class OdometrySection:
    """``[Odometry]``: how a step is computed (§6.2.2)."""

    circle: bool  # Kreisberechnung: the arc (§2.2) instead of the straight step
    line: int = 0
    lines: Mapping[str, int] = field(default_factory=dict, compare=False, repr=False)  # each value's line


@dataclass(frozen=True)
class GyroscopeSection:
    """``[Gyroscop]``: where the gyroscope is plugged in (§6.2.3)."""

    interface: str  # Schnittstelle: the serial device
    line: int = 0
    lines: Mapping[str, int] = field(default_factory=dict, compare=False, repr=False)  # each value's line


@dataclass(frozen=True)
class WallsSection:
    """``[Walls]``: the wall detection's 13 values (§6.2.4), mm and degrees."""

    detect: bool  # Wanderkennung
    history: int  # Historienlänge: sonar points kept per sensor
    max_distance_mm: float  # max. Distanz
    min_points_side: int  # min. Punkte (Seite)
    min_points_pairs: int  # min. Punkte (Paare)
    max_sigma_d_side_mm: float  # max. σ_d (Seite)
    max_sigma_d_pairs_mm: float  # max. σ_d (Paare)
    max_sigma_alpha_deg: float  # max. σ_α (Seite): the pairs' angle, as its description says
    max_delta_d_arrays_mm: float  # max. Δd (oben / unten)
    max_delta_alpha_arrays_deg: float  # max. Δα (oben / unten)
    wall_file: str  # Wanddatei
    max_delta_d_association_mm: float  # max. Δd (Zuordnung)
    max_delta_alpha_association_deg: float  # max. Δα (Zuordnung)
    line: int = 0
    lines: Mapping[str, int] = field(default_factory=dict, compare=False, repr=False)  # each value's line


@dataclass(frozen=True)
class LopsSection:
    """``[Lops]``, which lopscpp shares (§6.2.5); Grundwert, §6.2.5's, may follow as a 19th."""

    robot_name: str  # Robotername
    port: int  # Port
    interface: str  # Schnittstelle
    slopes: tuple[float, float, float]  # Steigung n, mm/µs
    offsets: tuple[float, float, float]  # Offset n, mm
    receivers: tuple[tuple[float, float], tuple[float, float], tuple[float, float]]  # X/Y-Position n
    weighting: bool  # Gewichten
    position_filter: bool  # Positionsfilter
    history_length: int  # Historienlänge
    grundwert: float | None  # Grundwert, mm per ms of age (optional)
    line: int = 0
    lines: Mapping[str, int] = field(default_factory=dict, compare=False, repr=False)  # each value's line


@dataclass(frozen=True)
class OfflineSection:
    """``[Offline]``: the offline mode's outputs and its input (§5.6)."""

    result: str  # Ergebnisdatei
    errors: str  # Fehlerdatei
    synchronised: bool  # Synchronisierte Daten (no: the raw data)
    line: int = 0
    lines: Mapping[str, int] = field(default_factory=dict, compare=False, repr=False)  # each value's line


@dataclass(frozen=True)
class ActionSection:
    """``[Action]``: the action files (§6.7, table B.4) as written."""

    auto: bool  # Auto: drive the first action file at the start
    files: tuple[str | None, str | None, str | None]  # Datei 1-3 (optional at the end)
    line: int = 0
    lines: Mapping[str, int] = field(default_factory=dict, compare=False, repr=False)  # each value's line


@dataclass(frozen=True)
class ActionSettings:
    """What the operator's console drives: file 1 at the start when ``auto``; the keys a, b, c
    (table 8.2) drive ``files``, resolved from the configuration file's folder."""

    auto: bool
    files: tuple[Path | None, Path | None, Path | None]


@dataclass(frozen=True)
class OfflineSettings:
    """The offline mode's files (§5.6, §8.3): the data log to read, the result and error logs
    to write (relative names in the logs folder, where the online run writes its logs), and
    whether the filter runs on the synchronised records or on the raw data again."""

    input: Path
    result: Path
    errors: Path
    synchronised: bool


@dataclass(frozen=True)
class SeedConfig:
    """syncaria's configuration (table B.1), every value in its section's order."""

    source: str
    base: Path  # the folder relative names of files to read are taken from
    main: MainSection
    sensors: tuple[SensorRow, ...]
    odometry: OdometrySection | None = None
    gyroscope: GyroscopeSection | None = None
    walls: WallsSection | None = None
    lops: LopsSection | None = None
    offline_section: OfflineSection | None = None
    action: ActionSection | None = None
    #: the ``[Sensors]`` heading's line (where a sensor it does not list is switched off)
    sensors_line: int = 0

    # ---------------------------------------------------------------------------------------
    # what the operator's console reads

    @property
    def ui(self) -> str:
        """Benutzerschnittstelle: ``ncurses``, ``stdout`` or ``none``."""
        return self.main.ui

    @property
    def mode(self) -> str:
        """Anbindung: ``robot`` (the seed's ``real`` too) or ``sim``."""
        return self.main.connection

    @property
    def debug_level(self) -> int:
        """Debuglevel: 0 fatal only, 1 also errors, 2 warnings, 3 information, 4 debug."""
        return self.main.debug_level

    @property
    def actions(self) -> ActionSettings:
        """[Action]: none given is no auto start and no files."""
        if self.action is None:
            return ActionSettings(False, (None, None, None))
        a, b, c = (None if name is None else self._read_path(name) for name in self.action.files)
        return ActionSettings(self.action.auto, (a, b, c))

    @property
    def offline(self) -> OfflineSettings | None:
        """[Offline] with the Datenlogdatei as its input; None without the section."""
        o = self.offline_section
        if o is None:
            return None
        log = self._log_path
        return OfflineSettings(log(self.main.data_log), log(o.result), log(o.errors), o.synchronised)

    def _read_path(self, name: str) -> Path:
        path = Path(name)
        return path if path.is_absolute() else Path(os.path.abspath(self.base / path))

    @staticmethod
    def _log_path(name: str) -> Path:
        path = Path(name)
        return path if path.is_absolute() else Path(DEFAULT_LOG_DIRECTORY) / path

    # ---------------------------------------------------------------------------------------
    # the Localizer's layer

    def localization_layer(self) -> dict[str, Any]:
        """What the Localizer takes of this file, in config/localization.yaml's shape (laid over
        it by ``load_config``; what the seed has no option for keeps that file's value)."""
        return self._layer()[0]

    def layer_lines(self) -> dict[tuple[str, ...], int]:
        """The line of the value each key of :meth:`localization_layer` came from."""
        return self._layer()[1]

    def _layer(self) -> tuple[dict[str, Any], dict[tuple[str, ...], int]]:
        layer: dict[str, Any] = {}
        lines: dict[tuple[str, ...], int] = {}
        m = self.main

        def put(path: tuple[str, ...], value: Any, line: int) -> None:
            node = layer
            for key in path[:-1]:
                node = node.setdefault(key, {})
            node[path[-1]] = value
            lines[path] = line

        listed = {row.name for row in self.sensors}
        for row in self.sensors:
            at = row.lines
            settings = ("synchronise", "position", "log_raw", "log_sync", "log_position", "filter")
            put(("sensors", row.name, "use"), True, row.line)
            for key in settings:
                value = getattr(row, key)
                if key in ("log_sync", "filter") and not row.synchronise:
                    value = False  # nothing synchronised: a note says so
                if key == "log_position" and not row.position:
                    value = False
                put(("sensors", row.name, key), value, at[key])
        for sensor in registered():
            if sensor.name not in listed and sensor.name != "truth":
                put(("sensors", sensor.name, "use"), False, self.sensors_line)
        trigger = {"mode": "count", "sensor": m.trigger, "count": m.trigger_count, "min_period_ms": 0}
        for key, value in {**trigger, "rounds": 0}.items():
            line = m.lines["trigger_count" if key in ("count", "min_period_ms") else "trigger"]
            put(("sync", "trigger", key), value, line)
        put(("filter", "enabled"), m.kalman_filter, m.lines["kalman_filter"])
        if m.position_init:
            put(("filter", "initial_pose"), "lops", m.lines["position_init"])
        if self.odometry is not None:
            model = "arc" if self.odometry.circle else "straight"
            put(("filter", "odometry_model"), model, self.odometry.lines["circle"])
        if self.walls is not None:
            w, at = self.walls, self.walls.lines
            put(("walls", "mode"), "darmstadt" if w.detect else "off", at["detect"])
            put(("walls", "file"), self._wall_file(), at["wall_file"])
            for key, name in (
                (("history",), "history"),
                (("max_distance_mm",), "max_distance_mm"),
                (("min_points_side",), "min_points_side"),
                (("min_points_pairs",), "min_points_pairs"),
                (("max_sigma_side_mm",), "max_sigma_d_side_mm"),
                (("max_sigma_d_pairs_mm",), "max_sigma_d_pairs_mm"),
                (("max_sigma_alpha_pairs_deg",), "max_sigma_alpha_deg"),
                (("association", "max_d_mm"), "max_delta_d_association_mm"),
                (("association", "max_alpha_deg"), "max_delta_alpha_association_deg"),
            ):
                put(("walls", *key), getattr(w, name), at[name])
        if self.lops is not None:
            receivers = [[x, y] for x, y in self.lops.receivers]
            put(("lops", "receivers"), receivers, self.lops.lines["receiver 1"])
        put(("logs", "data"), _literal(m.data_log), m.lines["data_log"])
        if m.error_log_file is not None:
            put(("logs", "errors"), _literal(m.error_log_file), m.lines["error_log_file"])
        put(("logs", "debug_level"), m.debug_level, m.lines["debug_level"])
        put(("logs", "error_log"), m.error_log, m.lines["error_log"])
        put(("ui",), m.ui, m.lines["ui"])
        actions = self.actions
        if self.action is not None:
            put(("actions", "auto"), actions.auto, self.action.lines["auto"])
            files = [None if p is None else str(p) for p in actions.files]
            while files and files[-1] is None:
                files.pop()
            put(("actions", "files"), files, self.action.lines.get("file 1", self.action.line))
        return layer, lines

    def _wall_file(self) -> str:
        """Wanddatei: a bundled room's name as it is, a file's path from the file's folder."""
        assert self.walls is not None
        name = self.walls.wall_file
        if "/" not in name and "." not in name:
            return name
        return str(self._read_path(name))

    # ---------------------------------------------------------------------------------------
    # what does not apply here

    def notes(self) -> list[Note]:
        """The values read and accepted that do not apply to the emulator, with why."""
        out: list[Note] = [
            Note(
                self.main.lines["connection"],
                "[Main] Anbindung",
                "the ring is the robot either way: tokenring up runs it on the world simulator "
                "(with --no-world on hardware); kept as SeedConfig.mode",
            )
        ]
        if not self.main.error_log and self.main.error_log_file is not None:
            out.append(
                Note(
                    self.main.lines["error_log_file"],
                    "[Main] Fehlerlogdatei",
                    "Fehlerlog is no: no error log",
                )
            )
        for row in self.sensors:
            where = f"[Sensors] {row.spelled}"
            if not row.synchronise and row.log_sync:
                out.append(
                    Note(
                        row.lines["log_sync"],
                        f"{where} Synchronisation loggen",
                        "not synchronised: nothing to log",
                    )
                )
            if not row.synchronise and row.filter:
                out.append(
                    Note(
                        row.lines["filter"],
                        f"{where} Kalmanfilter",
                        "not synchronised: the filter takes synchronised data only",
                    )
                )
            if row.position and not _has_position(row.name):
                out.append(
                    Note(row.lines["position"], f"{where} Position", f"{row.name} has no position of its own")
                )
            if not row.position and row.log_position:
                out.append(
                    Note(
                        row.lines["log_position"],
                        f"{where} Positionslogging",
                        "no position computed: none to log",
                    )
                )
        if self.gyroscope is not None:
            out.append(
                Note(
                    self.gyroscope.lines["interface"],
                    "[Gyroscop] Schnittstelle",
                    "the gyroscope is the ring's gyro node (up --sensors darmstadt): no serial line to open",
                )
            )
        if self.walls is not None:
            for key, option in (
                ("max_delta_d_arrays_mm", "max. Δd (oben / unten)"),
                ("max_delta_alpha_arrays_deg", "max. Δα (oben / unten)"),
            ):
                out.append(
                    Note(
                        self.walls.lines[key],
                        f"[Walls] {option}",
                        "the robot has one ring of eight sonars, not the Pioneer's two arrays: no upper and lower walls to compare",
                    )
                )
        if self.lops is not None:
            at = self.lops.lines
            wire = "LOPS's packets reach copro over Zenoh (robot/<ring>/lops/packets), not a TCP socket"
            out.append(Note(at["robot_name"], "[Lops] Robotername", wire))
            out.append(Note(at["port"], "[Lops] Port", wire))
            out.append(
                Note(
                    at["interface"],
                    "[Lops] Schnittstelle",
                    "the emulated MCU is LOPS's hardware: no serial line",
                )
            )
            same = (
                "lopscpp's: the LOPS tokenring up --sensors darmstadt starts runs with this same value "
                "(modules/lops/config.py); the Localizer takes LOPS's distances"
            )
            for key, option in _lopscpp_options(self.lops):
                out.append(Note(at[key], f"[Lops] {option}", same))
        return out

    def note_lines(self) -> list[str]:
        """:meth:`notes` as the operator is told them, in file order: ``file:line: [Section]
        option: why`` each."""
        notes = sorted(self.notes(), key=lambda note: note.line)
        return [f"{self.source}:{note.line}: {note.option}: {note.why}" for note in notes]

    def check_beneath(self, under: Mapping[str, Any] | None) -> None:
        """Refuse LOPS receivers other than those of the LOPS ``tokenring up`` started (``under``,
        the layer ``up`` lays beneath the file, names them): the filter would take its distances
        to receivers where none stands."""
        theirs = ((under or {}).get("lops") or {}).get("receivers")
        if self.lops is None or not theirs:
            return
        for n, (mine, started) in enumerate(zip(self.lops.receivers, theirs, strict=False), start=1):
            if any(abs(a - float(b)) > RECEIVER_TOLERANCE_MM for a, b in zip(mine, started, strict=False)):
                line = self.lops.lines[f"receiver {n}"]
                raise ConfigError(
                    f"{self.source}:{line}: [Lops] X/Y-Position {n}: {mine[0]:g} {mine[1]:g} mm, but the LOPS "
                    f"tokenring up started has its receiver {n} at {float(started[0]):g} {float(started[1]):g} mm "
                    "(its world's corners): the filter would measure to a receiver where none stands"
                )


def _has_position(name: str) -> bool:
    """Whether the sensor ``name`` stores a position of its own (the sonar's: the walls')."""
    sensor = sensor_named(name)
    return name == "sonar" or (sensor is not None and sensor.position is not None)


def _literal(name: str) -> str:
    """A log file's name as the seed wrote it: braces kept, not a ``{start}`` to fill in."""
    return name.replace("{", "{{").replace("}", "}}")


def _lopscpp_options(lops: LopsSection) -> list[tuple[str, str]]:
    """lopscpp's values of ``[Lops]`` (its line keys and table names) the file gives."""
    options = [(f"slope {n}", f"Steigung {n}") for n in (1, 2, 3)]
    options += [(f"offset {n}", f"Offset {n}") for n in (1, 2, 3)]
    options += [("weighting", "Gewichten"), ("position_filter", "Positionsfilter")]
    options += [("history_length", "Historienlänge")]
    if lops.grundwert is not None:
        options.append(("grundwert", "Grundwert"))
    return options


# ---------------------------------------------------------------------------------------------
# reading


def read_seed_config(
    path_or_text: str | bytes | Path, source: str | None = None, *, base: Path | None = None
) -> SeedConfig:
    """syncaria's configuration file (table B.1): a :class:`~pathlib.Path` is read, a ``str``
    (or UTF-8 ``bytes``) is the text itself. ``source`` names it in errors; ``base`` is the
    folder relative names of files to read are taken from (default: the file's, else
    ``source``'s when it names a file, else the working directory)."""
    if isinstance(path_or_text, Path):
        from tokenring import message_error, read_text

        source = source or str(path_or_text)
        text = read_text(path_or_text, "configuration file", message_error(ConfigError))
        base = base if base is not None else path_or_text.parent
    elif isinstance(path_or_text, bytes):
        source = source or "<config>"
        try:
            text = path_or_text.decode("utf-8")
        except UnicodeDecodeError as exc:
            line = path_or_text.count(b"\n", 0, exc.start) + 1
            raise ConfigError(f"{source}:{line}: not UTF-8 text (byte {exc.start})") from None
    else:
        source = source or "<config>"
        text = path_or_text
    if base is None:
        base = Path(source).parent if not source.startswith("<") else Path()
    return _read(read_sections(text, source), source, base)


def _read(sections: Sequence[Section], source: str, base: Path) -> SeedConfig:
    found: dict[str, Section] = {}
    for section in sections:
        name = SECTION_NAMES.get(section.key)
        if name is None:
            known = ", ".join(f"[{n}]" for n, _ in TABLE_B1)
            raise ConfigError(
                f"{source}:{section.line}: [{section.name}] is no section of table B.1 ({known})"
            )
        if name in found:
            raise ConfigError(
                f"{source}:{section.line}: [{section.name}] again (the first at line {found[name].line})"
            )
        found[name] = section
    for name in ("Main", "Sensors"):
        if name not in found:
            raise ConfigError(f"{source}: no [{name}] section (table B.1)")
    sensors = _sensors(found["Sensors"], source)
    main = _main(found["Main"], source)
    listed = {row.name: row for row in sensors}
    for sensor, name in SENSOR_SECTIONS.items():
        if sensor in listed and name not in found:
            row = listed[sensor]
            raise ConfigError(
                f"{source}:{row.line}: [Sensors] {row.spelled} is listed, but there is no [{name}] section for it"
            )
    if main.trigger not in listed:
        raise ConfigError(
            f"{source}:{main.lines['trigger']}: [Main] Trigger: {main.trigger} triggers the synchronisation "
            "but is not listed in [Sensors]"
        )
    if main.position_init and "lops" not in listed:
        raise ConfigError(
            f"{source}:{main.lines['position_init']}: [Main] Positionsinitialisierung: yes initialises the "
            "position by LOPS, which is not listed in [Sensors]"
        )
    config = SeedConfig(
        source=source,
        base=base,
        main=main,
        sensors=sensors,
        odometry=_odometry(found["Odometry"], source) if "Odometry" in found else None,
        gyroscope=_gyroscope(found["Gyroscop"], source) if "Gyroscop" in found else None,
        walls=_walls(found["Walls"], source) if "Walls" in found else None,
        lops=_lops(found["Lops"], source) if "Lops" in found else None,
        offline_section=_offline(found["Offline"], source) if "Offline" in found else None,
        action=_action(found["Action"], source) if "Action" in found else None,
        sensors_line=found["Sensors"].line,
    )
    if config.walls is not None:
        _check_wall_file(config)
    return config


def _main(section: Section, source: str) -> MainSection:
    r = Values(section, source)
    connection = r.choice("Anbindung", CONNECTIONS, "connection")
    ui = r.choice("Benutzerschnittstelle", UIS, "ui")
    trigger = _sensor_name(r, "Trigger", "trigger")
    count = r.whole("Triggeranzahl", 1, 1_000_000, "trigger_count")
    kalman = r.yes_no("Kalmanfilter", "kalman_filter")
    position_init = r.yes_no("Positionsinitialisierung", "position_init")
    data_log = _file_name(r, "Datenlogdatei", "data_log")
    debug_level = r.whole("Debuglevel", 0, 4, "debug_level")
    error_log = r.yes_no("Fehlerlog", "error_log")
    error_file = _file_name(r, "Fehlerlogdatei", "error_log_file") if r.more() else None
    r.end()
    if error_log and error_file is None:
        raise r.fail(r.lines["error_log"], "Fehlerlog is yes: Fehlerlogdatei (a file name) must follow it")
    return MainSection(
        connection, ui, trigger, count, kalman, position_init, data_log, debug_level, error_log, error_file,
        section.line, r.lines,
    )  # fmt: skip


def _sensors(section: Section, source: str) -> tuple[SensorRow, ...]:
    rows: list[SensorRow] = []
    first: dict[str, SensorRow] = {}
    r = Values(section, source)
    while r.more():
        r.lines = {}
        name = _sensor_name(r, "Sensorname", "name")
        spelled = r.last.text
        flags = [
            r.yes_no(f"{option} of {spelled}", key)
            for option, key in (
                ("Synchronisieren", "synchronise"),
                ("Position", "position"),
                ("Rohdatenlogging", "log_raw"),
                ("Synchronisation loggen", "log_sync"),
                ("Positionslogging", "log_position"),
                ("Kalmanfilter", "filter"),
            )
        ]
        row = SensorRow(name, spelled, *flags, line=r.lines["name"], lines=dict(r.lines))
        if name in first:
            raise r.fail(row.line, f"{spelled}: {name} is listed twice (first at line {first[name].line})")
        if name == "odometry" and not row.synchronise:
            raise r.fail(
                row.lines["synchronise"],
                f"Synchronisieren of {spelled}: no is not possible here: the odometry's synchronised steps "
                "are the track every other sensor's samples are carried along, and dead reckoning's",
            )
        if row.position and not row.synchronise and _has_position(name):
            raise r.fail(
                row.lines["position"],
                f"Position of {spelled}: yes with Synchronisieren no: here a sensor's position is computed "
                "from its synchronised data (the seed's module computed it from the raw data)",
            )
        first[name] = row
        rows.append(row)
    if not rows:
        raise ConfigError(f"{source}:{section.line}: [{section.name}] lists no sensor (7 values each)")
    return tuple(rows)


def _sensor_name(r: Values, option: str, key: str) -> str:
    """A sensor as the seed names it (odo, gyro, walls, lops ...) or ours, as our name."""
    known = {**SEED_SENSOR_NAMES, **{s.name: s.name for s in registered()}}
    return r.choice(option, known, key)


def _file_name(r: Values, option: str, key: str) -> str:
    name = r.text(option, key)
    if name.endswith("/") or Path(name).name in ("", ".", ".."):
        raise r.bad(r.last, option, "a file name, not a folder")
    return name


def _odometry(section: Section, source: str) -> OdometrySection:
    r = Values(section, source)
    circle = r.yes_no("Kreisberechnung", "circle")
    r.end()
    return OdometrySection(circle, section.line, r.lines)


def _gyroscope(section: Section, source: str) -> GyroscopeSection:
    r = Values(section, source)
    interface = r.text("Schnittstelle", "interface")
    r.end()
    return GyroscopeSection(interface, section.line, r.lines)


def _walls(section: Section, source: str) -> WallsSection:
    r = Values(section, source)
    big = int(MAX_VALUE)
    values = WallsSection(
        detect=r.yes_no("Wanderkennung", "detect"),
        history=r.whole("Historienlänge", 1, 100_000, "history"),
        max_distance_mm=r.number("max. Distanz", key="max_distance_mm", positive=True),
        min_points_side=r.whole("min. Punkte (Seite)", 3, big, "min_points_side"),
        min_points_pairs=r.whole("min. Punkte (Paare)", 3, big, "min_points_pairs"),
        max_sigma_d_side_mm=r.number("max. σ_d (Seite)", key="max_sigma_d_side_mm", positive=True),
        max_sigma_d_pairs_mm=r.number("max. σ_d (Paare)", key="max_sigma_d_pairs_mm", positive=True),
        max_sigma_alpha_deg=r.number("max. σ_α (Seite)", key="max_sigma_alpha_deg", positive=True),
        max_delta_d_arrays_mm=r.number("max. Δd (oben / unten)", 0.0, key="max_delta_d_arrays_mm"),
        max_delta_alpha_arrays_deg=r.number("max. Δα (oben / unten)", 0.0, key="max_delta_alpha_arrays_deg"),
        wall_file=_file_name(r, "Wanddatei", "wall_file"),
        max_delta_d_association_mm=r.number("max. Δd (Zuordnung)", 0.0, key="max_delta_d_association_mm"),
        max_delta_alpha_association_deg=r.number(
            "max. Δα (Zuordnung)", 0.0, 180.0, key="max_delta_alpha_association_deg"
        ),
        line=section.line,
        lines=r.lines,
    )
    r.end()
    return values


def _check_wall_file(config: SeedConfig) -> None:
    """The Wanddatei must name a bundled room or a readable file (checked now: the error names
    its line)."""
    from modules.description.roomfile import resolve_world
    from tokenring import TokenRingError

    assert config.walls is not None
    try:
        resolve_world(config._wall_file())
    except (TokenRingError, OSError, ValueError) as exc:
        line = config.walls.lines["wall_file"]
        raise ConfigError(
            f"{config.source}:{line}: [Walls] Wanddatei: {' '.join(str(exc).split())}"
        ) from None


def _lops(section: Section, source: str) -> LopsSection:
    r = Values(section, source)
    robot_name = r.text("Robotername", "robot_name")
    port = r.whole("Port", 1, 65535, "port")
    interface = r.text("Schnittstelle", "interface")
    slopes, offsets = [], []
    for n in (1, 2, 3):
        slopes.append(r.number(f"Steigung {n}", key=f"slope {n}", positive=True))
        offsets.append(r.number(f"Offset {n}", key=f"offset {n}"))
    receivers = []
    for n in (1, 2, 3):
        x = r.number(f"X-Position {n}", key=f"receiver {n}")
        receivers.append((x, r.number(f"Y-Position {n}", key=f"receiver {n} y")))
    weighting = r.yes_no("Gewichten", "weighting")
    position_filter = r.yes_no("Positionsfilter", "position_filter")
    history = r.whole("Historienlänge", 2, 100_000, "history_length")
    grundwert = r.number("Grundwert", key="grundwert", positive=True) if r.more() else None
    r.end()
    lops = LopsSection(
        robot_name, port, interface, (slopes[0], slopes[1], slopes[2]), (offsets[0], offsets[1], offsets[2]),
        (receivers[0], receivers[1], receivers[2]), weighting, position_filter, history, grundwert,
        section.line, r.lines,
    )  # fmt: skip
    _check_lopscpp(lops, r)
    return lops


def _check_lopscpp(lops: LopsSection, r: Values) -> None:
    """lopscpp's values must be those the LOPS ``tokenring up`` starts runs with: it does not
    read this file, and other ones would change what it measures."""
    d = LOPSCPP_DEFAULTS
    given = {f"slope {n}": (lops.slopes[n - 1], d["slopes"][n - 1]) for n in (1, 2, 3)}
    given |= {f"offset {n}": (lops.offsets[n - 1], d["offsets"][n - 1]) for n in (1, 2, 3)}
    given |= {
        "weighting": (lops.weighting, d["weighting"]),
        "position_filter": (lops.position_filter, d["position_filter"]),
        "history_length": (lops.history_length, d["history_length"]),
    }
    if lops.grundwert is not None:
        given["grundwert"] = (lops.grundwert, d["grundwert"])
    for key, option in _lopscpp_options(lops):
        mine, started = given[key]
        same = mine == started if isinstance(mine, bool | int) else math.isclose(mine, started, rel_tol=1e-9)
        if not same:
            raise r.fail(
                lops.lines[key],
                f"{option}: {_shown(mine)} is lopscpp's, and the LOPS tokenring up --sensors darmstadt starts "
                f"runs with {_shown(started)} without reading this file (python -m modules.lops --config "
                "FILE takes it)",
            )


def _shown(value: Any) -> str:
    if isinstance(value, bool):
        return "yes" if value else "no"
    return f"{value:g}"


def _offline(section: Section, source: str) -> OfflineSection:
    r = Values(section, source)
    result = _file_name(r, "Ergebnisdatei", "result")
    errors = _file_name(r, "Fehlerdatei", "errors")
    synchronised = r.yes_no("Synchronisierte Daten", "synchronised")
    r.end()
    return OfflineSection(result, errors, synchronised, section.line, r.lines)


def _action(section: Section, source: str) -> ActionSection:
    r = Values(section, source)
    auto = r.yes_no("Auto", "auto")
    files: list[str | None] = [None, None, None]
    for n in (1, 2, 3):
        if r.more():
            files[n - 1] = _file_name(r, f"Datei {n}", f"file {n}")
    r.end()
    if auto and files[0] is None:
        raise r.fail(
            r.lines["auto"], "Auto is yes: Datei 1 (the action file driven at the start) must follow"
        )
    return ActionSection(auto, (files[0], files[1], files[2]), section.line, r.lines)
