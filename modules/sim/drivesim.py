"""Action-file drives without a ring: main's action navigator and pilot, copro's Localizer as
config/localization.yaml has it, and the simulated robot, sonar and compass of
:mod:`modules.sim.closedloop`, all stepped on one simulated clock in one process.

What ``bench.localization --generated`` does on the ring, here in seconds per drive: the compass's
calibration turn (eight 45° turns, the compass CALIBRATING meanwhile), 20 s at rest (the ring's
2 s pause at speed 10), then main's :class:`~modules.navigation.actions.ActionNavigator` squares up to
the heading from before the calibration turn and drives the room's random action file (``tokenring
world drive``, drive seed = room seed), 10 s at rest to end. The Localizer has the room's walls as
its known walls and starts at the room's start pose; its position records are kept as the ring's
data log keeps them and judged the same way (:func:`judge`). What is left out: main's
SET_GLOBAL_POSITION corrections of the motor (the filter integrates the step counters, which they
leave alone), the compass module's own calibration and the ring's timing (see :mod:`modules.sim.closedloop`).

``python -m bench.drivesim`` (:mod:`bench.drivesim`) runs and judges such drives from the command line.
"""

from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np
import yaml

from modules.localization.logs import DataLog
from modules.sim.closedloop import TICK_MS, TRUTH_PERIOD_MS, VISIT_MS, ClosedLoop

CALIBRATION_TURNS = 8
CALIBRATION_PAUSE_MS = 500  # at rest after each calibration turn (the compass's stop)
SETTLE_AFTER_CALIBRATION_MS = 20_000  # the ring's bench waits 2 s real at speed 10
REST_AFTER_DRIVE_MS = 10_000  # and 1 s real after the file is done
SPEED_PCT = 50


class Records(DataLog):
    """Stands in for the Localizer's data log: keeps its position records (``P``) of the filter
    (K), dead reckoning (O) and the truth (L), as the ring's log would hold them; no file."""

    def __init__(self) -> None:  # (no stream opened: the core only writes and closes)
        self.positions: dict[str, list[tuple[int, dict[str, Any]]]] = {"K": [], "O": [], "T": []}

    def write(self, stamp_ms: int, source: str, kind: str, payload: Any) -> None:
        if kind == "P" and source in self.positions:
            self.positions[source].append((int(stamp_ms), payload))

    def close(self) -> None:
        pass


def repository_config(world_file: str, overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """config/localization.yaml with ``world_file``'s walls as the known walls (and its start
    pose), as ``bench.localization --generated`` configures copro; ``overrides`` as dotted keys."""
    from modules.localization.config import default_config_path

    config = yaml.safe_load(default_config_path().read_text()) or {}
    config["walls"] = {**config.get("walls", {}), "file": world_file}
    config["logs"] = {**config.get("logs", {}), "enabled": False}
    for key, value in (overrides or {}).items():
        node = config
        *parents, last = key.split(".")
        for part in parents:
            node = node.setdefault(part, {})
        node[last] = value
    return config


class DriveSim(ClosedLoop):
    """One action-file drive of ``world`` (a world file) with noise seed ``seed``."""

    def __init__(self, world: str, seed: int, actions_text: str, config: dict[str, Any]) -> None:
        from modules.localization.config import load_config
        from modules.localization.localizer import LocalizationCore
        from modules.navigation.navigator import Navigator

        super().__init__(world, seed, localizer=False, calibrate=False)
        self.variants = {}  # no maps: the drive is judged by its poses
        self.records = Records()
        self.core = LocalizationCore(load_config(copy.deepcopy(config)), data_log=self.records)
        self.actions_text = actions_text
        self.phase = "calibrating"
        self.navigator: Navigator | None = None  # type: ignore[assignment]
        self.finished_why = "time is up"

    def _position_reached(self, status: int, seq: int) -> None:
        if self.phase == "driving":
            self.pilot.note_position_reached(status, seq)

    def drive(self, max_minutes: float = 40.0) -> dict[str, Any]:
        """Calibration turn, rest, the action file, rest; returns the position records and truth."""
        from modules.description.robot import MOTOR_TICK_MS
        from modules.navigation.actions import ActionNavigator, parse_actions
        from modules.navigation.pilot import TURN_LEFT, TURN_RIGHT

        end_ms = max_minutes * 60_000.0
        next_visit = next_motor = 0.0
        turns_left = CALIBRATION_TURNS
        phase_until = 0.0
        rest_heading: float | None = None
        while self.now < end_ms:
            pose = self.robot.pose
            if self.now >= next_motor:
                self.motor.tick(self.now)
                next_motor += MOTOR_TICK_MS
            self.sonar.tick(self.now, pose)
            self.compass.state = (
                3
                if self.phase == "calibrating" and turns_left < CALIBRATION_TURNS
                else (1 if self.compass.state == 3 else self.compass.state)
            )
            turning = self.motor.direction in (TURN_LEFT, TURN_RIGHT)
            self.compass.tick(self.now, pose, turning, self.motor.move is not None)
            if self.now >= self.next_truth:
                self.truth.append((self.now, pose.x, pose.y, pose.theta))
                self._feed_truth(pose)
                self.next_truth += TRUTH_PERIOD_MS
            if self.now >= next_visit:
                next_visit += VISIT_MS
                self.counter = (self.counter + 1) & 0xFF
                self._copro()
                if self.phase == "calibrating":
                    if rest_heading is None and self.pose_filtered and self.pose is not None:
                        rest_heading = self.pose[2]  # main's heading at rest before the turn
                    if self.motor.move is None and self.now >= phase_until and rest_heading is not None:
                        if turns_left > 0:
                            self.motor.command("TURN_LEFT", self.now, angle_deg=45, speed_pct=SPEED_PCT)
                            turns_left -= 1
                            phase_until = self.now + CALIBRATION_PAUSE_MS
                        else:
                            self.phase, phase_until = "settling", self.now + SETTLE_AFTER_CALIBRATION_MS
                elif self.phase == "settling" and self.now >= phase_until:
                    actions = parse_actions(self.actions_text, "drive.act")
                    self.navigator = ActionNavigator(
                        self.layout, actions, speed_pct=SPEED_PCT, start_heading=rest_heading
                    )
                    self.phase = "driving"
                    self.drive_start_ms = self.now
                elif self.phase == "driving":
                    ended = self._main()
                    if ended is not None:
                        self.finished_why = ended
                        self.phase, phase_until = "resting", self.now + REST_AFTER_DRIVE_MS
                elif self.phase == "resting" and self.now >= phase_until:
                    break
            self.now += TICK_MS
        return {
            "finished": self.finished_why,
            "sim_seconds": self.now / 1000.0,
            "moves": dict(self.motor.moves),
            "positions": self.records.positions,
            "truth": np.asarray(self.truth, dtype=float).reshape(-1, 4),
            "report": self.core.report() if self.core is not None else {},
        }

    def _feed_truth(self, pose: Any) -> None:
        from modules.localization.sync import Sample

        assert self.core is not None
        self.core.feed(Sample("truth", int(self.now), {"x": pose.x, "y": pose.y, "theta": pose.theta}))


def judge(positions: dict[str, list[tuple[int, dict[str, Any]]]], truth: np.ndarray) -> dict[str, Any]:
    """The filter (K) and dead reckoning (O) against the simulator's truth (rows t, x, y, θ) at
    their synchronisations' stamps: end error, RMSE, worst error, the share within the filter's
    3σ in x and in y (what ``modules.pc.analysis`` computes from the ring's data log)."""
    out: dict[str, Any] = {}
    t, tx, ty = truth[:, 0], truth[:, 1], truth[:, 2]
    for source in ("K", "O"):
        rows = positions.get(source, [])
        if not rows:
            continue
        stamps = np.array([s for s, _ in rows], dtype=float)
        x = np.array([p["x"] for _, p in rows])
        y = np.array([p["y"] for _, p in rows])
        dx, dy = x - np.interp(stamps, t, tx), y - np.interp(stamps, t, ty)
        dist = np.hypot(dx, dy)
        entry: dict[str, Any] = {
            "end_error_mm": float(dist[-1]),
            "rmse_mm": float(np.sqrt(np.mean(dist**2))),
            "max_error_mm": float(dist.max()),
        }
        if source == "K":
            sig = np.array([p["sigma"][:2] for _, p in rows], dtype=float)
            inside = (np.abs(dx) <= 3 * sig[:, 0]) & (np.abs(dy) <= 3 * sig[:, 1])
            entry.update(within_3sigma=float(np.mean(inside)), samples_3sigma=len(inside))
            entry["end_sigma_mm"] = [float(sig[-1, 0]), float(sig[-1, 1])]
            tpsi = np.interp(stamps, t, np.unwrap(truth[:, 3]))
            psi = np.array([p["psi"] for _, p in rows])
            entry["end_heading_deg"] = math.degrees(math.remainder(psi[-1] - tpsi[-1], 2 * math.pi))
            worst = int(np.argmax(dist))
            entry["worst_at_s"] = float(stamps[worst] / 1000.0)
        out[source] = entry
    return out


def judged_drive(
    room: int | str, world: str, seed: int, actions_text: str, overrides: dict[str, Any] | None
) -> dict[str, Any]:
    """One drive of ``world`` by ``actions_text``, judged against the truth (see :func:`judge`)."""
    sim = DriveSim(world, seed, actions_text, repository_config(world, overrides))
    result = sim.drive()
    initial = sim.core.config["filter"]["initial"]
    figures = judge(result["positions"], result["truth"])
    k, o = figures.get("K", {}), figures.get("O", {})
    report = result["report"]
    return {
        "room": room,
        "seed": seed,
        "filter_mm": k.get("end_error_mm"),
        "filter_rmse_mm": k.get("rmse_mm"),
        "filter_max_mm": k.get("max_error_mm"),
        "worst_at_s": k.get("worst_at_s"),
        "within_3sigma": k.get("within_3sigma"),
        "samples_3sigma": k.get("samples_3sigma"),
        "filter_heading_deg": k.get("end_heading_deg"),
        "filter_end_sigma_mm": k.get("end_sigma_mm"),
        "dead_reckoning_mm": o.get("end_error_mm"),
        "finished": result["finished"],
        "sim_seconds": result["sim_seconds"],
        "moves": result["moves"],
        "gates": report.get("gates"),
        "walls_associated": report.get("walls_associated"),
        "walls_past_end": report.get("walls_past_end"),
        # the floor's mean step scale as the drive left it (what `tokenring calibrate` pools)
        "step_scale_mean": report.get("step_scale_mean"),
        "step_scale_mean_sigma": report.get("step_scale_mean_sigma"),
        "step_scale_prior": [initial.get("step_scale"), initial.get("step_scale_mean_sigma")],
    }
