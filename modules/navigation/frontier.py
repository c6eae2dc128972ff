"""What the sonars have seen of the room, where the seen space ends, and which walls were seen
but never mapped: the places left to explore after the room's lap.

A coarse grid round the start. A cell is *hit* where an echo came from, *free* where the axis of
a beam reached past it to its echo (not past an earlier hit: an oblique wall's echo is weak, and
the reading runs on beyond it), and *mapped* where a side sonar's echo came from while the robot
drove straight with vector generation on, near enough for it (``map_range_mm``), and *driven*
under the robot's body wherever it was (a way, even where no echo showed the floor free). Two
kinds of target come out of it:

* a *frontier*: free cells next to cells nothing reached, away from every hit — space the robot
  could drive into and has not seen (Yamauchi 1997, "A frontier-based approach to autonomous
  exploration");
* an *unmapped wall*: hit cells away from every mapped one — a wall seen from afar (a pocket
  behind an obtuse corner the lap cut off, the far side of a partition) that no vector covers.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from modules.description.robot import ROBOT_RADIUS_MM, SONAR_MOUNTS, SonarMount, sonar_world_pose

NO_CONTACT_CM = 255

Pose = tuple[float, float, float]


@dataclass(frozen=True)
class FrontierSettings:
    cell_mm: float = 100.0
    extent_mm: float = 16000.0  # the grid reaches this far from the start each way
    free_range_mm: float = 1500.0  # echoes this far at most count: farther ones are coarse
    cone_deg: float = 10.0  # the part of the 30° beam taken as seen free up to its echo
    rays: int = 3
    hit_clearance_mm: float = 300.0  # frontier cells this near a hit are a wall's unseen stretch
    min_cells: int = 5  # a frontier shorter than this many cells (0.5 m) is no way in
    map_range_mm: float = 1000.0  # side echoes this near make vectors (the tracker's range)
    #: hits this near a mapped cell are that wall's (at 300 a wall 30 cm behind a mapped one,
    #: a shallow notch's back or a pocket's, was taken for it and never visited)
    mapped_clearance_mm: float = 150.0
    min_wall_cells: int = 5  # an unmapped wall shorter than this many cells is noise
    narrow_cost: float = 8.0  # a cell next to an echo costs this many times one in the open


@dataclass(frozen=True)
class Frontier:
    """A place left to explore: the cell nearest the middle of a stretch of frontier or of an
    unmapped wall (world mm), and the stretch's size in cells."""

    x: float
    y: float
    cells: int


class SeenGrid:
    """Free, hit and mapped cells from sonar readings; :meth:`frontiers` lists where the seen
    space ends, :meth:`unmapped_walls` the walls seen but not mapped."""

    def __init__(
        self,
        origin: tuple[float, float],
        settings: FrontierSettings | None = None,
        mounts: tuple[SonarMount, ...] = SONAR_MOUNTS,
    ) -> None:
        self.s = settings or FrontierSettings()
        self.mounts = mounts
        self.size = int(2 * self.s.extent_mm / self.s.cell_mm)
        self.x0 = origin[0] - self.s.extent_mm
        self.y0 = origin[1] - self.s.extent_mm
        self.free = np.zeros((self.size, self.size), dtype=bool)
        self.hit = np.zeros((self.size, self.size), dtype=bool)
        self.mapped = np.zeros((self.size, self.size), dtype=bool)
        self.driven = np.zeros((self.size, self.size), dtype=bool)  # under the robot's body
        half = math.radians(self.s.cone_deg) / 2.0
        self._offsets = np.linspace(-half, half, self.s.rays) if self.s.rays > 1 else np.zeros(1)
        self._steps = np.arange(0.0, self.s.free_range_mm, self.s.cell_mm / 2.0)
        # the floor under the robot's body: points of its disc half a cell apart
        reach = np.linspace(
            -ROBOT_RADIUS_MM, ROBOT_RADIUS_MM, 2 * math.ceil(ROBOT_RADIUS_MM / self.s.cell_mm * 2) + 1
        )
        self._footprint = np.array(
            [(x, y) for x in reach for y in reach if math.hypot(x, y) <= ROBOT_RADIUS_MM]
        )

    def _cells(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        col = np.floor((x - self.x0) / self.s.cell_mm).astype(int)
        row = np.floor((y - self.y0) / self.s.cell_mm).astype(int)
        inside = (col >= 0) & (col < self.size) & (row >= 0) & (row < self.size)
        return row[inside], col[inside], inside

    def add(self, pose: Pose, distances_cm: Sequence[int], mapping: Sequence[int] = ()) -> None:
        """One sweep: each echo's point hit, and its cone free up to it (no further than the
        first cell hit before); no echo shows nothing (a wall met too obliquely to answer looks
        the same). Echoes of the sonars in ``mapping`` (the side sonars, driving straight with
        vector generation on) within ``map_range_mm`` mark their cells mapped. The cells under the
        robot's body are *driven*: a way for :meth:`route` where no echo came near enough to
        show it free (open floor more than 1.5 m from every wall)."""
        s = self.s
        row, col, _ = self._cells(pose[0] + self._footprint[:, 0], pose[1] + self._footprint[:, 1])
        self.driven[row, col] = True
        for index, cm in enumerate(distances_cm[: len(self.mounts)]):
            if cm == NO_CONTACT_CM or cm * 10.0 > s.free_range_mm:
                continue
            sx, sy, direction = sonar_world_pose(pose[0], pose[1], pose[2], index, self.mounts)
            row, col, _ = self._cells(
                np.array([sx + cm * 10.0 * math.cos(direction)]),
                np.array([sy + cm * 10.0 * math.sin(direction)]),
            )
            self.hit[row, col] = True
            if index in mapping and cm * 10.0 <= s.map_range_mm:
                self.mapped[row, col] = True
            steps = self._steps[
                self._steps < cm * 10.0 - 1.5 * s.cell_mm
            ]  # a thin wall's two sides never touch
            for angle in direction + self._offsets:
                row, col, inside = self._cells(sx + np.cos(angle) * steps, sy + np.sin(angle) * steps)
                if not inside.all():
                    continue
                blocked = np.flatnonzero(self.hit[row, col])
                end = int(blocked[0]) if len(blocked) else len(row)
                self.free[row[:end], col[:end]] = True

    def mapped_near(self, point: tuple[float, float]) -> bool:
        """A mapped cell lies within ``mapped_clearance_mm`` of ``point``."""
        reach = math.ceil(self.s.mapped_clearance_mm / self.s.cell_mm)
        row, col, _ = self._cells(np.array([point[0]]), np.array([point[1]]))
        if len(row) == 0:
            return False
        r, c = int(row[0]), int(col[0])
        return bool(self.mapped[max(0, r - reach) : r + reach + 1, max(0, c - reach) : c + reach + 1].any())

    def route(
        self, start: tuple[float, float], goal: tuple[float, float], clearance_mm: float
    ) -> list[tuple[float, float]] | None:
        """Waypoints (world mm; the last one the passable cell nearest ``goal``) through cells
        seen free or driven: the cheapest path on the grid (Dijkstra), a cell costing more the
        nearer it lies to an echo within ``clearance_mm`` (up to ``narrow_cost`` times), pulled
        straight wherever a line keeps at least the clearance its stretch of path had. None: no
        way there is known."""
        from scipy import ndimage
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import dijkstra

        passable = self.free | self.driven
        cells = np.argwhere(passable)
        if len(cells) == 0:
            return None
        clearance = ndimage.distance_transform_edt(~self.hit) * self.s.cell_mm
        # 1 at the clearance and beyond, rising to narrow_cost right at an echo
        cost = 1.0 + (self.s.narrow_cost - 1.0) * np.clip(1.0 - clearance / clearance_mm, 0.0, 1.0)
        number = np.full(self.free.shape, -1)
        number[cells[:, 0], cells[:, 1]] = np.arange(len(cells))
        rows, cols, weights = [], [], []
        here = cost[cells[:, 0], cells[:, 1]]
        for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
            r, c = cells[:, 0] + dr, cells[:, 1] + dc
            ok = (r >= 0) & (r < self.size) & (c >= 0) & (c < self.size)
            there = np.full(len(cells), -1)
            there[ok] = number[r[ok], c[ok]]
            linked = np.flatnonzero(there >= 0)
            rows.append(linked)
            cols.append(there[linked])
            step = math.hypot(dr, dc) / 2.0
            weights.append(step * (here[linked] + cost[r[linked], c[linked]]))
        graph = coo_matrix(
            (np.concatenate(weights), (np.concatenate(rows), np.concatenate(cols))),
            shape=(len(cells), len(cells)),
        ).tocsr()
        centres = np.column_stack(
            [self.x0 + (cells[:, 1] + 0.5) * self.s.cell_mm, self.y0 + (cells[:, 0] + 0.5) * self.s.cell_mm]
        )
        first = int(np.argmin(((centres - np.asarray(start)) ** 2).sum(axis=1)))
        last = int(np.argmin(((centres - np.asarray(goal)) ** 2).sum(axis=1)))
        distances, previous = dijkstra(graph, directed=False, indices=first, return_predecessors=True)
        if not np.isfinite(distances[last]):
            return None
        path = [last]
        while path[-1] != first:
            path.append(int(previous[path[-1]]))
        path.reverse()
        points = [(float(x), float(y)) for x, y in centres[path]]
        kept = [float(clearance[r, c]) for r, c in cells[path]]
        waypoints, at = [], 0
        while at < len(points) - 1:
            ahead = len(points) - 1
            if kept[at] < clearance_mm:  # out of a narrow place along the path itself first
                ahead = next((i for i in range(at + 1, len(points)) if kept[i] >= clearance_mm), ahead)
            while ahead > at + 1 and not self._clear(
                points[at], points[ahead], passable, clearance, min(clearance_mm, *kept[at : ahead + 1])
            ):
                ahead -= 1
            waypoints.append(points[ahead])
            at = ahead
        return waypoints or [points[-1]]

    def crosses_echo(self, points: Sequence[tuple[float, float]]) -> bool:
        """A leg of the path through ``points`` passes a cell an echo came from (sampled every
        tenth of a cell: a line between two diagonal hit cells of a thin wall clips one)."""
        for a, b in itertools.pairwise(points):
            row, col, _ = self._line(a, b, self.s.cell_mm / 10.0)
            if self.hit[row, col].any():
                return True
        return False

    def _clear(
        self,
        a: tuple[float, float],
        b: tuple[float, float],
        passable: np.ndarray,
        clearance: np.ndarray,
        least_mm: float,
    ) -> bool:
        """Every cell on the line from ``a`` to ``b`` is passable and ``least_mm`` from every echo."""
        row, col, inside = self._line(a, b, self.s.cell_mm / 2.0)
        return bool(inside.all() and passable[row, col].all() and (clearance[row, col] >= least_mm).all())

    def _line(
        self, a: tuple[float, float], b: tuple[float, float], step_mm: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The cells of points every ``step_mm`` from ``a`` to ``b`` (as :meth:`_cells`)."""
        t = np.linspace(0.0, 1.0, max(2, int(math.dist(a, b) / step_mm) + 1))
        return self._cells(a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t)

    def frontiers(self) -> list[Frontier]:
        """Stretches of free cells next to unseen ones, away from hits, longest first."""
        unknown = ~self.free & ~self.hit
        edge = np.zeros_like(self.free)
        edge[1:, :] |= unknown[:-1, :]
        edge[:-1, :] |= unknown[1:, :]
        edge[:, 1:] |= unknown[:, :-1]
        edge[:, :-1] |= unknown[:, 1:]
        near_hit = _near(self.hit, self.s.hit_clearance_mm / self.s.cell_mm)
        return self._stretches(self.free & edge & ~near_hit, self.s.min_cells)

    def unmapped_walls(self) -> list[Frontier]:
        """Stretches of hit cells away from every mapped cell, longest first."""
        near_mapped = _near(self.mapped, self.s.mapped_clearance_mm / self.s.cell_mm)
        return self._stretches(self.hit & ~near_mapped, self.s.min_wall_cells)

    def _stretches(self, mask: np.ndarray, min_cells: int) -> list[Frontier]:
        """The mask's 8-connected groups of at least ``min_cells``, longest first."""
        from scipy import ndimage

        labels, count = ndimage.label(mask, structure=np.ones((3, 3), dtype=int))
        found = []
        for label in range(1, count + 1):
            cells = np.argwhere(labels == label).astype(float)
            if len(cells) < min_cells:
                continue
            middle = cells.mean(axis=0)
            row, col = cells[int(np.argmin(((cells - middle) ** 2).sum(axis=1)))]
            found.append(
                Frontier(
                    float(self.x0 + (col + 0.5) * self.s.cell_mm),
                    float(self.y0 + (row + 0.5) * self.s.cell_mm),
                    len(cells),
                )
            )
        return sorted(found, key=lambda f: -f.cells)


def _near(mask: np.ndarray, cells: float) -> np.ndarray:
    """Every cell within ``cells`` (a square) of a set one."""
    from scipy import ndimage  # after the lap only: main's node starts without it

    reach = math.ceil(cells)
    return ndimage.binary_dilation(mask, np.ones((2 * reach + 1, 2 * reach + 1), dtype=bool))
