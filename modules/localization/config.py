"""The localisation's configuration: one commented YAML file, validated with clear errors.

The seed's options (000, §5.1 and table B.1) in YAML: which sensors are used and what of each is
logged, the trigger (every ``period_ms`` of the trigger sensor's time on a fixed grid — ours, the
default — or the seed's sensor and count, or every K token rounds), sync on/off, filter on/off,
which data the filter uses, the odometry model, the wall file. ``config/localization.yaml`` in
the repository is the commented default; every key may be left out (the default applies), an
unknown key or a bad value is an error naming the file, line and key (exit code 2 on the command
line). A ``sync.trigger`` that sets ``count`` or ``min_period_ms`` but no ``mode`` is the count
trigger: what it meant before the period trigger existed (so older logs replay as they ran).

``sensors.<name>`` is each sensor's, as its file in :mod:`modules.localization.sensors` says
(its defaults, its own checks, the ``up --sensors`` sets that turn it on; the seed's
``synchronise`` and ``position`` switches among the settings every sensor has); the
filter's settings for the built-in sensors (``filter.compass``, ``filter.gyro``,
``filter.correlator``, ``lops``) stay here with the fusion they tune. ``ui`` and ``actions`` are
the operator console's (the seed's Benutzerschnittstelle and [Action]); the Localizer ignores them.

The seed's own file (table B.1: a ``.cfg``, or text that starts with a ``[Section]``) is read by
:mod:`modules.localization.seedconfig` and laid over :data:`REPOSITORY_SETTINGS`; its errors name
its lines too. Its values that are accepted but do not apply here are told, once each as
``file:line: [Section] option: why`` on standard error, while a command holds :func:`seed_notes`
open (``up --localizer``, ``console -C``, ``replay --config``); elsewhere (copro, the tests'
calls) nobody is told.
"""

from __future__ import annotations

import contextlib
import copy
import math
import os
import sys
from collections.abc import Callable, Iterator
from contextvars import ContextVar
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

from modules.localization.errors import MAX_VALUE, ConfigError
from modules.localization.logs import DEFAULT_DEBUG_LEVEL, DEFAULT_LOG_DIRECTORY
from modules.localization.sensors import names, registered
from tokenring import NumberLoader, YAMLStructureError, one_line

if TYPE_CHECKING:
    from modules.localization.seedconfig import SeedConfig

# fmt: off
#: the defaults of everything but ``sensors`` (each sensor's file has its own: :func:`defaults`)
CORE_DEFAULTS: dict[str, Any] = {
    "sync": {"enabled": True, "trigger": {"mode": "period", "sensor": "odometry", "period_ms": 100, "count": 1, "min_period_ms": 100, "rounds": 0}},
    "filter": {
        "enabled": True,
        "odometry_model": "arc",
        "estimate": ["glide", "compass_offset", "step_scale"],
        "initial_pose": "world",
        "compass": {"mode": "newest", "sigma_deg": 1.5, "north_deg": 90.0, "max_turn_rate_deg_s": 2.0, "settle_ms": 0},
        "gyro": {"sigma_deg": 0.05, "sigma_deg_s": 0.05, "scale_rel": 0.01, "max_turn_rate_deg_s": 2.0, "settle_ms": 400},
        "correlator": {"sigma_mm": 1.0, "sigma_rel": 0.03, "max_turn_rate_deg_s": 2.0},
        "travel": {"enabled": False, "max_incidence_deg": 8.0, "max_range_mm": 800.0, "model_sigma": 0.005, "unknown_wall": True, "unknown_wall_bound": False, "unknown_wall_bound_sigma": 0.0, "unknown_wall_max_sigma": 1.0, "wait_for_map": False, "check_at": "end"},
        "noise": {
            "distance_rel": 0.01,
            "rotation_rel": 0.02,
            "rotation_rad_per_mm": 0.0002,
            "glide_per_move_rel": 0.06,
            "step_scale_per_move": 0.005,
            "glide_walk_per_deg": 0.001,
            "compass_offset_walk_deg_per_s": 0.05,
            "step_scale_walk_per_m": 0.0005,
            "step_scale_mean_walk_per_move": 0.001,
        },
        "initial": {"sigma_mm": 20.0, "sigma_deg": 2.0, "glide_sigma": 0.3, "compass_offset_sigma_deg": 3.0, "step_scale": 1.0, "step_scale_sigma": 0.02, "step_scale_mean_sigma": 0.02},
        "gate_probability": 0.997,
        "valid_sigma_mm": 150.0,
        "valid_sigma_deg": 5.0,
    },
    "walls": {
        "mode": "darmstadt",
        "file": "square",
        "history": 60,
        "max_distance_mm": 1400.0,
        "side_sensors": [3, 4, 6, 7],
        "pairs": [[3, 4], [7, 6]],
        "min_points_side": 15,
        "min_span_side_mm": 150.0,
        "max_sigma_side_mm": 30.0,
        "min_points_pairs": 10,
        "max_sigma_d_pairs_mm": 35.0,
        "max_sigma_alpha_pairs_deg": 15.0,
        "noise_floor_mm": 5.0,
        "max_turn_deg": 0.5,
        "min_sigma_d_mm": 6.0,
        "min_sigma_alpha_deg": 0.7,
        "range_model": "axis",
        "max_beam_off_deg": 25.0,
        "sonar_late": {"from_mm": 700.0, "mm_per_m": 25.0, "mm_per_deg2": 0.055},
        "shared_sigma_mm": 0.0,
        "repeat_after_mm": 100.0,
        "bias_floor_mm": 0.0,
        "association": {"max_d_mm": 400.0, "max_alpha_deg": 20.0, "margin_mm": 150.0, "min_wall_length_mm": 500.0},
        "ahead": {"enabled": False, "sensors": [1], "max_range_mm": 1400.0, "max_off_deg": 20.0, "sigma_mm": 15.0, "oblique_from_deg": 20.0, "oblique_sigma_mm": 25.0, "clear_mm": 150.0, "max_innovation_mm": 150.0, "repeat_after_mm": 100.0, "max_turn_rate_deg_s": 2.0, "confirm_mm": 30.0, "confirm_within_ms": 1000},
    },
    "robot": {"mm_per_step": 0.5419, "steps_per_degree": 6.5, "sonars": "robot"},
    "lops": {"receivers": [], "sigma_mm": 10.0, "delay_ms": 15.0, "delay_sigma_ms": 10.0, "floor_mm": 3.0, "init": {"fixes": 5, "drive_mm": 300.0, "max_turn_deg": 2.0, "settle_ms": 500}},
    "logs": {"enabled": True, "directory": DEFAULT_LOG_DIRECTORY, "data": "localization-{start}.trlog", "errors": "localization-{start}.trerr", "error_log": True, "debug_level": DEFAULT_DEBUG_LEVEL, "debug": False},
    "ui": "ncurses",
    "actions": {"auto": False, "files": []},
}
# fmt: on


#: sensors.<name>'s settings a sensor that is not synchronised cannot have on
NEED_SYNCHRONISE = ("position", "log_sync", "filter")
#: the operator console's screens (the seed's Benutzerschnittstelle; none: the NoUserInterface)
UIS = ("stdout", "ncurses", "none")
#: the action files the console's keys a, b and c drive (table 8.2)
ACTION_FILES = 3


def defaults() -> dict[str, Any]:
    """Every setting's default: ``sensors.<name>`` from each registered sensor (its file's
    ``settings``, in synchronisation order), the rest from :data:`CORE_DEFAULTS`. A new copy."""
    sensors = {sensor.name: copy.deepcopy(dict(sensor.settings)) for sensor in registered()}
    return {"sensors": sensors, **copy.deepcopy(CORE_DEFAULTS)}


def __getattr__(name: str) -> Any:
    """The tables the sensor registry makes, worked out when read (PEP 562): :data:`DEFAULTS`
    (:func:`defaults`) and :data:`SENSOR_SET_CONFIG` (:func:`sensor_set_config` of each set)."""
    if name == "DEFAULTS":
        return defaults()
    if name == "SENSOR_SET_CONFIG":
        sets = sorted({each for sensor in registered() for each in sensor.sets})
        return {DEFAULT_SENSOR_SET: {}, **{each: sensor_set_config(each) for each in sets}}
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


#: what config/localization.yaml sets beyond the built-in defaults (issue 21): the sonar's
#: tangent range model with its late echo, the error a fit's points share, longer side lines, the
#: travel gauge's settings (out to 1.4 m, known walls only, checked where its ranges were read; off),
#: the compass's measured accuracy, no compass reading bent by the motors' start or stop, a floor
#: under the pose's σ across a wall (its fits share an error) and the floor's mean step scale as a
#: state, from which each move's scale starts, and the front and diagonal sonars' ranges to a wall
#: ahead (up to 25° off its normal, beyond 20° with a larger σ), and the floor's step scale calibrated on the
#: tuning drives (``tokenring calibrate``). The
#: built-in defaults keep the earlier values: exploration mode builds on them, and old logs replay
#: as they ran
REPOSITORY_SETTINGS: dict[str, Any] = {
    "filter": {
        "compass": {"sigma_deg": 0.5, "settle_ms": 400},
        "travel": {"enabled": False, "max_range_mm": 1400.0, "unknown_wall": False, "check_at": "points"},
        "estimate": ["glide", "compass_offset", "step_scale", "step_scale_mean"],
        "noise": {"compass_offset_walk_deg_per_s": 0.01},
        "initial": {"compass_offset_sigma_deg": 0.5, "step_scale": 1.0129, "step_scale_mean_sigma": 0.002},
    },
    "walls": {
        "range_model": "tangent",
        "shared_sigma_mm": 8.0,
        "min_span_side_mm": 220.0,
        "bias_floor_mm": 8.0,
        "ahead": {"enabled": True, "sensors": [0, 1, 2], "max_off_deg": 25.0},
    },
    "lops": {"delay_sigma_ms": 100.0},
}

ESTIMATES = ("glide", "compass_offset", "step_scale", "step_scale_mean")
#: sync.trigger.mode: every period_ms of the sensor's time on a fixed grid, or after count samples
TRIGGER_MODES = ("period", "count")


def default_config_path() -> Path:
    """``config/localization.yaml`` of the repository (the commented defaults)."""
    return Path(__file__).resolve().parents[2] / "config" / "localization.yaml"


#: the set ``tokenring up`` starts without ``--sensors``: the Hamburg robot's, none of the sets'
DEFAULT_SENSOR_SET = "hamburg"


def sensor_set_config(name: str) -> dict[str, Any]:
    """What ``tokenring up --sensors NAME`` turns on in the Localizer, laid under the
    configuration given (whose keys win): the sensors whose ``sets`` name it — for
    ``darmstadt`` the gyroscope, the floor correlator (logged, not fused: the seed never ran one)
    and LOPS; nothing for another set."""
    sensors = {sensor.name: {"use": True} for sensor in registered() if name in sensor.sets}
    return {"sensors": sensors} if sensors else {}


def sensor_set_layer(sensors: str | None, lops_receivers: list[list[float]] | None = None) -> dict[str, Any]:
    """What ``up --sensors`` lays beneath the Localizer's configuration: the set's sensors, and
    where the LOPS that ``up`` started put its receivers (so the filter can take its distances)."""
    under = sensor_set_config(sensors or DEFAULT_SENSOR_SET)
    if lops_receivers:
        under = layered(under, {"lops": {"receivers": [list(r) for r in lops_receivers]}})
    return under


def layered(under: dict[str, Any], over: Any) -> Any:
    """``over`` laid on ``under``, mapping by mapping: a key ``over`` names wins, whole."""
    if not isinstance(under, dict) or not isinstance(over, dict):
        return copy.deepcopy(over)
    out = copy.deepcopy(under)
    for key, value in over.items():
        out[key] = layered(out[key], value) if key in out else copy.deepcopy(value)
    return out


#: configurations that ship with tokenring, by name: ``--localizer early-ekf``
NAMED_CONFIGS = {"early-ekf": "early-ekf.yaml", "syncaria": "syncaria.cfg"}


def config_path(source: str | Path) -> Path:
    """The file a ``--localizer`` names: a path, or the name of a bundled configuration
    (:data:`NAMED_CONFIGS`) when no file of that name exists."""
    path = Path(source)
    if not path.exists() and str(source) in NAMED_CONFIGS:
        return default_config_path().with_name(NAMED_CONFIGS[str(source)])
    return path


def load_config(
    source: str | Path | dict | None = None, under: dict[str, Any] | None = None
) -> dict[str, Any]:
    """A validated configuration: ``None`` gives the defaults, else a file path, the name of a
    bundled one (:func:`config_path`) or a dict; ``under`` (a partial configuration, e.g. a
    sensor set's) lies beneath it. A path ending ``.cfg`` is the seed's file (table B.1), as is
    text that starts with a ``[Section]``; relative ``actions.files`` are the file's folder's."""
    if source is None:
        return validate(under, "<config>", {}) if under else defaults()
    if isinstance(source, dict):
        return validate(layered(under or {}, source), "<config>", {})
    from tokenring import message_error, read_text

    path = config_path(source)
    text = read_text(path, "configuration file", message_error(ConfigError))
    if path.suffix.lower() == ".cfg":
        return parse_seed_config(text, str(path), under)
    return parse_config(text, str(path), under)


def parse_seed_config(text: str, source: str, under: dict[str, Any] | None = None) -> dict[str, Any]:
    """The seed's configuration text (table B.1) as a validated configuration: what it says laid
    over :data:`REPOSITORY_SETTINGS`, ``under`` beneath both; errors carry ``source:line``."""
    from modules.localization.seedconfig import read_seed_config

    seed = read_seed_config(text, source)
    seed.check_beneath(under)
    data = layered(REPOSITORY_SETTINGS, seed.localization_layer())
    config = validate(layered(under, data) if under else data, source, seed.layer_lines())
    tell_notes(seed)
    return config


def read_seed_file(path: str | Path) -> SeedConfig:
    """The seed's file at ``path`` (table B.1) as it is written (what the operator's console
    reads of it: screen, action files, offline mode), its notes told as :func:`parse_seed_config`
    tells them."""
    from modules.localization.seedconfig import read_seed_config

    seed = read_seed_config(Path(path))
    tell_notes(seed)
    return seed


def _to_stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


#: who is told the notes of the seed files read (:func:`seed_notes`); None: none is open
_TOLD: ContextVar[Callable[[str], None] | None] = ContextVar("seed_notes", default=None)


@contextlib.contextmanager
def seed_notes(quiet: bool = False, say: Callable[[str], None] = _to_stderr) -> Iterator[None]:
    """While open, every seed file read (:func:`load_config`, :func:`read_seed_file`) tells
    ``say`` (standard error) each of its notes once, as ``file:line: [Section] option: why`` (the
    values accepted that do not apply here, :meth:`~modules.localization.seedconfig.SeedConfig.notes`);
    ``quiet`` tells nobody (``--json``). Opened inside an open one, the outer one's ``say`` and
    memory stay (``console -Moffline`` replays through ``replay``'s)."""
    if not quiet and _TOLD.get() is not None:
        yield
        return
    told: set[str] = set()

    def once(line: str) -> None:
        if not quiet and line not in told:
            told.add(line)
            say(line)

    token = _TOLD.set(once)
    try:
        yield
    finally:
        _TOLD.reset(token)


def tell_notes(seed: SeedConfig) -> None:
    """Tell the open :func:`seed_notes` the notes of ``seed`` (nobody, when none is open)."""
    say = _TOLD.get()
    if say is not None:
        for line in seed.note_lines():
            say(line)


def parse_config(text: str, source: str, under: dict[str, Any] | None = None) -> dict[str, Any]:
    """Parse and validate YAML text (or the seed's, when it starts with a ``[Section]``); errors
    carry ``source:line``."""
    from modules.localization.seedconfig import looks_like_seed_config

    if looks_like_seed_config(text):
        return parse_seed_config(text, source, under)
    try:
        node = yaml.compose(text, Loader=NumberLoader)
        data = yaml.load(text, Loader=NumberLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{source}:{mark.line + 1}" if mark is not None else source
        if isinstance(exc, YAMLStructureError):  # a recursive or exploding document, not a typo
            raise ConfigError(f"{where}: {exc.problem}") from None
        raise ConfigError(
            f"{where}: not valid YAML: {one_line(getattr(exc, 'problem', None) or exc)}"
        ) from None
    if data is None:
        data = {}  # an empty configuration is the defaults (tests/robot/localization/test_localizer_config.py)
    lines: dict[tuple[str, ...], int] = {}
    _collect_lines(node, (), lines)
    config = validate(layered(under, data) if under else data, source, lines)
    if not source.startswith("<"):
        folder = Path(source).parent
        files = config["actions"]["files"]
        config["actions"]["files"] = [
            f if f is None or Path(f).is_absolute() else os.path.abspath(folder / f) for f in files
        ]
    return config


def _collect_lines(node: Any, path: tuple[str, ...], out: dict[tuple[str, ...], int]) -> None:
    if isinstance(node, yaml.MappingNode):
        for key, value in node.value:
            sub = (*path, str(key.value))
            out[sub] = key.start_mark.line + 1
            _collect_lines(value, sub, out)


def validate(data: Any, source: str, lines: dict[tuple[str, ...], int]) -> dict[str, Any]:
    """Merge ``data`` over the defaults, checking every key and value."""
    checker = _Checker(source, lines)
    config = checker.merge(defaults(), data, ())
    trigger = data.get("sync", {}).get("trigger", {}) if isinstance(data, dict) else {}
    if isinstance(trigger, dict) and "mode" not in trigger and {"count", "min_period_ms"} & set(trigger):
        config["sync"]["trigger"]["mode"] = "count"  # written for the count trigger
    checker.debug_level(config, data)
    checker.switches(config, data)
    checker.semantics(config)
    return config


class _Checker:
    def __init__(self, source: str, lines: dict[tuple[str, ...], int]) -> None:
        self.source = source
        self.lines = lines

    def fail(self, path: tuple[str, ...], problem: str) -> ConfigError:
        line = None
        for cut in range(len(path), 0, -1):
            line = self.lines.get(path[:cut])
            if line is not None:
                break
        where = f"{self.source}:{line}" if line is not None else self.source
        key = ".".join(path) if path else "(top level)"
        return ConfigError(f"{where}: {key}: {problem}")

    def merge(self, default: Any, value: Any, path: tuple[str, ...]) -> Any:
        if isinstance(default, dict):
            if not isinstance(value, dict):
                raise self.fail(path, f"expected a mapping with keys {', '.join(default)}")
            out = copy.deepcopy(default)
            for key, sub in value.items():
                if key not in default:
                    raise self.fail((*path, str(key)), f"unknown key (known here: {', '.join(default)})")
                out[key] = self.merge(default[key], sub, (*path, key))
            return out
        return self.leaf(default, value, path)

    def leaf(self, default: Any, value: Any, path: tuple[str, ...]) -> Any:
        if isinstance(default, bool):
            if not isinstance(value, bool):
                raise self.fail(path, f"expected true or false, got {value!r}")
            return value
        if isinstance(default, int):
            if isinstance(value, bool) or not isinstance(value, int):
                raise self.fail(path, f"expected a whole number, got {value!r}")
            if value < 0:
                raise self.fail(path, f"must not be negative, got {value}")
            if value > MAX_VALUE:
                raise self.fail(path, f"must be within 0..{MAX_VALUE:g}, got {value}")
            return value
        if isinstance(default, float):
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                raise self.fail(path, f"expected a number, got {value!r}")
            if value < 0:
                raise self.fail(path, f"must not be negative, got {value}")
            if value > MAX_VALUE:
                raise self.fail(path, f"must be within 0..{MAX_VALUE:g}, got {value:g}")
            return float(value)
        if isinstance(default, str):
            return self.text_or_special(value, path)
        if isinstance(default, list):
            if not isinstance(value, list):
                raise self.fail(path, f"expected a list, got {value!r}")
            return value
        raise self.fail(path, "unsupported value")  # pragma: no cover - DEFAULTS is fixed

    def text_or_special(self, value: Any, path: tuple[str, ...]) -> Any:
        if path == ("filter", "initial_pose") and isinstance(value, dict):
            return value
        if path == ("robot", "sonars") and isinstance(value, list):
            return value
        if not isinstance(value, str) or not value:
            raise self.fail(path, f"expected text, got {value!r}")
        return value

    def debug_level(self, c: dict[str, Any], data: Any) -> None:
        """``logs.debug_level`` (the seed's Debuglevel, 0-4) and the older ``logs.debug``, read as
        4 (true) or 3 (false): one given sets the other; both must agree."""
        logs = data.get("logs") if isinstance(data, dict) else None
        given = set(logs) & {"debug", "debug_level"} if isinstance(logs, dict) else set()
        level = c["logs"]["debug_level"]
        if not 0 <= level <= 4:
            raise self.fail(
                ("logs", "debug_level"),
                f"must be 0-4 (0 fatal only, 1 +errors, 2 +warnings, 3 +information, 4 +debug), got {level}",
            )
        if given == {"debug"}:
            c["logs"]["debug_level"] = 4 if c["logs"]["debug"] else DEFAULT_DEBUG_LEVEL
        elif given == {"debug", "debug_level"} and c["logs"]["debug"] != (level >= 4):
            raise self.fail(
                ("logs", "debug"),
                f"{c['logs']['debug']} says debug level {4 if c['logs']['debug'] else 3}, but debug_level is "
                f"{level}: give debug_level alone (debug is its older form)",
            )
        c["logs"]["debug"] = c["logs"]["debug_level"] >= 4

    def switches(self, c: dict[str, Any], data: Any) -> None:
        """A sensor that is not synchronised has no synchronised data: no position, nothing to log
        or to filter (those of its settings written on are an error, the others are off); the
        odometry's synchronisation cannot be off (the others are carried along its track)."""
        written = data.get("sensors") if isinstance(data, dict) else None
        for name, settings in c["sensors"].items():
            if settings["synchronise"]:
                continue
            if name == "odometry" and settings["use"]:
                raise self.fail(
                    ("sensors", name, "synchronise"),
                    "the odometry's synchronised steps are the track every other sensor's samples are "
                    "carried along, and dead reckoning's: it cannot be off alone (sync.enabled: false)",
                )
            own = written.get(name) if isinstance(written, dict) else None
            for key in NEED_SYNCHRONISE:
                if isinstance(own, dict) and own.get(key) is True:
                    raise self.fail(
                        ("sensors", name, key),
                        "needs the sensor's synchronised data, and synchronise is false (with it, "
                        f"{', '.join(NEED_SYNCHRONISE)} are false or left out)",
                    )
                settings[key] = False
        for name, settings in c["sensors"].items():
            if not settings["position"]:
                own = written.get(name) if isinstance(written, dict) else None
                if isinstance(own, dict) and own.get("log_position") is True:
                    raise self.fail(
                        ("sensors", name, "log_position"),
                        "no position is computed (position or synchronise is false)",
                    )
                settings["log_position"] = False

    def semantics(self, c: dict[str, Any]) -> None:
        def choice(path: tuple[str, ...], allowed: tuple[str, ...]) -> None:
            value = _get(c, path)
            if value not in allowed:
                raise self.fail(path, f"must be one of {', '.join(allowed)}, got {value!r}")

        trigger = c["sync"]["trigger"]
        if trigger["rounds"] == 0:
            choice(("sync", "trigger", "mode"), TRIGGER_MODES)
            choice(("sync", "trigger", "sensor"), names())
            if trigger["mode"] == "period" and trigger["period_ms"] < 1:
                raise self.fail(("sync", "trigger", "period_ms"), "must be at least 1 (ms of sensor time)")
            if trigger["mode"] == "count" and trigger["count"] < 1:
                raise self.fail(("sync", "trigger", "count"), "must be at least 1")
            if not c["sensors"][trigger["sensor"]]["use"]:
                raise self.fail(
                    ("sync", "trigger", "sensor"),
                    f"{trigger['sensor']} is not used (sensors.{trigger['sensor']}.use)",
                )
        choice(("filter", "odometry_model"), ("arc", "straight"))
        choice(("filter", "compass", "mode"), ("newest", "mean"))
        choice(("walls", "mode"), ("darmstadt", "exploration", "off"))
        choice(("walls", "range_model"), ("tangent", "axis"))
        choice(("filter", "travel", "check_at"), ("end", "points"))
        for name in c["filter"]["estimate"]:
            if name not in ESTIMATES:
                raise self.fail(
                    ("filter", "estimate"), f"unknown state {name!r} (known: {', '.join(ESTIMATES)})"
                )
        if "step_scale_mean" in c["filter"]["estimate"] and "step_scale" not in c["filter"]["estimate"]:
            raise self.fail(("filter", "estimate"), "step_scale_mean needs step_scale")
        if not 0.5 <= c["filter"]["initial"]["step_scale"] <= 1.5:
            raise self.fail(
                ("filter", "initial", "step_scale"),
                f"must lie between 0.5 and 1.5 (true step / nominal), got {c['filter']['initial']['step_scale']}",
            )
        pose = c["filter"]["initial_pose"]
        if isinstance(pose, dict):
            keys = {"x_mm", "y_mm", "heading_deg"}
            if set(pose) != keys or not all(
                isinstance(v, int | float) and not isinstance(v, bool) for v in pose.values()
            ):
                raise self.fail(
                    ("filter", "initial_pose"), "expected world, motor or {x_mm, y_mm, heading_deg} numbers"
                )
        elif pose not in ("world", "motor", "lops"):
            raise self.fail(
                ("filter", "initial_pose"),
                f"expected world, motor, lops or {{x_mm, y_mm, heading_deg}}, got {pose!r}",
            )
        if pose == "lops" and not c["sensors"]["lops"]["use"]:
            raise self.fail(
                ("filter", "initial_pose"),
                "lops: the position is initialised by LOPS, which is not used (sensors.lops.use)",
            )
        if c["lops"]["init"]["fixes"] < 1 or c["lops"]["init"]["drive_mm"] <= 0:
            raise self.fail(("lops", "init"), "fixes must be at least 1 and drive_mm positive")
        for each in registered():  # each sensor's own (the truth: never fused)
            if each.check_settings is not None:
                each.check_settings(c, self.fail)
        receivers = c["lops"]["receivers"]
        if receivers and not (
            len(receivers) == 3
            and all(
                isinstance(r, list) and len(r) == 2
                and all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) and abs(v) <= MAX_VALUE for v in r)
                for r in receivers
            )
        ):  # fmt: skip
            raise self.fail(
                ("lops", "receivers"), "expected three [x_mm, y_mm] pairs of numbers, LOPS's receivers"
            )
        if c["sensors"]["lops"]["filter"] and not receivers:
            raise self.fail(
                ("sensors", "lops", "filter"),
                "the filter takes LOPS's distances to its receivers: give lops.receivers (up --sensors darmstadt does)",
            )
        for sensor, positive in (
            ("gyro", ("sigma_deg", "sigma_deg_s", "scale_rel")),
            ("correlator", ("sigma_mm", "sigma_rel")),
        ):
            for key in positive:
                if c["filter"][sensor][key] <= 0:
                    raise self.fail(("filter", sensor, key), "must be positive")
        if c["lops"]["sigma_mm"] <= 0:
            raise self.fail(("lops", "sigma_mm"), "must be positive")
        p = c["filter"]["gate_probability"]
        if not 0.5 <= p < 1.0:
            raise self.fail(("filter", "gate_probability"), f"must be in [0.5, 1), got {p}")
        for key in ("mm_per_step", "steps_per_degree"):
            if c["robot"][key] <= 0:
                raise self.fail(("robot", key), "must be positive")
        sonars = c["robot"]["sonars"]
        if isinstance(sonars, str):
            if sonars != "robot":
                raise self.fail(
                    ("robot", "sonars"),
                    "expected robot (modules/description/robot.py) or a list of [x_mm, y_mm, angle_deg]",
                )
            count = 8
        else:
            for i, m in enumerate(sonars):
                if not (isinstance(m, list) and len(m) == 3 and all(isinstance(v, int | float) for v in m)):
                    raise self.fail(
                        ("robot", "sonars"), f"entry {i}: expected [x_mm, y_mm, angle_deg], got {m!r}"
                    )
            count = len(sonars)
        walls = c["walls"]
        for i in walls["side_sensors"]:
            if not isinstance(i, int) or not 0 <= i < count:
                raise self.fail(("walls", "side_sensors"), f"sonar index {i!r} is not in 0..{count - 1}")
        for i in walls["ahead"]["sensors"]:
            if not isinstance(i, int) or not 0 <= i < count:
                raise self.fail(("walls", "ahead", "sensors"), f"sonar index {i!r} is not in 0..{count - 1}")
        for pair in walls["pairs"]:
            if not (
                isinstance(pair, list)
                and len(pair) == 2
                and all(isinstance(i, int) and 0 <= i < count for i in pair)
            ):
                raise self.fail(
                    ("walls", "pairs"), f"expected pairs of sonar indices 0..{count - 1}, got {pair!r}"
                )
        for key in ("min_points_side", "min_points_pairs"):
            if walls[key] < 3:
                raise self.fail(("walls", key), "needs at least 3 points to fit a line")
        if walls["mode"] == "darmstadt" and not walls["file"]:
            raise self.fail(("walls", "file"), "Darmstadt mode needs a wall file (a world name or path)")
        for key in ("data", "errors"):
            name = c["logs"][key]
            try:
                name.format(start="x")
            except (KeyError, IndexError, ValueError):
                raise self.fail(("logs", key), f"only {{start}} may be substituted in {name!r}") from None
        choice(("ui",), UIS)
        actions = c["actions"]
        files = actions["files"]
        if len(files) > ACTION_FILES or not all(f is None or (isinstance(f, str) and f) for f in files):
            raise self.fail(
                ("actions", "files"), f"expected up to {ACTION_FILES} file names (or null), got {files!r}"
            )
        if actions["auto"] and not (files and files[0]):
            raise self.fail(
                ("actions", "auto"), "true drives the first of actions.files at the start: name it"
            )


def _get(config: dict[str, Any], path: tuple[str, ...]) -> Any:
    value: Any = config
    for key in path:
        value = value[key]
    return value


def dump_defaults() -> str:
    """The defaults as YAML (what ``config/localization.yaml`` spells out with comments)."""
    return yaml.safe_dump(defaults(), sort_keys=False)
