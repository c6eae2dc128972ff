"""Explore 2's settings: the distances it keeps and stops at, the lengths it drives, the limits of
each of its phases (wall following, turn checks, islands, the interior, frontiers, the way home)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class WallSettings:
    """Explore 2's distances, lengths and limits (:class:`~modules.navigation.navigator.ExploreLeftWall`)."""

    wall_cm: int = 30  # the distance to keep from the left wall (side sonar reading)
    front_stop_cm: int = 25  # an obstacle this near ahead ends a segment: inner corner
    lost_margin_cm: int = 25  # the left sonar reading this much over wall_cm: the wall ended
    lost_sweeps: int = 2  # ... on this many sweeps in a row (one dropout is no corner)
    segment_mm: int = 600
    find_mm: int = 5000
    face_cm: int = 150  # at the start, an echo this near (not ahead) is turned to before driving
    reacquire_mm: int = 900
    clear_mm: int = 400  # drive on past an outer corner before turning left
    max_correction_deg: float = 15.0
    speed_pct: int = 100
    #: the floor's step length, gauged once at the first wall: turned to face it square on (the
    #: wall was just put parallel on the left), back off this far and drive up to it again. The
    #: filter's travel gauge fits the front sonar's ranges of the two moves; without it the lap's
    #: walls are drawn on an unmeasured step (1 % long floor: 60 mm at 6 m). 0: no gauging
    gauge_mm: int = 800
    #: ALERTs in a row with no other move finished between: the escape the lock allows backs
    #: off too (a turn with the nose at a wall's end touches it whichever way it goes first)
    alerts_before_back_off: int = 2
    alert_back_mm: int = 80
    #: an inner turn that hit ALERT (its nose at the corner's end) is backed off and turned again,
    #: this many times in a row; after that the escapes go on as for any ALERT
    inner_retries: int = 4
    lap_min_mm: int = 2500  # driven along walls before a lap can end
    lap_radius_mm: float = 450.0
    lap_overlap_mm: float = 0.0  # a lap ends this far short of its start at the latest
    max_laps: int = 1
    lap_fallback_deg: float = 630.0  # turned this far since following began: round it is, for sure
    max_islands: int = 3  # laps round an island (turning left all round) before giving up
    settle_ms: int = 1200  # at rest after a turn before it is judged by the fused heading
    check_min_deg: float = 10.0  # turns at least this big are checked (smaller ones slip < 1°)
    turn_tolerance_deg: float = 1.5
    max_fixes: int = 2
    align_cm: int = 60  # both left sonars this near: the wall on the left is in view for aligning
    align_min_deg: float = 6.0  # a wall this far off parallel after a turn is aligned by the sonars
    align_tolerance_deg: float = 2.5  # ... down to this (the pair's baseline is only 16 cm)
    search_deg: int = 120  # a turn looking for the wall to become parallel on the left, at most
    search_speed_pct: int = 40  # slow: the pair reads every 120 ms
    # free-standing obstacles: after the lap, go round what the right side saw inside it
    visit_islands: int = 3  # at most this many, nearest first (0: the lap ends the run)
    #: a right-side reading this near on a follow segment marks an obstacle. Not farther: a round
    #: obstacle a metre or more from the lap, gone round with straight segments and 90° turns, maps
    #: junk; an island with flat faces near the lap (the office pillar) is the case it serves
    sighting_cm: int = 90
    sighting_link_mm: float = 350.0  # sightings this near each other belong to one obstacle
    sighting_min: int = 8  # an obstacle needs this many sightings (one dropout is none)
    inside_margin_mm: float = 150.0  # ... lying this far inside the lap's path (the room's walls lie outside)
    #: sightings inside or this near the path round an island visited were of that island (a path
    #: mapped a few cm off leaves some of them outside it, and a second visit would map junk)
    circled_margin_mm: float = 700.0
    #: round an island: turned left this much (once round and onto the first face again, so that
    #: its corner with the last face closes) and a follow segment this long on that face
    island_turn_deg: float = 405.0
    island_last_mm: int = 150
    island_budget_mm: int = 5000  # driven along it without closing the lap: give up
    # the interior: after the lap and the islands it showed, drive through what no sonar came
    # near (a pillar 1.8 m from every wall is out of the lap's sight), up to ``max_probes`` drives
    max_probes: int = 8
    probe_cell_mm: float = 250.0  # the interior's grid
    probe_seen_mm: float = 900.0  # a cell this near a path driven counts as seen (sighting_cm)
    # what the lap cut off: after the probes, drive to where the space the sonars saw ends (a
    # frontier, :mod:`modules.navigation.frontier`) and follow the wall found there, this far
    max_frontiers: int = 6
    frontier_follow_mm: int = 4000
    frontier_tried_mm: float = 700.0  # a frontier this near one driven to is not tried again
    frontier_beyond_mm: float = 1000.0  # ... driven on past it into the unseen until blocked
    route_clearance_mm: float = 250.0  # the way there keeps this far from every echo
    frontier_arrived_mm: float = 600.0  # blocked this near the place: there (follow what blocks)
    #: moves on the way there at most: this many, and 3 more for each waypoint (aim, check, drive)
    goto_moves: int = 12
    #: a wall mapped already blocked the way short of the place: plan it again this often
    goto_replans: int = 2
    # done: back to where the exploration began, facing as it did then
    return_home: bool = True
    home_tolerance_mm: float = 200.0
    home_detours: int = 4  # something in the way home: turn right, drive on, aim again; this often
    detour_mm: int = 500
    #: the way home retraces the trail, cut short wherever a straight line stays this near it
    #: (the robot's centre drove there; the body is 188 mm out, the followed wall 300 mm away)
    home_corridor_mm: float = 100.0
    route_spacing_mm: float = 50.0  # the trail's points this far apart for the route
    waypoint_tolerance_mm: float = 120.0  # a waypoint on the way home this near is reached
