"""Unit conversion at the wire: the ring carries the seed's units, programs use mm/rad/CCW.

On the wire (protocol.yaml): x/y in mm, angles in 1/100 degree 0..35999, **clockwise**, 0°
along +X; the compass heading in 1/100 degree from north, clockwise (navigation). Inside the
programs: mm and radians, **counter-clockwise**, 0 along +X, in (-pi, pi].
"""

from __future__ import annotations

import math

CDEG_PER_TURN = 36000


def wrap_angle(rad: float) -> float:
    """An angle in (-pi, pi]."""
    wrapped = math.remainder(rad, 2 * math.pi)
    return math.pi if wrapped == -math.pi else wrapped


def cdeg_cw_to_rad_ccw(cdeg: int) -> float:
    """A wire angle (1/100 degree, clockwise) as radians counter-clockwise."""
    return wrap_angle(-math.radians(cdeg / 100.0))


def rad_ccw_to_cdeg_cw(rad: float) -> int:
    """Radians counter-clockwise as a wire angle (1/100 degree, clockwise, 0..35999)."""
    return round(-math.degrees(rad) * 100.0) % CDEG_PER_TURN


#: short names for the same two conversions
cdeg_to_rad = cdeg_cw_to_rad_ccw
rad_to_cdeg = rad_ccw_to_cdeg_cw


def wire_pose(x_mm: int, y_mm: int, angle_cdeg: int) -> tuple[float, float, float]:
    """A wire pose as (x mm, y mm, heading rad CCW)."""
    return float(x_mm), float(y_mm), cdeg_cw_to_rad_ccw(angle_cdeg)


pose_from_wire = wire_pose


def pose_to_wire(x_mm: float, y_mm: float, heading_rad: float) -> dict[str, int]:
    """(x, y, heading CCW) as the wire's ``x_mm``, ``y_mm``, ``angle_cdeg``."""
    return {"x_mm": round(x_mm), "y_mm": round(y_mm), "angle_cdeg": rad_ccw_to_cdeg_cw(heading_rad)}


def heading_to_cdeg(heading: float) -> int:
    """Compass heading (radians from north, clockwise) -> wire heading 0..35999."""
    return round(math.degrees(heading) * 100) % CDEG_PER_TURN


def cdeg_to_heading(cdeg: int) -> float:
    """Wire heading (1/100 degree from north, clockwise) -> radians from north, clockwise, [0, 2 pi)."""
    return math.radians(cdeg / 100.0) % (2 * math.pi)


def heading_to_theta(heading: float, north: float = math.pi / 2) -> float:
    """Compass heading -> program angle, given where north points (radians CCW from +X)."""
    return wrap_angle(north - heading)


def theta_to_heading(theta: float, north: float = math.pi / 2) -> float:
    """Program angle -> compass heading (radians from north, clockwise, [0, 2 pi))."""
    return (north - theta) % (2 * math.pi)
