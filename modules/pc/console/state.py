"""What the operator's console shows, gathered from the live feed and main's PC link, and the
panels as plain text lines (the terminal screen and the stdout mode draw the same lines).

The feed's topics (:mod:`modules.pc.feed`, :mod:`tokenring.observe`): the sensors' raw data as the
token carries them (``/channel/<module>.data``), the localisation's synchronisation and position
store (``/robot/localization``, copro's snapshot), its messages (``/robot/messages``, earlier ones
included) and the true pose (``/robot/pose/true``, the simulator's, for reference). The action
queue is main's (its ``state`` over the PC link), asked for by :meth:`ConsoleState.poll_main`.
"""

from __future__ import annotations

import functools
import math
import threading
from collections import Counter
from typing import Any

from tokenring.observe import Message

#: the sensors' data channels, in the order the seed's screen listed its sensors
SENSOR_CHANNELS = (
    ("odometry", "motor.data"),
    ("gyro", "gyro.data"),
    ("correlator", "correlator.data"),
    ("compass", "compass.data"),
    ("sonar", "sonar.data"),
    ("battery", "charger.data"),
)
MESSAGES_SHOWN = 200


class ConsoleState:
    """The latest value of every topic the console shows (written by the feed's thread)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.channels: dict[str, dict[str, Any]] = {}
        self.updates: dict[str, int] = {}  # how often each channel changed: the screen shows it moves
        self.localization: dict[str, Any] | None = None
        self.messages: list[dict[str, Any]] = []
        self.true_pose: tuple[float, float, float] | None = None
        self.main: dict[str, Any] | None = None
        self.main_error: str | None = None
        self.version = 0

    def on_message(self, message: Message) -> None:
        """A feed sink: keep what the panels show."""
        topic, data = message.topic, message.data
        with self._lock:
            if topic.startswith("/channel/") and topic.endswith(".data"):
                name = topic.removeprefix("/channel/")
                self.channels[name] = data
                self.updates[name] = self.updates.get(name, 0) + 1
            elif topic == "/robot/localization":
                self.localization = data
            elif topic == "/robot/messages":
                self.messages = list(data.get("messages") or [])[-MESSAGES_SHOWN:]
            elif topic == "/robot/pose/true":
                position = data.get("pose", {}).get("position", {})
                orientation = data.get("pose", {}).get("orientation", {})
                theta = 2.0 * math.atan2(orientation.get("z", 0.0), orientation.get("w", 1.0))
                self.true_pose = (position.get("x", 0.0) * 1000.0, position.get("y", 0.0) * 1000.0, theta)
            else:
                return
            self.version += 1

    def poll_main(self, link: Any) -> None:
        """main's navigator state and action queue, over the PC link (call it on a worker thread)."""
        try:
            state = link.request("state")
            error = None
        except Exception as exc:  # main gone or slow: the panel says so, the screen goes on
            state, error = None, str(exc)
        with self._lock:
            if state is not None:
                self.main = state
            self.main_error = error
            self.version += 1

    # -- panels ----------------------------------------------------------------------------------
    def sensors_lines(self) -> list[str]:
        """Every sensor's newest raw data: those the localisation is configured with, and any
        other whose node writes its channel; how often the channel changed, and the
        localisation's count of samples taken and missed."""
        with self._lock:
            channels, updates = dict(self.channels), dict(self.updates)
            configured = dict((self.localization or {}).get("sensors") or {})
        lines = []
        for sensor, channel in SENSOR_CHANNELS:
            data, taken = channels.get(channel), configured.pop(sensor, None)
            if data is None or (not data.get("stamp_ms") and updates.get(channel, 0) <= 1):
                if taken and taken.get("values"):
                    lines.append(f"{sensor:<10} {_values(taken['values'])}{_counts(taken)}")
                continue  # a channel nobody writes: the node is not on this ring
            lines.append(f"{sensor:<10} {_raw(sensor, data)}  ({updates.get(channel, 0)}){_counts(taken)}")
        for sensor, taken in configured.items():
            if sensor != "truth" and isinstance(taken, dict):
                lines.append(f"{sensor:<10} {_values(taken.get('values') or {})}{_counts(taken)}")
        return lines or ["(no sensor data yet: is the ring up?)"]

    def sync_lines(self) -> list[str]:
        """The synchronisation: trigger, period, how many so far."""
        with self._lock:
            snapshot = self.localization
        if snapshot is None:
            return ["(no localisation on this ring, or not yet heard from)"]
        sync = snapshot.get("sync") or {}
        trigger = sync.get("sensor", "?")
        rule = (
            f"every {sync.get('count')} sample(s)"
            if sync.get("mode") == "count"
            else f"every {sync.get('period_ms')} ms"
        )
        last, mean = sync.get("last_period_ms"), sync.get("mean_period_ms")
        return [
            f"trigger    {trigger}, {rule} ({sync.get('mode', '?')})",
            f"syncs      {sync.get('syncs', 0)}",
            f"period     last {_num(last)} ms, mean {_num(mean)} ms",
        ]

    def position_lines(self) -> list[str]:
        """The position store: every source's position with its X/Y/ψ validities (table B.7's
        P records), then the best pose and the filter's σ."""
        with self._lock:
            snapshot, truth = self.localization, self.true_pose
        lines = []
        positions = (snapshot or {}).get("positions") or {}
        for name, p in positions.items():
            lines.append(f"{name:<10} {_pose(p)}  {_valid(p)}")
        best = (snapshot or {}).get("filter")
        if isinstance(best, dict) and best.get("x_mm") is not None:
            sigma = best.get("sigma") or {}
            spread = (
                f"σ {_num(sigma.get('x_mm'), 1)} / {_num(sigma.get('y_mm'), 1)} mm  {_deg(sigma.get('heading_rad'))}°"
                if sigma
                else "no σ (no filter)"
            )
            lines.append(f"{'best':<10} {_pose(best)}  {_valid(best)}  {best.get('source')}, {spread}")
        if truth is not None and "truth" not in positions:
            lines.append(
                f"{'truth':<10} {_pose({'x_mm': truth[0], 'y_mm': truth[1], 'heading_rad': truth[2]})}"
            )
        return lines or ["(no positions yet)"]

    def queue_lines(self) -> list[str]:
        """main's navigator and the actions still queued."""
        with self._lock:
            main, error = self.main, self.main_error
        if main is None:
            return [f"(main: {error})" if error else "(asking main…)"]
        queue = main.get("queue") or []
        lines = [f"navigator {main.get('navigator')}, last abort {main.get('abort_reason')}"]
        lines += [f"{'▶' if i == 0 else ' '} {text}" for i, text in enumerate(queue[:12])]
        if len(queue) > 12:
            lines.append(f"  … {len(queue) - 12} more")
        if not queue:
            lines.append("  (queue empty)")
        return lines

    def message_lines(self, since: int = 0) -> list[str]:
        """Messages as the seed's error log wrote them (table B.5): class, time in ms, text."""
        with self._lock:
            messages = list(self.messages)
        return [message_line(m) for m in messages[since:]]


def message_line(m: dict[str, Any]) -> str:
    """One message as table B.5 writes it: class letter, 9-wide time stamp, text."""
    return f"{str(m.get('class', '?'))[:1]} {int(m.get('stamp_ms') or 0):9d} {m.get('text', '')}"


def _raw(sensor: str, data: dict[str, Any]) -> str:
    """A sensor's raw data in a line, its most telling fields first."""
    if sensor == "odometry":
        from modules.units import pose_from_wire

        x, y, theta = pose_from_wire(data.get("x_mm", 0), data.get("y_mm", 0), data.get("angle_cdeg", 0))
        return (
            f"steps {data.get('steps_left')} / {data.get('steps_right')}  "
            f"x {x:.0f} y {y:.0f} mm  ψ {math.degrees(theta):.2f}°  "
            f"{_enum_name('motor_state', data.get('state'))}  t {data.get('stamp_ms')}"
        )
    if sensor == "gyro":
        return (
            f"rate {data.get('rate_urad_s', 0) / 1e6:+.6f} rad/s  angle {data.get('angle_mrad', 0) / 1000:+.3f} rad  "
            f"sample {data.get('sample')}  t {data.get('stamp_ms')}"
        )
    if sensor == "correlator":
        return f"forward {data.get('forward_um', 0) / 1000:.1f} mm  sample {data.get('sample')}  t {data.get('stamp_ms')}"
    if sensor == "compass":
        return f"heading {data.get('heading_cdeg', 0) / 100:.2f}°  {_enum_name('compass_state', data.get('state'))}  t {data.get('stamp_ms')}"
    if sensor == "battery":
        return (
            f"motors {data.get('motors_mv', 0) / 1000:.2f} V {data.get('motors_pct')} %  electronics "
            f"{data.get('electronics_mv', 0) / 1000:.2f} V  {data.get('remaining_min')} min left"
        )
    if sensor == "sonar":
        distances = " ".join("--" if d == 255 else str(d) for d in data.get("distances") or [])
        return f"{distances} cm  sweep {data.get('sweep')}"
    return _values(data)


@functools.cache
def _enum(name: str) -> dict[int, str]:
    from tokenring import default_protocol

    return {value: key.lower() for key, value in default_protocol().enums.get(name, {}).items()}


def _enum_name(enum: str, value: Any) -> str:
    """An enum value by its name in protocol.yaml (the value itself if it has none)."""
    return _enum(enum).get(value, str(value)) if isinstance(value, int) else str(value)


def _pose(p: dict[str, Any]) -> str:
    return f"x {_num(p.get('x_mm')):>6} mm  y {_num(p.get('y_mm')):>6} mm  ψ {_deg(p.get('heading_rad')):>7}°"


def _valid(p: dict[str, Any]) -> str:
    """The X/Y/ψ validity bits as letters, ``-`` where not known."""
    return "".join(c if p.get(f"{n}_valid") else "-" for c, n in (("X", "x"), ("Y", "y"), ("ψ", "heading")))


def _counts(taken: dict[str, Any] | None) -> str:
    if not taken:
        return ""
    missed = taken.get("missed")
    return f"  [{taken.get('samples', 0)} taken{'' if missed is None else f', {missed} missed'}]"


def _values(data: Any) -> str:
    if not isinstance(data, dict):
        return str(data)
    return "  ".join(
        f"{k} {'/'.join(map(str, v)) if isinstance(v, list) else v}"
        for k, v in data.items()
        if not isinstance(v, dict)
    )


def _num(value: Any, digits: int = 0) -> str:
    if not isinstance(value, int | float) or not math.isfinite(value):
        return "?"
    return f"{value:.{digits}f}"


def _deg(value: Any, digits: int = 2) -> str:
    if not isinstance(value, int | float) or not math.isfinite(value):
        return "?"
    return f"{math.degrees(value):.{digits}f}"


def unseen_lines(shown: list[str], now: list[str]) -> tuple[list[str], bool]:
    """The lines of ``now`` not in ``shown`` yet (remembered there as shown), and whether one of
    them comes before a line already shown: the messages said before the console opened join
    the list after the first live ones, so a screen shows the list afresh, in order, and a plain
    terminal prints them as they come. ``now`` is a bounded list that moves on."""
    remaining = Counter(shown)
    fresh: list[str] = []
    earlier = False
    for line in now:
        if remaining[line] > 0:
            remaining[line] -= 1
            earlier = earlier or bool(fresh)
        else:
            fresh.append(line)
    shown.extend(fresh)
    del shown[:-500]
    return fresh, earlier
