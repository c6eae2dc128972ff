"""The seed's logfileanalyser output (seed 000, §9.2, appendix B.4): ``tokenring analyze LOG
--seed-out DIR``.

In ``DIR`` one subdirectory per module, named as the seed named them: ``position``,
``odometrie``, ``gyroskop``, ``lops``, ``sonar`` and ``time``. Each holds its data files in
table B.9's format — one line per measurement, each field right-aligned in the table's width,
one blank between fields — and ``command``, the gnuplot control file: ``gnuplot command``
inside the directory draws the module's plot (``<module>.png`` with the default terminal).

==========================  ===============================================  ===============
file                        fields (table B.9's widths)                      from the log
==========================  ===============================================  ===============
position/<name>             X 8, Y 8 (mm)                                    ``x P``, x and y valid
odometrie/links, rechts     time 8 (ms), the wheel's increment 8 (ticks)     ``O C``
gyroskop/gyroskop           time 8 (ms), rate 15 (rad, the angle of one      ``G R``
                            sample: the seed's ``G R`` value, figure 10.2)
lops/empfaenger1..3         time 8 (ms), distance 8 (mm; none heard: no      ``L R``
                            line)
sonar/empfaenger0..N-1      time 8 (ms), distance 8 (mm; no contact: no      ``W R``
                            line); one file per sonar of the log, numbered
                            from 0 as the robot's mounts are
time/synchronisation        time 8 (ms), the ms since the one before 5       ``S S``
time/<sensor>               time 8 (ms), the ms since its sample before 5    ``R`` of the sensor
==========================  ===============================================  ===============

``DIR/logfile.cfg`` (the seed's default name) is the configuration in table B.2's format that
makes this output: ``--seed-config FILE`` reads such a file (the seed's own, figure 10.1, or one
written here and edited) and honours its six plot switches, its gnuplot terminals and its
styles, which positions it plots and which sensors the time module shows. A module the log has
no data for gets no directory, and one line says so.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
import re
import shutil
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from modules.localization.records import seed_int
from modules.localization.sensors import registered, sensor_named, sensor_of_letter
from tokenring import UsageError

#: the modules in table B.2's order of the plot switches ([MAIN]: Pfadplot, LOPS-Plot,
#: Gyroskopplot, Odometrieplot, Sonarplot, Timeplot), each its subdirectory's name
MODULES = ("position", "lops", "gyroskop", "odometrie", "sonar", "time")
#: what each module shows, for the lines that say a module has no data
TITLES = {
    "position": "positions with x and y (x P)",
    "lops": "LOPS records (L R)",
    "gyroskop": "gyroscope records (G R)",
    "odometrie": "synchronised odometry records (O C)",
    "sonar": "sonar records (W R)",
    "time": "synchronisations (S S) or sensors with two raw records",
}
#: the configuration file's default name (seed §9.2: "wird die Datei logfile.cfg verwendet")
CONFIG_NAME = "logfile.cfg"
#: the sonar styles table B.2's [SONAR] section lists ("für alle 16 Sonarsensoren")
SEED_SONARS = 16
#: the seed's LOPS receivers (figure 10.1's [Lops] section: three styles)
RECEIVERS = 3
#: the terminal written when none is given: a PNG, as Debian's gnuplot-nox has it
DEFAULT_TERMINAL = "pngcairo size 900,600"
DEFAULT_POSITION_TERMINAL = "pngcairo size 800,800"

#: the style of the modules' scattered values (the seed's figure 10.1 has ``dots``: a pixel each,
#: which it drew as vectors; in a PNG a small disc shows, and its key too)
DOTS = "points pt 7 ps 0.3"
#: gnuplot's plotting styles for two columns (``plot ... with STYLE``)
STYLES = ("lines", "points", "linespoints", "impulses", "dots", "steps", "fsteps", "histeps", "boxes")
#: a style's or a terminal's further words (``lines lw 2``, ``pngcairo size 800,600 font
#: 'Arial,10'``): never a ``;`` (a second command) nor a backquote (a shell command)
_WORD = re.compile(r"[A-Za-z0-9_.,:+='-]+")
#: the terminals that draw on the screen (no output file; gnuplot waits for the window to close)
SCREEN_TERMINALS = ("x11", "wxt", "qt", "aqua", "windows")
#: a terminal's output file's extension (others: the terminal's name)
EXTENSIONS = {
    "pngcairo": "png",
    "png": "png",
    "jpeg": "jpg",
    "gif": "gif",
    "svg": "svg",
    "pdfcairo": "pdf",
    "pdf": "pdf",
    "postscript": "ps",
    "epscairo": "eps",
    "fig": "fig",
    "dumb": "txt",
    "canvas": "html",
    "epslatex": "tex",
    "cairolatex": "tex",
}

#: the seed's position names (figure 10.1's [Position]: kalman, lops, odometrie) and ours: any
#: registered sensor's name names its position
SEED_POSITION_NAMES = {"kalman": "K", "filter": "K", "odometrie": "O"}


class SeedConfigError(UsageError):
    """A table B.2 file that cannot be honoured; the message names the file and line."""


# =============================================================================================
# the log's data, by module


@dataclass
class SeedData:
    """What the modules take from a data log, in log order."""

    positions: dict[str, list[tuple[float, float]]] = field(default_factory=dict)  # letter: (x, y)
    wheels: list[tuple[int, float, float]] = field(default_factory=list)  # (stamp, left, right)
    gyro: list[tuple[int, float]] = field(default_factory=list)  # (stamp, rad per sample)
    lops: list[list[tuple[int, float]]] = field(default_factory=lambda: [[] for _ in range(RECEIVERS)])
    sonar: list[list[tuple[int, int]]] = field(default_factory=list)  # per sonar (stamp, mm)
    sonars: int = 0  # how many sonars the log's sweeps carried
    stamps: dict[str, list[int]] = field(default_factory=dict)  # sensor name: its raw stamps
    syncs: list[int] = field(default_factory=list)


def collect(records: list[list[Any]]) -> SeedData:
    """The modules' data from a data log's records."""
    from modules.localization.sensors.gyro import GYRO_SAMPLE_S
    from modules.localization.sync import NO_CONTACT_CM

    data = SeedData()
    for stamp, source, kind, p in records:
        if kind == "P":
            valid = p.get("valid", [True, True, True])
            if valid[0] and valid[1] and math.isfinite(float(p["x"])) and math.isfinite(float(p["y"])):
                data.positions.setdefault(source, []).append((float(p["x"]), float(p["y"])))
        elif (source, kind) == ("S", "S"):
            data.syncs.append(stamp)
        elif (source, kind) == ("O", "C"):
            data.wheels.append((stamp, float(p["dl"]), float(p["dr"])))
        elif kind == "R":
            sensor = sensor_of_letter(source)
            if sensor is not None:
                data.stamps.setdefault(sensor.name, []).append(stamp)
            values = p.get("v", {})
            if source == "G" and "rate_urad_s" in values:
                # the seed's G R: the angle of one 20.48 ms sample (figure B.3, figure 10.2)
                data.gyro.append((stamp, float(values["rate_urad_s"]) / 1e6 * GYRO_SAMPLE_S))
            elif source == "L" and "counter" in values:
                for i, key in enumerate(("d1", "d2", "d3")):
                    d = values.get(key)
                    if d is not None and math.isfinite(float(d)):
                        data.lops[i].append((stamp, float(d)))
            elif source == "W" and "distances" in values:
                distances = values["distances"]
                while len(data.sonar) < len(distances):
                    data.sonar.append([])
                data.sonars = max(data.sonars, len(distances))
                for i, cm in enumerate(distances):
                    if cm != NO_CONTACT_CM:
                        data.sonar[i].append((stamp, int(cm) * 10))
    return data


def position_letter(name: str) -> str | None:
    """The source a position name names: the seed's (kalman, odometrie) or a sensor's name."""
    if name in SEED_POSITION_NAMES:
        return SEED_POSITION_NAMES[name]
    sensor = sensor_named(name)
    return sensor.letter if sensor is not None and sensor.position is not None else None


def position_name(letter: str) -> str:
    """What :file:`logfile.cfg` calls a position source: the seed's name, else its sensor's."""
    seed = {"K": "kalman", "O": "odometrie"}
    if letter in seed:
        return seed[letter]
    sensor = sensor_of_letter(letter)
    return sensor.name if sensor is not None else letter


def position_names() -> list[str]:
    """Every position name a configuration may give."""
    return [*SEED_POSITION_NAMES, *(s.name for s in registered() if s.position is not None)]


# =============================================================================================
# the configuration (table B.2)


@dataclass
class SeedConfig:
    """Table B.2's values: [MAIN] the log, the output directory and the six plot switches; per
    module its gnuplot terminal (``Format``) and styles; the positions to plot and the sensors
    the time module shows, each with its style."""

    log: str
    output: str
    plots: dict[str, bool]
    terminals: dict[str, str]
    positions: list[tuple[str, str]]
    odometry: tuple[str, str] = ("lines", "lines")
    gyro: str = DOTS
    lops: tuple[str, ...] = (DOTS,) * RECEIVERS
    sonar: tuple[str, ...] = (DOTS,) * SEED_SONARS
    sync: bool = True
    sync_style: str = DOTS
    timed: list[tuple[str, str]] = field(default_factory=list)
    #: where the [SONAR] styles were read (file:line; empty: not read from a file)
    sonar_at: str = ""


def default_config(data: SeedData, log: str, output: str) -> SeedConfig:
    """Every module on, a PNG each; every position with x and y the log has (the filter, dead
    reckoning, LOPS, ours), every sensor with raw samples in the time module."""
    letters = sorted(data.positions, key=lambda s: (s != "K", s != "O", s != "L", s))
    return SeedConfig(
        log=log,
        output=output,
        plots=dict.fromkeys(MODULES, True),
        terminals={m: DEFAULT_POSITION_TERMINAL if m == "position" else DEFAULT_TERMINAL for m in MODULES},
        positions=[(position_name(letter), "lines") for letter in letters],
        timed=[(s.name, DOTS) for s in registered() if len(data.stamps.get(s.name, [])) > 1],
    )


def _value(text: str) -> str:
    """A value as table B.2's files hold it: in double quotes when it has blanks."""
    if any(c in text for c in '#["\n\r'):
        raise UsageError(f"{text!r}: a value of the seed's configuration files holds no # [ or \"")
    return f'"{text}"' if not text or any(c.isspace() for c in text) else text


def _yes(flag: bool) -> str:
    return "yes" if flag else "no"


def config_text(config: SeedConfig) -> str:
    """``config`` as a table B.2 file (figure 10.1's layout, with comments naming the values)."""
    t = config.terminals
    lines = [
        "# the seed's logfileanalyser configuration (seed 000, table B.2), written by",
        "# tokenring analyze --seed-out; read back with --seed-config. Values by position.",
        "[MAIN]",
        "# Logdatei: the data log analysed; Output: the output directory",
        _value(config.log),
        _value(config.output),
        "# Pfadplot LOPS-Plot Gyroskopplot Odometrieplot Sonarplot Timeplot",
        " ".join(_yes(config.plots[m]) for m in MODULES),
        "",
        "[POSITION]",
        "# Format: the gnuplot terminal and its options; then per position its name and style",
        _value(t["position"]),
        *(f"{_value(name)} {_value(style)}" for name, style in config.positions),
        "",
        "[LOPS]",
        "# Format; the styles of the three receivers (figure 10.1)",
        _value(t["lops"]),
        " ".join(_value(s) for s in config.lops),
        "",
        "[ODOMETRY]",
        "# Format; the styles of the left and the right wheel",
        _value(t["odometrie"]),
        " ".join(_value(s) for s in config.odometry),
        "",
        "[GYROSCOP]",
        "# Format; the style of the rates",
        _value(t["gyroskop"]),
        _value(config.gyro),
        "",
        "[SONAR]",
        f"# Format; the styles of the sonars 0 to {SEED_SONARS - 1} (the robot's have files)",
        _value(t["sonar"]),
        " ".join(_value(s) for s in config.sonar[: SEED_SONARS // 2]),
        " ".join(_value(s) for s in config.sonar[SEED_SONARS // 2 :]),
        "",
        "[TIME]",
        "# Format; the synchronisation (yes/no) and its style; then per sensor its name and style",
        _value(t["time"]),
        _yes(config.sync),
        _value(config.sync_style),
        *(f"{_value(name)} {_value(style)}" for name, style in config.timed),
    ]
    return "\n".join(lines) + "\n"


# =============================================================================================
# the gnuplot control files


def output_name(module: str, terminal: str) -> str | None:
    """The file gnuplot writes with ``terminal`` (None: it draws on the screen)."""
    name = terminal.split()[0]
    if name in SCREEN_TERMINALS:
        return None
    return f"{module}.{EXTENSIONS.get(name, name)}"


def command_text(
    module: str, terminal: str, title: str, labels: tuple[str, str], curves: list[tuple[str, str, str]]
) -> str:
    """The gnuplot control file ``command``: ``curves`` are (data file, title, style)."""
    output = output_name(module, terminal)
    lines = [
        f"# the seed's logfileanalyser, module {module}: run `gnuplot command` in this directory",
        f"set terminal {terminal}",
        *([f"set output '{output}'"] if output is not None else []),
        f"set title '{title}'",
        f"set xlabel '{labels[0]}'",
        f"set ylabel '{labels[1]}'",
        "set grid",
        *(["set size ratio -1", "set key below"] if module == "position" else ["set key outside right top"]),
        "plot \\",
    ]
    plots = [f"  '{file}' using 1:2 title '{name}' with {style}" for file, name, style in curves]
    lines.append(", \\\n".join(plots))
    if output is None:
        lines.append("pause mouse close")
    return "\n".join(lines) + "\n"


# =============================================================================================
# the modules' files


def _time_rows(points: Sequence[tuple[int, float]], width: int) -> str:
    return "".join(f"{stamp:8d} {seed_int(value, width)}\n" for stamp, value in points)


@dataclass
class Module:
    """One module's output: its files (name: text, ``command`` among them) or why it has none."""

    name: str
    files: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)


def modules(data: SeedData, config: SeedConfig) -> list[Module]:
    """Every module the configuration turns on, with its files; one without data has none and
    a note why (as has a position or a sensor listed but not in the log)."""
    out: list[Module] = []
    t = config.terminals
    for name in MODULES:
        if not config.plots[name]:
            continue
        module = Module(name)
        curves: list[tuple[str, str, str]] = []
        if name == "position":
            for source, style in config.positions:
                letter = position_letter(source)
                rows = data.positions.get(letter or "", [])
                if not rows:
                    module.notes.append(f"the log has no {source} position with x and y: not plotted")
                    continue
                module.files[source] = "".join(f"{seed_int(x, 8)} {seed_int(y, 8)}\n" for x, y in rows)
                curves.append((source, source, style))
            labels, title = ("x [mm]", "y [mm]"), "positions"
        elif name == "odometrie":
            if data.wheels:
                module.files["links"] = _time_rows([(s, dl) for s, dl, _ in data.wheels], 8)
                module.files["rechts"] = _time_rows([(s, dr) for s, _, dr in data.wheels], 8)
                curves = [("links", "left", config.odometry[0]), ("rechts", "right", config.odometry[1])]
            labels, title = ("time [ms]", "increment [ticks]"), "encoder increments per synchronisation"
        elif name == "gyroskop":
            if data.gyro:
                module.files["gyroskop"] = "".join(f"{s:8d} {v:15.12f}\n" for s, v in data.gyro)
                curves = [("gyroskop", "gyroscope", config.gyro)]
            labels, title = ("time [ms]", "rate [rad per 20.48 ms sample]"), "gyroscope"
        elif name == "lops":
            for i, points in enumerate(data.lops):
                if points:
                    module.files[f"empfaenger{i + 1}"] = _time_rows(points, 8)
                    curves.append((f"empfaenger{i + 1}", f"receiver {i + 1}", config.lops[i]))
            labels, title = ("time [ms]", "distance [mm]"), "LOPS: distances to the receivers"
        elif name == "sonar":
            for i in range(data.sonars):
                if i >= len(config.sonar):
                    at = f"{config.sonar_at}: " if config.sonar_at else ""
                    raise SeedConfigError(
                        f"{at}[SONAR] has {len(config.sonar)} styles; the log has {data.sonars} sonars"
                    )
                if data.sonar[i]:
                    module.files[f"empfaenger{i}"] = _time_rows(data.sonar[i], 8)
                    curves.append((f"empfaenger{i}", f"sonar {i}", config.sonar[i]))
            labels, title = ("time [ms]", "distance [mm]"), "sonar distances (no contact not drawn)"
        else:  # time
            series: list[tuple[str, list[int], str]] = []
            if config.sync:
                series.append(("synchronisation", data.syncs, config.sync_style))
            series += [(sensor, data.stamps.get(sensor, []), style) for sensor, style in config.timed]
            for file, stamps, style in series:
                if len(stamps) < 2:
                    module.notes.append(f"the log has fewer than two {file} time stamps: not plotted")
                    continue
                module.files[file] = "".join(f"{b:8d} {b - a:5d}\n" for a, b in itertools.pairwise(stamps))
                curves.append((file, file, style))
            labels, title = ("time [ms]", "cycle time [ms]"), "cycle times"
        if curves:
            module.files["command"] = command_text(name, t[name], title, labels, curves)
        else:
            module.files = {}
            module.notes.append(f"the log has no {TITLES[name]}: no {name}/ written")
        out.append(module)
    return out


# =============================================================================================
# writing


def existing_outputs(out: Path) -> list[Path]:
    """What ``--seed-out DIR`` would replace: the modules' directories and the configuration."""
    return [p for p in [*(out / m for m in MODULES), out / CONFIG_NAME] if p.exists() or p.is_symlink()]


def _write_directory(target: Path, files: dict[str, str]) -> None:
    """``files`` as the directory ``target``: written whole beside it, then renamed into its
    place (an older one moved aside first, removed once the new one is in)."""
    temp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent))
    old: Path | None = None
    try:
        os.chmod(temp, 0o755)
        for name, text in files.items():
            (temp / name).write_text(text, encoding="utf-8")
        if target.exists() or target.is_symlink():
            old = Path(tempfile.mkdtemp(prefix=f".{target.name}.old.", dir=target.parent))
            os.rename(target, old / target.name)
        os.rename(temp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            shutil.rmtree(temp)
        if old is not None and not target.exists():
            with contextlib.suppress(OSError):
                os.rename(old / target.name, target)  # the older one back where it was
        raise
    finally:
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)


def write_seed_out(
    records: list[list[Any]],
    out: str | Path,
    config: SeedConfig | None,
    log_name: str,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Write the seed's logfileanalyser output of a data log's records into ``out`` (checked by
    the caller: nothing there to keep); ``config`` None: :func:`default_config`. Returns what
    was written and why a module or a curve was not."""
    from tokenring import option_error, write_atomically, write_failed

    folder = Path(out)
    data = collect(records)
    config = config or default_config(data, log_name, str(out))
    written = modules(data, config)  # before anything is written: a bad style count is an error
    error = option_error("--seed-out")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise write_failed(folder, exc, error) from None
    report: dict[str, Any] = {"dir": str(folder), "modules": {}, "notes": []}
    for module in written:
        target = folder / module.name
        report["notes"] += [f"{module.name}: {note}" for note in module.notes]
        if module.files:
            try:
                _write_directory(target, module.files)
            except OSError as exc:
                raise write_failed(target, exc, error) from None
            report["modules"][module.name] = sorted(module.files)
            if progress is not None:
                count = len(module.files) - 1
                progress(f"{module.name}/ ({count} data file{'s' if count > 1 else ''} and command)")
        elif target.exists() and target.is_dir():
            shutil.rmtree(target)  # --force: an older run's module must not sit beside this run's
    for name in MODULES:
        if name not in report["modules"] and (folder / name).is_dir() and not config.plots[name]:
            shutil.rmtree(folder / name)  # switched off: not this run's output either
    write_atomically(folder / CONFIG_NAME, config_text(config), error)
    if progress is not None:
        progress(CONFIG_NAME)
    return report


# =============================================================================================
# reading a table B.2 file

Value = tuple[str, int]  # a value and its line


def _sections(text: str, source: str) -> dict[str, tuple[int, list[Value]]]:
    """The file's sections by upper-case name: the heading's line and the values in order,
    each with its line (the appendix-B reader's, :func:`modules.localization.seedconfig.read_sections`)."""
    from modules.localization.seedconfig import read_sections

    out: dict[str, tuple[int, list[Value]]] = {}
    for section in read_sections(text, source):
        name = section.name.upper()
        if name in out:
            raise SeedConfigError(
                f"{source}:{section.line}: [{section.name}] again (first at line {out[name][0]})"
            )
        out[name] = (section.line, [(v.text, v.line) for v in section.values])
    return out


#: table B.2's sections, by the module each configures (figure 10.1's spellings as aliases)
SECTIONS = {
    "MAIN": "main",
    "POSITION": "position",
    "LOPS": "lops",
    "ODOMETRY": "odometrie",
    "ODOMETRIE": "odometrie",
    "GYROSCOP": "gyroskop",
    "GYROSKOP": "gyroskop",
    "GYROSCOPE": "gyroskop",
    "SONAR": "sonar",
    "TIME": "time",
}


class _Section:
    """A section's values read one after another, each problem naming the file and line."""

    def __init__(self, source: str, name: str, line: int, values: list[Value]) -> None:
        self.source, self.name, self.line, self.values, self.next = source, name, line, values, 0

    def fail(self, problem: str, line: int | None = None) -> SeedConfigError:
        return SeedConfigError(f"{self.source}:{line or self.line}: [{self.name}] {problem}")

    def left(self) -> int:
        return len(self.values) - self.next

    def take(self, what: str) -> Value:
        if self.next >= len(self.values):
            last = self.values[-1][1] if self.values else self.line
            raise self.fail(f"ends before its {what} (table B.2)", last)
        value = self.values[self.next]
        self.next += 1
        return value

    def yes(self, what: str) -> bool:
        text, line = self.take(what)
        if text.lower() not in ("yes", "no", "ja", "nein"):
            raise self.fail(f"{what}: {text!r} is not yes or no", line)
        return text.lower() in ("yes", "ja")

    def terminal(self) -> str:
        text, line = self.take("Format (the gnuplot terminal)")
        words = text.split()
        if (
            not words
            or not re.fullmatch(r"[a-z][a-z0-9]*", words[0])
            or not all(_WORD.fullmatch(w) for w in words)
            or text.count("'") % 2
        ):
            raise self.fail(
                f"Format: {text!r} is not a gnuplot terminal with its options (a name, then words of "
                "letters, digits and , . : + = ' -)",
                line,
            )
        return " ".join(words)

    def style(self, what: str) -> str:
        text, line = self.take(what)
        words = text.split()
        if (
            not words
            or words[0] not in STYLES
            or not all(_WORD.fullmatch(w) for w in words)
            or text.count("'") % 2
        ):
            raise self.fail(f"{what}: {text!r} is not a gnuplot style ({', '.join(STYLES)})", line)
        return " ".join(words)

    def done(self) -> None:
        if self.left():
            text, line = self.values[self.next]
            raise self.fail(f"has a value too many: {text!r} (table B.2)", line)


def parse_config(text: str, source: str) -> SeedConfig:
    """A table B.2 file (the seed's logfileanalyser configuration) as a :class:`SeedConfig`;
    every problem is a :class:`SeedConfigError` naming the file and line."""
    sections = _sections(text, source)
    for name, (line, _) in sections.items():
        if name not in SECTIONS:
            raise SeedConfigError(
                f"{source}:{line}: no section [{name}] in table B.2 (its sections: MAIN, POSITION, "
                "LOPS, ODOMETRY, GYROSCOP, SONAR, TIME)"
            )
    by_module: dict[str, _Section] = {}
    for name, (line, values) in sections.items():
        module = SECTIONS[name]
        if module in by_module:
            raise SeedConfigError(f"{source}:{line}: [{name}] again (as [{by_module[module].name}])")
        by_module[module] = _Section(source, name, line, values)
    if "main" not in by_module:
        raise SeedConfigError(f"{source}: no [MAIN] section (table B.2: log file, output, six plot switches)")
    main = by_module["main"]
    log, output = main.take("Logdatei")[0], main.take("Output")[0]
    switches = ("Pfadplot", "LOPS-Plot", "Gyroskopplot", "Odometrieplot", "Sonarplot", "Timeplot")
    plots = {module: main.yes(switch) for module, switch in zip(MODULES, switches, strict=True)}
    main.done()
    config = SeedConfig(
        log=log,
        output=output,
        plots=plots,
        terminals={m: DEFAULT_POSITION_TERMINAL if m == "position" else DEFAULT_TERMINAL for m in MODULES},
        positions=[],
    )
    for module in MODULES:
        section = by_module.get(module)
        if section is None:
            if plots[module] and module != "lops":  # table B.2 has no [LOPS]; figure 10.1 has
                switch = switches[MODULES.index(module)]
                raise SeedConfigError(f"{source}: no section for the {switch}, which [MAIN] turns on")
            continue
        config.terminals[module] = section.terminal()
        if module == "position":
            seen: dict[str, int] = {}
            while section.left():
                name, line = section.take("Position")
                if position_letter(name) is None:
                    raise section.fail(
                        f"Position: no position {name!r} (the names: {', '.join(position_names())})", line
                    )
                if name in seen:
                    raise section.fail(f"Position {name!r} again (first at line {seen[name]})", line)
                seen[name] = line
                config.positions.append((name, section.style(f"the style of position {name!r}")))
        elif module == "lops":
            config.lops = tuple(section.style(f"the style of receiver {i + 1}") for i in range(RECEIVERS))
        elif module == "odometrie":
            config.odometry = (
                section.style("the left wheel's style"),
                section.style("the right wheel's style"),
            )
        elif module == "gyroskop":
            config.gyro = section.style("Stil")
        elif module == "sonar":
            styles = [section.style("the first sonar's style")]
            while section.left() and len(styles) < SEED_SONARS:
                styles.append(section.style(f"sonar {len(styles)}'s style"))
            config.sonar = tuple(styles)
            config.sonar_at = f"{source}:{section.line}"
        else:  # time
            config.sync = section.yes("Synchronisation")
            config.sync_style = section.style("the synchronisation's style")
            seen = {}
            while section.left():
                name, line = section.take("Sensor")
                if sensor_named(name) is None:
                    names = ", ".join(s.name for s in registered())
                    raise section.fail(f"Sensor: no sensor {name!r} (the sensors: {names})", line)
                if name in seen:
                    raise section.fail(f"Sensor {name!r} again (first at line {seen[name]})", line)
                seen[name] = line
                config.timed.append((name, section.style(f"the style of sensor {name!r}")))
        section.done()
    return config


def read_config(path: str | Path) -> SeedConfig:
    """``path`` read as a table B.2 file (:func:`parse_config`); one line naming it if it cannot be."""
    from tokenring import message_error, read_text

    text = read_text(path, "analyser configuration", message_error(SeedConfigError))
    return parse_config(text, str(path))
