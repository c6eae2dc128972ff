"""The sonar's corrections of the localisation's filter against the known walls: walls fitted
to the readings (side and pair fits), associated with a known wall and corrected with, and the
``walls.ahead`` ranges to a known wall met square on; the wall file's room or the robot's map.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from modules.localization.params import sonar_mounts
from modules.localization.walls import (
    KnownWall,
    beam_echoes,
    circle_in_beam,
    from_frame,
    off_axis_lateness_mm,
    range_lateness_mm,
    wall_position,
    wrap,
)


class WallCorrections:
    """The wall corrections of :class:`~modules.localization.localizer.LocalizationCore` (a part of
    it, on its state: ``config``, ``ekf``, ``known_walls``, ``known_circles`` and the walls' and
    ranges' counters)."""

    def _correct_wall(self, wall: dict[str, Any], stamp: int) -> list[int]:
        """Associate one fitted wall with a known wall and correct; returns [wall index, accepted]."""
        ekf = self.ekf
        assert ekf is not None
        assoc = self.config["walls"]["association"]
        pose = ekf.pose
        p1, p2 = from_frame(tuple(wall["p1"]), pose), from_frame(tuple(wall["p2"]), pose)
        cov = np.array([[wall["cov"][0], wall["cov"][1]], [wall["cov"][1], wall["cov"][2]]])
        sensors = self._sensors_at(wall.get("sensors", []), pose)
        best: tuple[float, KnownWall] | None = None
        for known in self.known_walls:
            if known.length < assoc["min_wall_length_mm"] or not known.visible_from(pose[0], pose[1]):
                continue
            if not known.contains(p1, p2, assoc["margin_mm"]):
                continue
            predicted, _ = ekf.line_model(known)
            if abs(wall["d"] - predicted[1]) > assoc["max_d_mm"]:
                continue
            if abs(math.degrees(wrap(wall["alpha"] - predicted[0]))) > assoc["max_alpha_deg"]:
                continue
            if sensors and not known.contains(sensors[0], sensors[-1], 0.0):
                # the sensors are past the wall's end: their nearest echo is the end, not the foot
                # of a perpendicular (a fit on a corner's ranges comes out tilted and reads long)
                self.walls_past_end += 1
                continue
            nis = ekf.line_nis(wall["alpha"], wall["d"], cov, known)
            if best is None or nis < best[0]:
                best = (nis, known)
        if best is None:
            self.walls_unassociated += 1
            return [-1, 0]
        self.walls_associated += 1
        repeat_mm = self.config["walls"]["repeat_after_mm"]
        last = self.wall_corrected_at.get(best[1].index)
        if (
            repeat_mm > 0
            and last is not None
            and math.hypot(pose[0] - last[0], pose[1] - last[1]) < repeat_mm
            and abs(wrap(pose[2] - last[2])) < math.radians(5.0)
        ):
            # the same sonar, range and incidence err alike: a second fit is no new information
            self.walls_repeated += 1
            return [best[1].index, 0]
        accepted = ekf.correct_line(wall["alpha"], wall["d"], cov, best[1], kind=f"wall_{wall['kind']}")
        if accepted:
            self.wall_corrected_at[best[1].index] = pose
            self._keep_bias_floor(best[1])
        self.message(
            "D",
            stamp,
            f"{wall['kind']} wall (sonar {wall['sensors']}) -> wall {best[1].index}: NIS {best[0]:.1f}",
        )
        if not accepted:
            self.message(
                "W",
                stamp,
                f"{wall['kind']} wall (sonar {wall['sensors']}) rejected by the gate for wall {best[1].index}",
            )
        return [best[1].index, int(accepted)]

    def _sensors_at(self, indices: list[int], pose: tuple[float, float, float]) -> list[tuple[float, float]]:
        """Where the sonars ``indices`` are with the robot at ``pose``: with the tangent model, whose
        ranges are to the wall's nearest point, the points a fitted wall's perpendiculars start at.
        Only against a wall file's walls, which end where the room's do; a map's end where mapped."""
        walls = self.config["walls"]
        if walls["range_model"] != "tangent" or walls["mode"] != "darmstadt":
            return []
        mounts = sonar_mounts(self.config)
        return [from_frame((mounts[i].x, mounts[i].y), pose) for i in indices if i < len(mounts)]

    def _correct_ahead(self, sonar: dict[str, Any], stamp: int) -> None:
        """Each ``walls.ahead`` sonar's range to the known wall it meets square on: a position
        measurement along its beam. On a long leg towards a wall it is what bounds the error the
        floor's step scale leaves; side walls cannot see it. Used only where the wall is the
        nearest thing in the cone by a margin and its perpendicular is near the beam's axis."""
        ekf = self.ekf
        assert ekf is not None
        settings = self.config["walls"]["ahead"]
        walls = self.config["walls"]
        late = walls["sonar_late"] if walls["range_model"] == "tangent" else None
        distances = sonar.get("distances_mm", [])
        at_x, at_y, at_heading = sonar.get("at", (0.0, 0.0, 0.0))  # where they were read
        mounts = sonar_mounts(self.config)
        x, y, psi = ekf.pose
        c, s = math.cos(psi), math.sin(psi)
        half_width = math.radians(walls["max_beam_off_deg"])
        for index in settings["sensors"]:
            measured = distances[index] if index < len(distances) else None
            if measured is None or measured > settings["max_range_mm"]:
                continue
            mount = mounts[index]
            # the sensor when it read, as a lever from the pose at the synchronisation (robot frame)
            lever_x, lever_y = from_frame((mount.x, mount.y), (at_x, at_y, at_heading))
            origin = from_frame((lever_x, lever_y), (x, y, psi))
            beam = psi + at_heading + mount.angle
            echoes = beam_echoes(origin, beam, half_width, self.known_walls)
            first = echoes[0] if echoes else None
            if (
                first is None
                or first.foot_off is None
                or abs(first.foot_off) > math.radians(settings["max_off_deg"])
                or first.wall.length < walls["association"]["min_wall_length_mm"]
                or not first.wall.visible_from(x, y)
            ):
                self.ahead["not_square"] += 1
                continue
            nearest_other = echoes[1].range_mm if len(echoes) > 1 else math.inf
            for circle in self.known_circles:
                met = circle_in_beam(origin, beam, half_width, circle)
                if met is not None:
                    nearest_other = min(nearest_other, met)
            if nearest_other - first.range_mm < settings["clear_mm"]:
                self.ahead["ambiguous"] += 1  # another wall (a corner) or a pillar about as near
                continue
            corrected = float(measured)
            if late is not None:
                corrected -= range_lateness_mm(corrected, late["from_mm"], late["mm_per_m"])
                corrected -= off_axis_lateness_mm(first.foot_off, late["mm_per_deg2"])
            if abs(corrected - first.range_mm) > settings["max_innovation_mm"]:
                self.ahead["unexpected"] += 1  # something the map does not have, or a lost pose
                continue
            wall = first.wall
            innovation = corrected - first.range_mm
            previous = self.ahead_candidate.get((index, wall.index))
            self.ahead_candidate[(index, wall.index)] = (stamp, innovation)
            if (
                previous is None
                or stamp - previous[0] > settings["confirm_within_ms"]
                or abs(innovation - previous[1]) > settings["confirm_mm"]
            ):
                self.ahead["unconfirmed"] += 1  # a range that its predecessor does not bear out
                continue
            last = self.ahead_corrected_at.get(wall.index)
            if last is not None and math.hypot(x - last[0], y - last[1]) < settings["repeat_after_mm"]:
                self.ahead["repeated"] += 1  # the same range and incidence err alike
                continue
            ca, sa = math.cos(wall.alpha), math.sin(wall.alpha)
            signed = wall.d - origin[0] * ca - origin[1] * sa
            sign = 1.0 if signed >= 0 else -1.0
            H = np.zeros((1, len(ekf.x)))
            H[0, 0], H[0, 1] = -sign * ca, -sign * sa
            H[0, 2] = -sign * (ca * (-s * lever_x - c * lever_y) + sa * (c * lever_x - s * lever_y))
            oblique = abs(first.foot_off) > math.radians(settings["oblique_from_deg"])
            R = np.array([[settings["oblique_sigma_mm" if oblique else "sigma_mm"] ** 2]])
            if ekf.update("ahead", np.array([corrected]), np.array([abs(signed)]), H, R):
                self.ahead["used"] += 1
                self.ahead_corrected_at[wall.index] = (x, y)
                self._keep_bias_floor(wall)
            else:
                self.ahead["rejected"] += 1

    def _keep_bias_floor(self, wall: KnownWall) -> None:
        """Keep the pose's variance across ``wall`` at ``walls.bias_floor_mm``² at least: its fits
        share an error (the sonar model's residue at that range and incidence) that the filter,
        taking them as independent, would otherwise average away."""
        floor = self.config["walls"]["bias_floor_mm"]
        ekf = self.ekf
        if floor <= 0 or ekf is None:
            return
        normal = np.array([math.cos(wall.alpha), math.sin(wall.alpha)])
        variance = float(normal @ ekf.P[:2, :2] @ normal)
        if variance < floor * floor:
            ekf.P[:2, :2] += (floor * floor - variance) * np.outer(normal, normal)

    def _wall_fix(
        self, reference: tuple[float, float, float], walls: list[dict[str, Any]], results: list[list[int]]
    ) -> dict[str, Any] | None:
        """The position the associated walls give alone (seed 000 §6.2.4), for the store."""
        known = {wall.index: wall for wall in self.known_walls}
        fits = [
            (wall["alpha"], wall["d"], known[index])
            for wall, (index, _) in zip(walls, results, strict=False)
            if index in known
        ]
        return wall_position(reference, fits)
