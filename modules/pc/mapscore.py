"""Scoring a vector map against the true walls (ground truth is for scoring only).

* **coverage** — the fraction of true wall length lying within 5 cm of a mapped vector that runs
  within 5° of the wall's direction;
* **precision** — the fraction of mapped length within 5 cm of a true wall;
* **orientation error** — the length-weighted mean angle between each mapped vector and the
  true wall it lies along (the nearest one), degrees;
* **corners closed** — true corners (where two walls meet at more than 30°) at which the map
  has a vertex: two vector ends within 2 cm of each other, within 10 cm of the corner.

Walls and vectors are (x1, y1, x2, y2) in mm; round obstacles come in as their polygon outline.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

DISTANCE_MM = 50.0
ANGLE_DEG = 5.0
SAMPLE_MM = 10.0
CORNER_MIN_DEG = 30.0
CORNER_RADIUS_MM = 100.0
VERTEX_MM = 20.0


def point_segment_distance(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Distances (P, S) from each point (x, y) to each segment (x1, y1, x2, y2)."""
    p = points[:, None, :]
    a = segments[None, :, 0:2]
    ab = segments[None, :, 2:4] - a
    denom = np.einsum("...i,...i", ab, ab)
    t = np.clip(np.einsum("...i,...i", p - a, ab) / np.where(denom > 0, denom, 1.0), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[..., None] * ab), axis=-1)


def sample_segments(
    segments: np.ndarray, step: float = SAMPLE_MM
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points every ``step`` mm along each segment: (points, segment index, weight in mm)."""
    points, owner, weight = [], [], []
    for i, (x1, y1, x2, y2) in enumerate(segments):
        length = math.hypot(x2 - x1, y2 - y1)
        n = max(1, math.ceil(length / step))
        t = (np.arange(n) + 0.5) / n
        points.append(np.column_stack([x1 + t * (x2 - x1), y1 + t * (y2 - y1)]))
        owner.append(np.full(n, i))
        weight.append(np.full(n, length / n))
    if not points:
        return np.zeros((0, 2)), np.zeros(0, dtype=int), np.zeros(0)
    return np.vstack(points), np.concatenate(owner), np.concatenate(weight)


def directions(segments: np.ndarray) -> np.ndarray:
    return np.arctan2(segments[:, 3] - segments[:, 1], segments[:, 2] - segments[:, 0])


def angle_diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Unsigned angle between line directions (0..pi/2), broadcasting."""
    d = np.abs(a - b) % math.pi
    return np.minimum(d, math.pi - d)


def true_corners(walls: np.ndarray) -> list[tuple[float, float]]:
    """Points where two walls share an end and meet at more than 30°."""
    corners = []
    ends = [(tuple(w[:2]), i) for i, w in enumerate(walls)] + [(tuple(w[2:]), i) for i, w in enumerate(walls)]
    dirs = directions(walls) if len(walls) else np.zeros(0)
    for k, (p, i) in enumerate(ends):
        for q, j in ends[k + 1 :]:
            if (
                i != j
                and math.dist(p, q) < 1.0
                and math.degrees(float(angle_diff(dirs[i], dirs[j]))) > CORNER_MIN_DEG
            ):
                corners.append(p)
    unique: list[tuple[float, float]] = []
    for c in corners:
        if all(math.dist(c, u) > 1.0 for u in unique):
            unique.append(c)
    return unique


def score_map(vectors: Any, walls: Any) -> dict[str, Any]:
    """The four figures (plus counts) for a map of ``vectors`` against ``walls`` (both mm)."""
    v = np.asarray(vectors, dtype=float).reshape(-1, 4)
    w = np.asarray(walls, dtype=float).reshape(-1, 4)
    v = v[np.hypot(v[:, 2] - v[:, 0], v[:, 3] - v[:, 1]) > 0] if len(v) else v
    wall_length = float(np.hypot(w[:, 2] - w[:, 0], w[:, 3] - w[:, 1]).sum()) if len(w) else 0.0
    map_length = float(np.hypot(v[:, 2] - v[:, 0], v[:, 3] - v[:, 1]).sum()) if len(v) else 0.0
    corners = true_corners(w)
    result: dict[str, Any] = {
        "vectors": len(v),
        "map_length_m": map_length / 1000.0,
        "wall_length_m": wall_length / 1000.0,
        "coverage": 0.0,
        "precision": 0.0,
        "orientation_error_deg": None,
        "corners_closed": 0,
        "corners_total": len(corners),
    }
    if len(v) == 0 or len(w) == 0:
        return result
    wall_pts, wall_owner, wall_weight = sample_segments(w)
    dist = point_segment_distance(wall_pts, v)  # (wall samples, vectors)
    aligned = angle_diff(directions(w)[wall_owner][:, None], directions(v)[None, :]) <= math.radians(
        ANGLE_DEG
    )
    covered = ((dist <= DISTANCE_MM) & aligned).any(axis=1)
    result["coverage"] = float((wall_weight * covered).sum() / wall_weight.sum())

    map_pts, map_owner, map_weight = sample_segments(v)
    to_walls = point_segment_distance(map_pts, w)
    near = to_walls.min(axis=1) <= DISTANCE_MM
    result["precision"] = float((map_weight * near).sum() / map_weight.sum())

    # orientation: each vector against the wall its samples lie nearest to on average
    nearest_wall = np.array([to_walls[map_owner == i].mean(axis=0).argmin() for i in range(len(v))])
    errors = np.degrees(angle_diff(directions(v), directions(w)[nearest_wall]))
    lengths = np.hypot(v[:, 2] - v[:, 0], v[:, 3] - v[:, 1])
    result["orientation_error_deg"] = float((errors * lengths).sum() / lengths.sum())

    ends = np.vstack([v[:, :2], v[:, 2:]])
    owner = np.concatenate([np.arange(len(v)), np.arange(len(v))])
    closed = 0
    for c in corners:
        near_c = np.flatnonzero(np.hypot(ends[:, 0] - c[0], ends[:, 1] - c[1]) <= CORNER_RADIUS_MM)
        if any(
            owner[a] != owner[b] and math.dist(ends[a], ends[b]) <= VERTEX_MM
            for k, a in enumerate(near_c)
            for b in near_c[k + 1 :]
        ):
            closed += 1
    result["corners_closed"] = closed
    return result


def world_walls(world: Any) -> np.ndarray:
    """The true walls of a :class:`modules.description.World` (round obstacles as polygons)."""
    return world.outline()
