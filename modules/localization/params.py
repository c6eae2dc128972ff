"""What the localisation's configuration makes (:mod:`modules.localization.config` reads and
checks it): the sonar mounts, the odometry's, the filter's and the wall detector's parameters,
the synchronisation trigger and the start pose."""

from __future__ import annotations

import math
from typing import Any

from modules.localization.ekf import EkfParams
from modules.localization.sync import OdometryParams, Trigger
from modules.localization.walls import DetectorParams, SonarMount


def with_body(config: dict[str, Any], body: str) -> dict[str, Any]:
    """``config`` with ``robot.sonars: robot`` spelled out as ``body``'s mounts when the ring's
    robot is not today's, so the filter and the data log place readings where this robot has its
    sonars (``robot`` alone means today's body, :data:`modules.description.robot.SONAR_MOUNTS`)."""
    if config["robot"]["sonars"] != "robot" or body == "ours":
        return config
    from modules.description.robot import sonar_mounts as body_mounts

    mounts = [[m.x, m.y, math.degrees(m.angle)] for m in body_mounts(body)]
    return {**config, "robot": {**config["robot"], "sonars": mounts}}


def sonar_mounts(config: dict[str, Any]) -> list[SonarMount]:
    """The sonar geometry: modules/description/robot.py, or the config's list of [x, y, angle_deg]."""
    spec = config["robot"]["sonars"]
    if spec == "robot":
        from modules.description.robot import SONAR_MOUNTS

        return [SonarMount(m.x, m.y, m.angle) for m in SONAR_MOUNTS]
    return [SonarMount(float(x), float(y), math.radians(a)) for x, y, a in spec]


def odometry_params(config: dict[str, Any]) -> OdometryParams:
    robot = config["robot"]
    return OdometryParams(robot["mm_per_step"], robot["steps_per_degree"], config["filter"]["odometry_model"])


def gyro_fused(config: dict[str, Any]) -> bool:
    """The gyroscope is used and fed to the filter: the filter then estimates its offset."""
    gyro = config["sensors"]["gyro"]
    return bool(gyro["use"] and gyro["filter"])


def ekf_params(config: dict[str, Any]) -> EkfParams:
    f = config["filter"]
    noise, initial = f["noise"], f["initial"]
    return EkfParams(
        odometry=odometry_params(config),
        estimate=tuple(f["estimate"]) + (("gyro_offset",) if gyro_fused(config) else ()),
        distance_noise_rel=noise["distance_rel"],
        rotation_noise_rel=noise["rotation_rel"],
        rotation_noise_rad_per_mm=noise["rotation_rad_per_mm"],
        glide_per_move_rel=noise["glide_per_move_rel"],
        step_scale_per_move=noise["step_scale_per_move"],
        glide_walk_per_deg=noise["glide_walk_per_deg"],
        compass_offset_walk_deg_per_s=noise["compass_offset_walk_deg_per_s"],
        step_scale_walk_per_m=noise["step_scale_walk_per_m"],
        step_scale_mean_walk_per_move=noise["step_scale_mean_walk_per_move"],
        initial_sigma_mm=initial["sigma_mm"],
        initial_sigma_deg=initial["sigma_deg"],
        initial_glide_sigma=initial["glide_sigma"],
        initial_compass_offset_sigma_deg=initial["compass_offset_sigma_deg"],
        initial_step_scale_sigma=initial["step_scale_sigma"],
        initial_step_scale=initial["step_scale"],
        initial_step_scale_mean_sigma=initial["step_scale_mean_sigma"],
        compass_sigma_deg=f["compass"]["sigma_deg"],
        gyro_offset_walk_deg_per_s=f["gyro"]["sigma_deg_s"],
        gyro_scale_rel=f["gyro"]["scale_rel"],
        gate_probability=f["gate_probability"],
        valid_sigma_mm=f["valid_sigma_mm"],
        valid_sigma_deg=f["valid_sigma_deg"],
    )


def detector_params(config: dict[str, Any]) -> DetectorParams:
    w = config["walls"]
    return DetectorParams(
        history=w["history"],
        max_distance_mm=w["max_distance_mm"],
        side_sensors=tuple(w["side_sensors"]),
        pairs=tuple(tuple(p) for p in w["pairs"]),
        min_points_side=w["min_points_side"],
        min_span_side_mm=w["min_span_side_mm"],
        max_sigma_side_mm=w["max_sigma_side_mm"],
        min_points_pairs=w["min_points_pairs"],
        max_sigma_d_pairs_mm=w["max_sigma_d_pairs_mm"],
        max_sigma_alpha_pairs_deg=w["max_sigma_alpha_pairs_deg"],
        noise_floor_mm=w["noise_floor_mm"],
        max_turn_deg=w["max_turn_deg"],
        min_sigma_d_mm=w["min_sigma_d_mm"],
        min_sigma_alpha_deg=w["min_sigma_alpha_deg"],
        range_model=w["range_model"],
        max_beam_off_deg=w["max_beam_off_deg"],
        late_from_mm=w["sonar_late"]["from_mm"],
        late_mm_per_m=w["sonar_late"]["mm_per_m"],
        late_mm_per_deg2=w["sonar_late"]["mm_per_deg2"],
        shared_sigma_mm=w["shared_sigma_mm"],
    )


def trigger_of(config: dict[str, Any]) -> Trigger:
    """The synchronisation trigger the config names (``sync.trigger``)."""
    trig = config["sync"]["trigger"]
    if trig["rounds"] > 0:
        return Trigger(sensor=None, rounds=trig["rounds"])
    if trig["mode"] == "period":
        return Trigger(trig["sensor"], period_ms=trig["period_ms"])
    return Trigger(trig["sensor"], trig["count"], min_period_ms=trig["min_period_ms"])


def start_pose_of(config: dict[str, Any]) -> tuple[float, float, float] | None:
    """The initial pose the config names (None: wait for the motor's first pose)."""
    spec = config["filter"]["initial_pose"]
    if isinstance(spec, dict):
        return float(spec["x_mm"]), float(spec["y_mm"]), math.radians(spec["heading_deg"])
    if spec == "world":
        from modules.description import load_world

        start = load_world(config["walls"]["file"]).start
        return float(start.x), float(start.y), float(start.theta)
    return None
