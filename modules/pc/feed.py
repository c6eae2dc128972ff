"""The robot's topics in a live feed (:mod:`tokenring.observe.feed`): poses, sonar, map, walls, LCD.

What ``record``, the web view and the Foxglove bridge show of the robot. Foxglove-shaped topics
carry Foxglove's well-known JSON shapes (metres, radians, quaternions, ``timestamp`` as
``{sec, nsec}``) and publish the matching JSON Schema under the Foxglove name, so Foxglove
draws them without configuration. The schemas are derived from the protobuf descriptors the
``foxglove-sdk`` package ships (:func:`foxglove_schema`), the same definitions Foxglove's own
JSON Schemas are generated from.

==========================  ======================  ============================================
topic                       schema                  from
==========================  ======================  ============================================
``/robot/pose/true``        foxglove.PoseInFrame    the world's ground truth (``world/truth``)
``/robot/pose/odometry``    foxglove.PoseInFrame    ``motor.data`` (dead reckoning)
``/robot/pose/filtered``    foxglove.PoseInFrame    ``copro.data`` when its pose is the EKF's
``/robot/uncertainty``      robot.Uncertainty       ``copro.data``'s EKF standard deviations
``/robot/tf``               foxglove.FrameTransform room → robot: filtered pose, else odometry
``/robot/sonar``            foxglove.SceneUpdate    ``sonar.data``: one line per beam, in the room
``/robot/sonar/beams``      robot.SonarBeams        the same beams as plain numbers (web view)
``/robot/map``              foxglove.SceneUpdate    VECTOR commands to ``map.command``, kept
``/robot/map/vectors``      robot.MapVectors        the same vectors in mm (as ``tokenring map``)
``/robot/walls``            foxglove.SceneUpdate    the room's walls and obstacles (``world/info``)
``/robot/walls/vectors``    robot.MapVectors        the same walls in mm, circles as 32-gons
``/robot/lcd``              robot.Lcd               the LCD's text lines (the lcd program's report)
``/robot/lcd/image``        foxglove.RawImage       the LCD's screen (``lcd/screen``), mono8
``/robot/navigator``        robot.Navigator         ``main.data`` with enum names
``/robot/localization``     robot.Localization      copro's localisation live: sensors, sync,
                                                    positions, filter, logs (``robot/
                                                    localization/state``, five a second)
``/robot/messages``         robot.Messages          its messages, the newest 200, earlier ones
                                                    asked for once (``robot/localization/
                                                    message`` and ``messages``)
``/robot/main``             robot.Main              main's action queue and navigator (its
                                                    ``state`` over the PC link, twice a second)
==========================  ======================  ============================================

Frames: ``room`` is the world's frame (the walls', x/y as in the world file, metres); ``robot``
is the robot's body (x forward, y left), placed by ``/robot/tf``. All three poses are in
``room``: the motor's dead reckoning starts at the world's start pose, and wire angles
(1/100 degree clockwise) are turned counter-clockwise (:mod:`modules.units`).

Why the sonar is a SceneUpdate and not a LaserScan: a LaserScan has one origin and evenly
spaced angles; the robot's eight pairs sit at eight different places on the body and look in
directions 45°, 0°, -45°, -90°, -90°, 180°, 90°, 90° (two pairs share a direction), which no
LaserScan can say. Line segments from each pair's true mount point show exactly where each
echo came from.
"""

from __future__ import annotations

import base64
import math
import threading
from dataclasses import dataclass, field
from functools import cache
from typing import Any

from modules.description import keys as robot_keys
from modules.description.robot import SONAR_NO_CONTACT, SONAR_RANGE_MM, SonarMount, sonar_world_pose
from modules.units import cdeg_cw_to_rad_ccw, wrap_angle
from modules.variants import body_mounts
from tokenring import CommandChannel, Protocol, frame_problem, keys
from tokenring.observe import FeedSource, Message, Topic, decode_msgpack

FRAME_ROOM = "room"
FRAME_ROBOT = "robot"
POSE_SOURCE_EKF = 2  # copro.data pose_source: 0 none, 1 dead reckoning, 2 EKF
VECTOR_CODE_NAME = "VECTOR"
CIRCLE_SEGMENTS = 32
LCD_WIDTH, LCD_HEIGHT = 128, 64  # the screen (modules/world/lcdpanel.py): 64 rows of 16 bytes
MESSAGES_SHOWN = 200  # /robot/messages: the localisation's newest messages

# --------------------------------------------------------------------------------------------
# Foxglove's JSON Schemas, from the protobuf descriptors foxglove-sdk ships

_WIRE_VARINT, _WIRE_I64, _WIRE_LEN, _WIRE_I32 = 0, 1, 2, 5
_NUMBER_TYPES = {1, 2}  # double, float
_SIGNED_TYPES = {3, 5, 15, 16, 17, 18}  # int64 int32 sfixed32 sfixed64 sint32 sint64
_UNSIGNED_TYPES = {4, 6, 7, 13}  # uint64 fixed64 fixed32 uint32
_BOOL, _STRING, _MESSAGE, _BYTES, _ENUM = 8, 9, 11, 12, 14
_REPEATED = 3


def _proto_fields(buf: bytes) -> list[tuple[int, Any]]:
    """The (field number, value) pairs of one protobuf message: ints or raw bytes."""
    out: list[tuple[int, Any]] = []
    i = 0

    def varint() -> int:
        nonlocal i
        value = shift = 0
        while True:
            byte = buf[i]
            i += 1
            value |= (byte & 0x7F) << shift
            shift += 7
            if byte < 0x80:
                return value

    while i < len(buf):
        tag = varint()
        number, wire = tag >> 3, tag & 7
        if wire == _WIRE_VARINT:
            out.append((number, varint()))
        elif wire == _WIRE_LEN:
            size = varint()
            out.append((number, buf[i : i + size]))
            i += size
        elif wire == _WIRE_I64:
            out.append((number, buf[i : i + 8]))
            i += 8
        elif wire == _WIRE_I32:
            out.append((number, buf[i : i + 4]))
            i += 4
        else:
            raise ValueError(f"protobuf wire type {wire} not supported")
    return out


@dataclass
class _ProtoField:
    name: str
    type: int
    repeated: bool
    type_name: str
    optional: bool  # proto3 `optional` or part of a oneof: not required in JSON


@dataclass
class _Descriptors:
    messages: dict[str, list[_ProtoField]] = field(default_factory=dict)
    enums: dict[str, list[tuple[str, int]]] = field(default_factory=dict)

    def add_file(self, data: bytes) -> None:
        items = _proto_fields(data)
        package = next((v.decode() for n, v in items if n == 2), "")
        for n, v in items:
            if n == 4:
                self._add_message(package, v)
            elif n == 5:
                self._add_enum(package, v)

    def _add_message(self, scope: str, data: bytes) -> None:
        items = _proto_fields(data)
        name = f"{scope}.{next(v.decode() for n, v in items if n == 1)}"
        fields = []
        for n, v in items:
            if n == 2:
                f = dict(_proto_fields(v))
                fields.append(
                    _ProtoField(
                        name=f[1].decode(),
                        type=f[5],
                        repeated=f.get(4) == _REPEATED,
                        type_name=f.get(6, b"").decode().lstrip("."),
                        optional=9 in f or bool(f.get(17)),
                    )
                )
            elif n == 3:
                self._add_message(name, v)
            elif n == 4:
                self._add_enum(name, v)
        self.messages[name] = fields

    def _add_enum(self, scope: str, data: bytes) -> None:
        items = _proto_fields(data)
        name = f"{scope}.{next(v.decode() for n, v in items if n == 1)}"
        values = []
        for n, v in items:
            if n == 2:
                f = dict(_proto_fields(v))
                values.append((f[1].decode(), f.get(2, 0)))
        self.enums[name] = values


def _time_schema(title: str) -> dict[str, Any]:
    sec: dict[str, Any] = {"type": "integer"}
    if title == "time":
        sec["minimum"] = 0
    return {
        "type": "object",
        "title": title,
        "properties": {"sec": sec, "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}},
    }


def _message_schema(d: _Descriptors, name: str) -> dict[str, Any]:
    if name == "google.protobuf.Timestamp":
        return _time_schema("time")
    if name == "google.protobuf.Duration":
        return _time_schema("duration")
    properties: dict[str, Any] = {}
    for f in d.messages[name]:
        if f.type == _MESSAGE:
            one = _message_schema(d, f.type_name)
        elif f.type == _ENUM:
            one = {
                "title": f.type_name,
                "oneOf": [{"title": n, "const": v} for n, v in d.enums[f.type_name]],
            }
        elif f.type in _NUMBER_TYPES:
            one = {"type": "number"}
        elif f.type in _SIGNED_TYPES:
            one = {"type": "integer"}
        elif f.type in _UNSIGNED_TYPES:
            one = {"type": "integer", "minimum": 0}
        elif f.type == _BOOL:
            one = {"type": "boolean"}
        elif f.type == _STRING:
            one = {"type": "string"}
        elif f.type == _BYTES:
            one = {"type": "string", "contentEncoding": "base64"}
        else:
            raise ValueError(f"{name}.{f.name}: protobuf type {f.type} not supported")
        properties[f.name] = {"type": "array", "items": one} if f.repeated else one
    schema: dict[str, Any] = {"title": name, "type": "object", "properties": properties}
    schema["required"] = [f.name for f in d.messages[name] if not f.optional]
    return schema


@cache
def foxglove_schema(name: str) -> dict[str, Any]:
    """The JSON Schema of a Foxglove well-known message (``foxglove.PoseInFrame``).

    Built from the FileDescriptorSet that ``foxglove-sdk`` ships for it: the same definitions
    Foxglove generates its JSON Schemas from (every field required unless ``optional``)."""
    import foxglove.messages

    schema = getattr(foxglove.messages, name.removeprefix("foxglove.")).get_schema()
    d = _Descriptors()
    for number, data in _proto_fields(bytes(schema.data)):
        if number == 1:
            d.add_file(data)
    return _message_schema(d, name)


# --------------------------------------------------------------------------------------------
# the robot's own (non-Foxglove) schemas

UNCERTAINTY_SCHEMA: dict[str, Any] = {
    "title": "robot.Uncertainty",
    "type": "object",
    "properties": {
        "sigma_x_m": {"type": "number", "minimum": 0, "description": "standard deviation of x, m"},
        "sigma_y_m": {"type": "number", "minimum": 0, "description": "standard deviation of y, m"},
        "sigma_theta_rad": {"type": "number", "minimum": 0, "description": "of the heading, rad"},
        "source": {"type": "string", "enum": ["ekf"], "description": "the filter that said so"},
    },
    "required": ["sigma_x_m", "sigma_y_m", "sigma_theta_rad", "source"],
}
_SEGMENTS_MM = {
    "type": "array",
    "items": {"type": "array", "items": {"type": "number"}, "minItems": 4, "maxItems": 4},
}
MAP_VECTORS_SCHEMA: dict[str, Any] = {
    "title": "robot.MapVectors",
    "type": "object",
    "properties": {"vectors": {**_SEGMENTS_MM, "description": "[x1, y1, x2, y2] in mm, room frame"}},
    "required": ["vectors"],
}
SONAR_BEAMS_SCHEMA: dict[str, Any] = {
    "title": "robot.SonarBeams",
    "type": "object",
    "properties": {
        "frame_id": {"type": "string"},
        "pose": {"type": "string", "enum": ["true", "filtered", "odometry"], "description": "placed at"},
        "distances_cm": {
            "type": "array",
            "items": {"type": "integer", "minimum": 0, "maximum": 255},
            "description": "per pair as on the wire; 255 = no contact",
        },
        "segments_m": {
            "type": "array",
            "items": {"type": "array", "items": {"type": "number"}, "minItems": 4, "maxItems": 4},
            "description": "per pair: mount point to echo (or to the range limit), room frame",
        },
        "contact": {"type": "array", "items": {"type": "boolean"}},
    },
    "required": ["frame_id", "pose", "distances_cm", "segments_m", "contact"],
}
LCD_SCHEMA: dict[str, Any] = {
    "title": "robot.Lcd",
    "type": "object",
    "properties": {
        "lines": {"type": "array", "items": {"type": "string"}, "description": "the screen's text"},
        "menu": {"type": "string"},
    },
    "required": ["lines"],
}

_INT_OR_NULL: dict[str, Any] = {"type": ["integer", "null"]}
_NUMBER_OR_NULL: dict[str, Any] = {"type": ["number", "null"]}
_TEXT_OR_NULL: dict[str, Any] = {"type": ["string", "null"]}
_PLACED: dict[str, Any] = {
    "x_mm": {**_NUMBER_OR_NULL, "description": "room frame, mm"},
    "y_mm": {**_NUMBER_OR_NULL, "description": "room frame, mm"},
    "heading_rad": {**_NUMBER_OR_NULL, "description": "counter-clockwise from +X"},
    "x_valid": {"type": "boolean", "description": "table B.7's X-Valid"},
    "y_valid": {"type": "boolean", "description": "table B.7's Y-Valid"},
    "heading_valid": {"type": "boolean", "description": "table B.7's Drehung-Valid"},
}
_SYNC: dict[str, Any] = {
    "mode": {"type": "string", "enum": ["period", "count", "rounds"]},
    "sensor": _TEXT_OR_NULL,
    "count": _INT_OR_NULL,
    "period_ms": _INT_OR_NULL,
    "rounds": _INT_OR_NULL,
    "syncs": {"type": "integer", "minimum": 0},
    "last_sync_ms": _INT_OR_NULL,
    "last_period_ms": {**_NUMBER_OR_NULL, "description": "sensor time between the last two"},
    "mean_period_ms": _NUMBER_OR_NULL,
    "skipped": {"type": "integer", "minimum": 0, "description": "grid times jumped over"},
}
LOCALIZATION_SCHEMA: dict[str, Any] = {
    "title": "robot.Localization",
    "type": "object",
    "description": "copro's localisation as the seed's screen showed it (modules/localization/liveview.py)",
    "properties": {
        "stamp_ms": {**_INT_OR_NULL, "description": "the last synchronisation, sensor time"},
        "sensors": {
            "type": "object",
            "description": "every configured sensor by name: its newest raw sample and counts",
            "additionalProperties": {
                "type": "object",
                "properties": {
                    "values": {"type": ["object", "null"], "description": "the sample's fields by name"},
                    "stamp_ms": _INT_OR_NULL,
                    "seq": {**_INT_OR_NULL, "description": "the sensor's own sample number"},
                    "samples": {"type": "integer", "minimum": 0, "description": "taken into syncs"},
                    "missed": {**_INT_OR_NULL, "description": "null: no way to tell"},
                    "late": {"type": "integer", "minimum": 0},
                },
                "required": ["values", "stamp_ms", "seq", "samples", "missed", "late"],
            },
        },
        "sync": {"type": "object", "properties": _SYNC, "required": list(_SYNC)},
        "positions": {
            "type": "object",
            "description": "the position store by source name (odometry, compass, gyro, lops, truth, filter, walls)",
            "additionalProperties": {
                "type": "object",
                "properties": {
                    **_PLACED,
                    "letter": {"type": "string", "description": "its log source (table B.6)"},
                    "stamp_ms": _INT_OR_NULL,
                },
                "required": [*_PLACED, "letter", "stamp_ms"],
            },
        },
        "filter": {
            "type": "object",
            "description": "the best pose: the EKF's, else dead reckoning",
            "properties": {
                "source": {"type": "string", "enum": ["ekf", "odometry", "none"]},
                **_PLACED,
                "stamp_ms": {"type": "integer"},
                "sigma": {
                    "type": ["object", "null"],
                    "properties": {
                        "x_mm": {"type": "number"},
                        "y_mm": {"type": "number"},
                        "heading_rad": {"type": "number"},
                    },
                    "required": ["x_mm", "y_mm", "heading_rad"],
                    "description": "the filter's standard deviations; null without a filter",
                },
            },
            "required": ["source", *_PLACED, "stamp_ms", "sigma"],
        },
        "logs": {
            "type": "object",
            "properties": {"data": _TEXT_OR_NULL, "errors": _TEXT_OR_NULL, "failure": _TEXT_OR_NULL},
            "required": ["data", "errors", "failure"],
        },
        "message_count": {"type": "integer", "minimum": 0, "description": "messages said so far"},
    },
    "required": ["stamp_ms", "sensors", "sync", "positions", "filter", "logs", "message_count"],
}
MESSAGES_SCHEMA: dict[str, Any] = {
    "title": "robot.Messages",
    "type": "object",
    "properties": {
        "messages": {
            "type": "array",
            "description": f"the localisation's newest {MESSAGES_SHOWN} messages, oldest first",
            "items": {
                "type": "object",
                "properties": {
                    "n": {"type": "integer", "minimum": 0, "description": "its number since copro started"},
                    "class": {"type": "string", "description": "table B.5: I W E F D"},
                    "stamp_ms": {"type": "integer", "description": "sensor time"},
                    "text": {"type": "string"},
                },
                "required": ["n", "class", "stamp_ms", "text"],
            },
        },
    },
    "required": ["messages"],
}


MAIN_SCHEMA: dict[str, Any] = {
    "title": "robot.Main",
    "type": "object",
    "description": "main's state over its PC link (modules/main.py state()), sent when it changes",
    "properties": {
        "queue": {
            "type": "array",
            "items": {"type": "string"},
            "description": "the actions still queued as action-file lines, the one under way first",
        },
        "navigator": {"type": ["string", "null"], "description": "enum navigator's name"},
        "running": {"type": ["boolean", "null"], "description": "a navigator runs"},
        "abort_reason": {"type": ["string", "null"], "description": "enum abort_reason's name"},
        "steps": {"type": ["integer", "null"]},
        "error": {"type": "string", "description": "only when main stopped answering: why"},
    },
}


def navigator_schema(protocol: Protocol) -> dict[str, Any]:
    """``main.data`` with its enums as names (names from protocol.yaml)."""

    def names(enum: str) -> dict[str, Any]:
        known = ", ".join(protocol.enums.get(enum, {}))
        return {"type": "string", "description": f"enum {enum}: {known} (else the number as text)"}

    return {
        "title": "robot.Navigator",
        "type": "object",
        "properties": {
            "state": names("navigator"),
            "explore_mode": {"type": "integer"},
            "abort_reason": names("abort_reason"),
            "alert_lock": names("direction"),
            "steps_done": {"type": "integer"},
            "stamp_ms": {"type": "integer", "description": "simulated ms of the change"},
        },
        "required": ["state", "explore_mode", "abort_reason", "alert_lock", "steps_done", "stamp_ms"],
    }


def robot_topics(protocol: Protocol) -> list[Topic]:
    """Every topic the robot's feed sources write."""
    pose, tf, scene = "foxglove.PoseInFrame", "foxglove.FrameTransform", "foxglove.SceneUpdate"
    image = "foxglove.RawImage"
    return [
        Topic("/robot/pose/true", pose, foxglove_schema(pose), "ground truth (the simulator)"),
        Topic("/robot/pose/odometry", pose, foxglove_schema(pose), "the motor's dead reckoning"),
        Topic("/robot/pose/filtered", pose, foxglove_schema(pose), "copro's EKF pose"),
        Topic("/robot/uncertainty", "robot.Uncertainty", UNCERTAINTY_SCHEMA, "the EKF's sigmas"),
        Topic("/robot/tf", tf, foxglove_schema(tf), "room -> robot (filtered, else odometry)"),
        Topic("/robot/sonar", scene, foxglove_schema(scene), "the eight sonar beams as lines"),
        Topic("/robot/sonar/beams", "robot.SonarBeams", SONAR_BEAMS_SCHEMA, "the beams as numbers"),
        Topic("/robot/map", scene, foxglove_schema(scene), "the map's vectors as they are recorded"),
        Topic("/robot/map/vectors", "robot.MapVectors", MAP_VECTORS_SCHEMA, "the map's vectors, mm"),
        Topic("/robot/walls", scene, foxglove_schema(scene), "the room's true walls and obstacles"),
        Topic("/robot/walls/vectors", "robot.MapVectors", MAP_VECTORS_SCHEMA, "the true walls, mm"),
        Topic("/robot/lcd", "robot.Lcd", LCD_SCHEMA, "the LCD's text lines"),
        Topic("/robot/lcd/image", image, foxglove_schema(image), "the LCD's screen (128x64)"),
        Topic("/robot/navigator", "robot.Navigator", navigator_schema(protocol), "main's navigator"),
        Topic("/robot/localization", "robot.Localization", LOCALIZATION_SCHEMA, "copro's localisation"),
        Topic("/robot/messages", "robot.Messages", MESSAGES_SCHEMA, "the localisation's messages"),
        Topic("/robot/main", "robot.Main", MAIN_SCHEMA, "main's action queue and navigator"),
    ]


# --------------------------------------------------------------------------------------------
# Foxglove-shaped values


def stamp(time_ns: int) -> dict[str, int]:
    """A Foxglove ``time``: whole seconds and nanoseconds."""
    return {"sec": time_ns // 1_000_000_000, "nsec": time_ns % 1_000_000_000}


def yaw_quaternion(theta: float) -> dict[str, float]:
    """A rotation of ``theta`` radians about +z (counter-clockwise seen from above); the angle is
    wrapped to (-pi, pi] first, so ``w`` >= 0 (one of the two equal quaternions, always the same)."""
    half = wrap_angle(theta) / 2.0
    return {"x": 0.0, "y": 0.0, "z": math.sin(half), "w": math.cos(half)}


def pose_in_frame(time_ns: int, x_mm: float, y_mm: float, theta: float) -> dict[str, Any]:
    """A ``foxglove.PoseInFrame`` in the room frame from a pose in mm / radians CCW."""
    return {
        "timestamp": stamp(time_ns),
        "frame_id": FRAME_ROOM,
        "pose": {
            "position": {"x": x_mm / 1000.0, "y": y_mm / 1000.0, "z": 0.0},
            "orientation": yaw_quaternion(theta),
        },
    }


def frame_transform(time_ns: int, x_mm: float, y_mm: float, theta: float) -> dict[str, Any]:
    """A ``foxglove.FrameTransform`` room → robot."""
    return {
        "timestamp": stamp(time_ns),
        "parent_frame_id": FRAME_ROOM,
        "child_frame_id": FRAME_ROBOT,
        "translation": {"x": x_mm / 1000.0, "y": y_mm / 1000.0, "z": 0.0},
        "rotation": yaw_quaternion(theta),
    }


def _color(r: float, g: float, b: float, a: float = 1.0) -> dict[str, float]:
    return {"r": r, "g": g, "b": b, "a": a}


_IDENTITY = {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": yaw_quaternion(0.0)}
LINE_LIST = 2  # foxglove.LinePrimitive.Type


def line_list(segments_m: list[list[float]], color: dict[str, float], thickness_px: float) -> dict[str, Any]:
    """A ``foxglove.LinePrimitive`` drawing each [x1, y1, x2, y2] (m) as one segment."""
    points = []
    for x1, y1, x2, y2 in segments_m:
        points += [{"x": x1, "y": y1, "z": 0.0}, {"x": x2, "y": y2, "z": 0.0}]
    return {
        "type": LINE_LIST,
        "pose": _IDENTITY,
        "thickness": thickness_px,
        "scale_invariant": True,
        "points": points,
        "color": color,
        "colors": [],
        "indices": [],
    }


def scene_entity(
    time_ns: int, entity_id: str, lines: list[dict[str, Any]], cylinders: list[dict[str, Any]] | None = None
) -> dict[str, Any]:
    """A ``foxglove.SceneEntity`` in the room frame with line (and cylinder) primitives."""
    return {
        "timestamp": stamp(time_ns),
        "frame_id": FRAME_ROOM,
        "id": entity_id,
        "lifetime": {"sec": 0, "nsec": 0},  # until replaced
        "frame_locked": False,
        "metadata": [],
        "arrows": [],
        "cubes": [],
        "spheres": [],
        "cylinders": cylinders or [],
        "lines": lines,
        "triangles": [],
        "texts": [],
        "models": [],
    }


def scene_update(entities: list[dict[str, Any]]) -> dict[str, Any]:
    """A ``foxglove.SceneUpdate`` replacing the given entities (same ``id``: replaced)."""
    return {"deletions": [], "entities": entities}


# --------------------------------------------------------------------------------------------
# sources


@dataclass
class RobotSource(FeedSource):
    """Poses, uncertainty, tf, sonar, map and navigator from the token's frames and the truth."""

    protocol: Protocol
    _last_frame: bytes = b""
    _last: dict[str, bytes] = field(default_factory=dict)
    _truth: tuple[float, float, float] | None = None
    _odometry: tuple[float, float, float] | None = None
    _filtered: tuple[float, float, float] | None = None
    _filter_on: bool = False
    _map: list[list[float]] = field(default_factory=list)
    _map_seen: set[tuple[int, int, int]] = field(default_factory=set)
    _navigator_state: tuple[Any, ...] = ()
    #: the sonar pairs of the ring's body (``up`` gives its watcher the ring's ``--algorithms``)
    mounts: tuple[SonarMount, ...] = field(default_factory=body_mounts)

    def topics(self) -> list[Topic]:
        others = WorldSource.NAMES + LcdSource.NAMES + LocalizationSource.NAMES + MainSource.NAMES
        return [t for t in robot_topics(self.protocol) if t.name not in others]

    def keys(self, ring: str) -> list[str]:
        return [keys.token(ring, "*"), robot_keys.world(ring, "truth")]

    def translate(self, key: str, payload: bytes, time_ns: int) -> list[Message]:
        if key.endswith("/world/truth"):
            return self._on_truth(payload, time_ns)
        return self._on_frame(payload, time_ns)

    # -- ground truth -------------------------------------------------------------------------

    def _on_truth(self, payload: bytes, time_ns: int) -> list[Message]:
        try:
            truth = decode_msgpack(payload)
            pose = (float(truth["x_mm"]), float(truth["y_mm"]), float(truth["theta_rad"]))
        except (ValueError, KeyError, TypeError):
            return []
        if not all(math.isfinite(v) for v in pose):
            return []
        self._truth = pose
        return [Message("/robot/pose/true", time_ns, pose_in_frame(time_ns, *pose))]

    # -- the token ----------------------------------------------------------------------------

    def _changed(self, frame: bytes, name: str, written: bool = False) -> bool:
        """Whether channel ``name`` differs from the last frame's; with ``written``, also whether
        its module wrote it at all (a channel of only zero bytes is the fresh token's, e.g. the
        motor's before it knows its start pose: not a pose at the room's origin)."""
        ch = self.protocol.channel(name)
        raw = frame[ch.address : ch.end]
        if self._last.get(name) == raw:
            return False
        self._last[name] = raw
        return not written or any(raw)

    def _on_frame(self, frame: bytes, time_ns: int) -> list[Message]:
        if frame == self._last_frame or frame_problem(frame, self.protocol):
            return []  # the same token seen at the next hop, or a damaged frame
        self._last_frame = frame
        out: list[Message] = []
        if self._changed(frame, "copro.data"):
            out += self._copro(self.protocol.channel("copro.data").decode(frame), time_ns)
        if self._changed(frame, "motor.data", written=True):
            out += self._motor(self.protocol.channel("motor.data").decode(frame), time_ns)
        if self._changed(frame, "sonar.data", written=True):
            out += self._sonar(self.protocol.channel("sonar.data").decode(frame), time_ns)
        if self._changed(frame, "map.command"):
            channel = self.protocol.channel("map.command")
            assert isinstance(channel, CommandChannel)
            out += self._map_command(channel.decode_command(frame), time_ns)
        if self._changed(frame, "main.data"):
            out += self._navigator(self.protocol.channel("main.data").decode(frame), time_ns)
        return out

    def _motor(self, data: dict[str, Any], time_ns: int) -> list[Message]:
        pose = (float(data["x_mm"]), float(data["y_mm"]), cdeg_cw_to_rad_ccw(int(data["angle_cdeg"])))
        self._odometry = pose
        out = [Message("/robot/pose/odometry", time_ns, pose_in_frame(time_ns, *pose))]
        if not self._filter_on:
            out.append(Message("/robot/tf", time_ns, frame_transform(time_ns, *pose)))
        return out

    def _copro(self, data: dict[str, Any], time_ns: int) -> list[Message]:
        self._filter_on = data["pose_source"] == POSE_SOURCE_EKF
        if not self._filter_on:
            return []
        pose = (
            float(data["pose_x_mm"]),
            float(data["pose_y_mm"]),
            cdeg_cw_to_rad_ccw(int(data["pose_angle_cdeg"])),
        )
        self._filtered = pose
        out = [
            Message("/robot/pose/filtered", time_ns, pose_in_frame(time_ns, *pose)),
            Message("/robot/tf", time_ns, frame_transform(time_ns, *pose)),
        ]
        if data.get("sigma_x_mm"):  # 0: copro has no filter's uncertainty to give
            sigmas = {
                "sigma_x_m": data["sigma_x_mm"] / 1000.0,
                "sigma_y_m": data["sigma_y_mm"] / 1000.0,
                "sigma_theta_rad": math.radians(data["sigma_angle_cdeg"] / 100.0),
                "source": "ekf",
            }
            out.append(Message("/robot/uncertainty", time_ns, sigmas))
        return out

    def _sonar(self, data: dict[str, Any], time_ns: int) -> list[Message]:
        # where the echoes really came from (the simulator's truth, against the true walls);
        # without a simulator, where the robot believes it is
        candidates = (
            ("true", self._truth),
            ("filtered", self._filtered if self._filter_on else None),
            ("odometry", self._odometry),
        )
        placed = next(((name, pose) for name, pose in candidates if pose is not None), None)
        if placed is None:
            return []
        name, (x, y, theta) = placed
        segments: list[list[float]] = []
        contact: list[bool] = []
        distances = [int(d) for d in data["distances"]]
        for mount in self.mounts:
            d = distances[mount.index]
            hit = d != SONAR_NO_CONTACT
            reach = d * 10.0 if hit else SONAR_RANGE_MM
            sx, sy, angle = sonar_world_pose(x, y, theta, mount.index, self.mounts)
            ex, ey = sx + reach * math.cos(angle), sy + reach * math.sin(angle)
            segments.append([sx / 1000.0, sy / 1000.0, ex / 1000.0, ey / 1000.0])
            contact.append(hit)
        hits = [s for s, c in zip(segments, contact, strict=True) if c]
        misses = [s for s, c in zip(segments, contact, strict=True) if not c]
        lines = [
            line_list(hits, _color(0.9, 0.2, 0.1), 3.0),
            line_list(misses, _color(0.5, 0.5, 0.5, 0.25), 1.0),
        ]
        beams = {
            "frame_id": FRAME_ROOM,
            "pose": name,
            "distances_cm": distances,
            "segments_m": segments,
            "contact": contact,
        }
        return [
            Message("/robot/sonar", time_ns, scene_update([scene_entity(time_ns, "sonar", lines)])),
            Message("/robot/sonar/beams", time_ns, beams),
        ]

    def _map_command(self, cmd: dict[str, Any], time_ns: int) -> list[Message]:
        name = cmd.get("command")
        if name not in (VECTOR_CODE_NAME, "CLEAR_MAP"):
            return []
        ident = (int(cmd["sender"]), int(cmd["incarnation"]), int(cmd["seq"]))
        if ident in self._map_seen:
            return []  # the same command seen again (acknowledged, or another hop)
        self._map_seen.add(ident)
        if name == "CLEAR_MAP":
            self._map.clear()
        else:
            a = cmd["args"]
            self._map.append([a["x1"] * 10.0, a["y1"] * 10.0, a["x2"] * 10.0, a["y2"] * 10.0])
        return self.map_messages(time_ns)

    def map_messages(self, time_ns: int) -> list[Message]:
        """The whole map as recorded so far (a SceneUpdate replaces the entity)."""
        segments_m = [[v / 1000.0 for v in vector] for vector in self._map]
        entity = scene_entity(time_ns, "map", [line_list(segments_m, _color(0.85, 0.1, 0.1), 2.5)])
        return [
            Message("/robot/map", time_ns, scene_update([entity])),
            Message("/robot/map/vectors", time_ns, {"vectors": [list(v) for v in self._map]}),
        ]

    def _navigator(self, data: dict[str, Any], time_ns: int) -> list[Message]:
        p = self.protocol
        out = {
            "state": p.enum_name("navigator", int(data["navigator"])),
            "explore_mode": int(data["explore_mode"]),
            "abort_reason": p.enum_name("abort_reason", int(data["abort_reason"])),
            "alert_lock": p.enum_name("direction", int(data["alert_lock"])),
            "steps_done": int(data["steps_done"]),
            "stamp_ms": int(data["stamp_ms"]),
        }
        state = tuple(v for k, v in out.items() if k != "stamp_ms")
        if state == self._navigator_state:
            return []  # only main's time stamp moved on
        self._navigator_state = state
        return [Message("/robot/navigator", time_ns, out)]


@dataclass
class WorldSource(FeedSource):
    """The room's true walls and obstacles (``world/info``), asked again every few seconds so a
    late subscriber (or a recording started later) gets them too."""

    protocol: Protocol
    poll_interval_s: float = 3.0
    NAMES = ("/robot/walls", "/robot/walls/vectors")

    def topics(self) -> list[Topic]:
        return [t for t in robot_topics(self.protocol) if t.name in self.NAMES]

    def poll(self, session: Any, ring: str, time_ns: int) -> list[Message]:
        from tokenring.transport import query

        for _, reply in query(session, robot_keys.world(ring, "info"), timeout=1.0):
            if reply.get("ok"):
                return walls_messages(reply["result"], time_ns)
        return []


def walls_messages(info: dict[str, Any], time_ns: int) -> list[Message]:
    """``/robot/walls`` (SceneUpdate) and ``/robot/walls/vectors`` (mm) from ``world/info``."""
    walls = [[float(v) for v in w[:4]] for w in info.get("walls", [])]
    circles = [[float(v) for v in c[:3]] for c in info.get("circles", [])]
    vectors = list(walls)
    for cx, cy, r in circles:
        for k in range(CIRCLE_SEGMENTS):
            a, b = 2 * math.pi * k / CIRCLE_SEGMENTS, 2 * math.pi * (k + 1) / CIRCLE_SEGMENTS
            vectors.append(
                [cx + r * math.cos(a), cy + r * math.sin(a), cx + r * math.cos(b), cy + r * math.sin(b)]
            )
    height_m = 0.3
    cylinders = [
        {
            "pose": {
                "position": {"x": cx / 1000.0, "y": cy / 1000.0, "z": height_m / 2},
                "orientation": yaw_quaternion(0.0),
            },
            "size": {"x": 2 * r / 1000.0, "y": 2 * r / 1000.0, "z": height_m},
            "bottom_scale": 1.0,
            "top_scale": 1.0,
            "color": _color(0.4, 0.4, 0.45, 0.6),
        }
        for cx, cy, r in circles
    ]
    lines = [line_list([[v / 1000.0 for v in w] for w in walls], _color(0.2, 0.2, 0.25), 3.0)]
    entity = scene_entity(time_ns, "walls", lines, cylinders)
    entity["metadata"] = [{"key": "world", "value": str(info.get("name", ""))}]
    return [
        Message("/robot/walls", time_ns, scene_update([entity])),
        Message("/robot/walls/vectors", time_ns, {"vectors": vectors}),
    ]


@dataclass
class LcdSource(FeedSource):
    """The LCD: its screen (``lcd/screen``, a 128×64 one-bit bitmap) as an image, and its text
    lines, which only what draws them knows: the lcd program's report (``ctl/70/program``), or
    before any program runs the OS menu's (``ctl/70/resident``), asked once a second."""

    protocol: Protocol
    poll_interval_s: float = 1.0
    NAMES = ("/robot/lcd", "/robot/lcd/image")

    def topics(self) -> list[Topic]:
        return [t for t in robot_topics(self.protocol) if t.name in self.NAMES]

    def keys(self, ring: str) -> list[str]:
        return [robot_keys.lcd(ring, "screen")]

    def translate(self, key: str, payload: bytes, time_ns: int) -> list[Message]:
        if len(payload) != LCD_WIDTH * LCD_HEIGHT // 8:
            return []
        return [Message("/robot/lcd/image", time_ns, lcd_image(payload, time_ns))]

    def poll(self, session: Any, ring: str, time_ns: int) -> list[Message]:
        from tokenring.transport import query

        node = self.protocol.node("lcd").id
        for verb in ("program", "resident"):
            for _, reply in query(session, keys.control(ring, node, verb), timeout=1.0):
                if not reply.get("ok"):
                    continue
                report = (reply.get("result") or {}).get("report") or {}
                if verb == "resident" and not report.get("showing"):
                    continue  # the OS menu is not on the display: a program's screen is
                if isinstance(report.get("lines"), list):
                    data = {
                        "lines": [str(line) for line in report["lines"]],
                        "menu": str(report.get("menu", "")),
                    }
                    return [Message("/robot/lcd", time_ns, data)]
        return []


def lcd_image(screen: bytes, time_ns: int) -> dict[str, Any]:
    """A ``foxglove.RawImage`` (mono8) of the screen: rows of 16 bytes, MSB the leftmost pixel;
    a lit pixel is dark (0) on the pale background (255), as the display shows it."""
    pixels = bytes(0 if byte & (0x80 >> bit) else 255 for byte in screen for bit in range(8))
    return {
        "timestamp": stamp(time_ns),
        "frame_id": "lcd",
        "width": LCD_WIDTH,
        "height": LCD_HEIGHT,
        "encoding": "mono8",
        "step": LCD_WIDTH,
        "data": base64.b64encode(pixels).decode("ascii"),
    }


@dataclass
class LocalizationSource(FeedSource):
    """copro's localisation (:mod:`modules.localization.liveview`): its live state as
    ``/robot/localization``, and its messages as ``/robot/messages``, the newest
    :data:`MESSAGES_SHOWN` sent whole again as each one comes.

    A feed opened late asks once for the messages said before (the ``robot/localization/messages``
    backlog); they join the list on the feed's own thread with the next sample of either key, so
    no list sent lacks a message an earlier one had, and each message is in it once (by its
    copro's ``run`` and number ``n``). Should the localisation say nothing for a whole poll
    interval, the next poll sends them itself."""

    protocol: Protocol
    poll_interval_s: float = 1.0
    NAMES = ("/robot/localization", "/robot/messages")
    _known: dict[tuple[int, int], dict[str, Any]] = field(default_factory=dict)  # (run, n) -> entry
    _runs: dict[str, int] = field(default_factory=dict)  # copro's run -> the order it was first seen in
    _backlog: list[dict[str, Any]] | None = None  # asked for, not in the list yet
    _backlog_polls: int = 0
    _asked: bool = False
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def topics(self) -> list[Topic]:
        return [t for t in robot_topics(self.protocol) if t.name in self.NAMES]

    def keys(self, ring: str) -> list[str]:
        return [robot_keys.localization(ring, "state"), robot_keys.localization(ring, "message")]

    def translate(self, key: str, payload: bytes, time_ns: int) -> list[Message]:
        try:
            data = decode_msgpack(payload)
        except Exception:
            return []
        if not isinstance(data, dict):
            return []
        out: list[Message] = []
        with self._lock:
            changed = self._take_backlog()
            if key.rsplit("/", 1)[-1] == "state":
                out.append(Message("/robot/localization", time_ns, data))
            else:
                changed = self._add(data) or changed
            if changed:
                out.append(self._messages(time_ns))
        return out

    def poll(self, session: Any, ring: str, time_ns: int) -> list[Message]:
        with self._lock:
            if self._backlog is not None:
                self._backlog_polls += 1
                if self._backlog_polls < 2 or not self._take_backlog():
                    return []
                return [self._messages(time_ns)]  # the localisation fell silent: shown from here
            if self._asked:
                return []
        from tokenring.transport import query

        for _, reply in query(session, robot_keys.localization(ring, "messages"), timeout=1.0):
            result = reply.get("result") if reply.get("ok") else None
            if isinstance(result, dict) and isinstance(result.get("messages"), list):
                run = str(result.get("run", ""))
                with self._lock:
                    self._backlog = [{**m, "run": run} for m in result["messages"] if isinstance(m, dict)]
                    self._backlog_polls = 0
                    self._asked = True
                break
        return []

    # -- with the lock held ----------------------------------------------------------------------

    def _take_backlog(self) -> bool:
        backlog, self._backlog = self._backlog, None
        if not backlog:
            return False
        added = [self._add(entry, trim=False) for entry in backlog]
        self._trim()
        return any(added)

    def _add(self, entry: dict[str, Any], trim: bool = True) -> bool:
        """One message into the list; False if it is not one, or there already."""
        n, stamp, cls, text = entry.get("n"), entry.get("stamp_ms"), entry.get("class"), entry.get("text")
        if not (
            isinstance(n, int) and isinstance(stamp, int) and isinstance(cls, str) and isinstance(text, str)
        ):
            return False
        run = self._runs.setdefault(str(entry.get("run", "")), len(self._runs))
        if (run, n) in self._known:
            return False
        self._known[(run, n)] = {"n": n, "class": cls, "stamp_ms": stamp, "text": text}
        if trim:
            self._trim()
        return True

    def _trim(self) -> None:
        if len(self._known) > MESSAGES_SHOWN:
            for old in sorted(self._known)[:-MESSAGES_SHOWN]:
                del self._known[old]

    def _messages(self, time_ns: int) -> Message:
        shown = [dict(self._known[k]) for k in sorted(self._known)]
        return Message("/robot/messages", time_ns, {"messages": shown})


@dataclass
class MainSource(FeedSource):
    """main's action queue and navigator (its ``state`` over the PC link, as ``tokenring
    console`` asks it) as ``/robot/main``, sent when it changes; once main stops answering, one
    message with ``error``, and it is asked again only every few seconds."""

    protocol: Protocol
    poll_interval_s: float = 0.5
    NAMES = ("/robot/main",)
    KEPT = ("queue", "navigator", "running", "abort_reason", "steps")
    RETRY_S = 5.0
    _link: Any = None
    _last: Any = None
    _quiet_until: float = 0.0

    def topics(self) -> list[Topic]:
        return [t for t in robot_topics(self.protocol) if t.name in self.NAMES]

    def poll(self, session: Any, ring: str, time_ns: int) -> list[Message]:
        import time

        from tokenring import TokenRingError
        from tokenring.host import PcLink

        if time.monotonic() < self._quiet_until:
            return []
        if self._link is None:
            self._link = PcLink(session, ring, timeout=1.0, connect_timeout=1.0)
        try:
            state = self._link.request("state")
            out = {k: state.get(k) for k in self.KEPT} if isinstance(state, dict) else None
        except TokenRingError as exc:
            self._quiet_until = time.monotonic() + self.RETRY_S
            out = {"error": str(exc)} if self._last is not None else None  # said once it was heard
        if out is None or out == self._last:
            return []
        self._last = out
        return [Message("/robot/main", time_ns, out)]


def robot_feed_sources(protocol: Protocol, ring: str) -> list[FeedSource]:
    """The robot's sources for :meth:`modules.plugin.RobotExtension.feed_sources`."""
    return [
        RobotSource(protocol),
        WorldSource(protocol),
        LcdSource(protocol),
        LocalizationSource(protocol),
        MainSource(protocol),
    ]
