"""The localisation's logs as MCAP (``tokenring log convert --to mcap``): Foxglove draws the
poses, PlotJuggler plots every number, in the same format as a live recording.

A data log (``.trlog``) becomes

* ``/robot/pose/true``, ``/robot/pose/odometry``, ``/robot/pose/filtered`` (and
  ``/robot/pose/compass``, ``/robot/pose/gyroscope``): its position records (``T``, ``O``, ``K``,
  ``M``, ``G`` ``P``: the filter's and each sensor's with a ``pose_topic``) as
  ``foxglove.PoseInFrame`` in the room frame, metres, exactly as the live feed's
  (:mod:`modules.pc.feed`); ``/robot/tf`` from the filter's pose, ``/robot/uncertainty`` from its
  standard deviations;
* ``/log/<source>/<kind>`` (``/log/odometry/raw``, ``/log/filter/position``, ...): every record,
  its payload's fields with ``stamp_ms`` beside them.

An error log (``.trerr``) becomes ``/log/errors`` as ``foxglove.Log``. Message times are the log's
start time plus each record's ``stamp_ms`` (the sensors' own clock).
"""

from __future__ import annotations

from collections import Counter
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from modules.localization.logs import KINDS, LogFile, sources
from modules.localization.sensors import registered
from tokenring import UsageError
from tokenring.observe import Message, Topic

#: the filter's pose (not a sensor's)
FILTER_TOPIC = "/robot/pose/filtered"
#: the poses the live feed (:mod:`modules.pc.feed`) publishes, first and in its order
LIVE_POSES = ("/robot/pose/true", "/robot/pose/odometry", FILTER_TOPIC)


def pose_topics() -> dict[str, str]:
    """The pose topic of each position source: the filter's and each sensor's ``pose_topic``;
    the live feed's first (truth, dead reckoning, filter), then the others in sensor order."""
    topics = {s.letter: s.pose_topic for s in registered() if s.pose_topic is not None}
    topics["K"] = FILTER_TOPIC
    first = [item for name in LIVE_POSES for item in topics.items() if item[1] == name]
    return dict(first + [item for item in topics.items() if item[1] not in LIVE_POSES])


def __getattr__(name: str) -> Any:
    """:data:`POSE_TOPICS` (:func:`pose_topics`), worked out from the sensor registry when read."""
    if name == "POSE_TOPICS":
        return pose_topics()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


#: foxglove.LogLevel for the seed's error classes
LOG_LEVELS = {"D": 1, "I": 2, "W": 3, "E": 4, "F": 5}


def start_ns(log: LogFile) -> int:
    """The log's start (``20040120-130535``, read as UTC) in ns since the epoch; 0 if unreadable."""
    try:
        started = datetime.strptime(str(log.header.get("start", "")), "%Y%m%d-%H%M%S")
    except ValueError:
        return 0
    return int(started.replace(tzinfo=UTC).timestamp()) * 1_000_000_000


def record_topic(source: str, kind: str) -> str:
    """``/log/<source>/<kind>``: the topic of a record's fields."""
    return f"/log/{sources().get(source, source)}/{KINDS.get(kind, kind).replace(' ', '_')}"


def log_topics(log: LogFile) -> list[Topic]:
    """The topics this log makes, with their schemas."""
    from modules.pc.feed import UNCERTAINTY_SCHEMA, foxglove_schema

    if log.kind == "errors":
        return [Topic("/log/errors", "foxglove.Log", foxglove_schema("foxglove.Log"), "the error log")]
    pose = foxglove_schema("foxglove.PoseInFrame")
    titles = sources()
    out = [
        Topic(name, "foxglove.PoseInFrame", pose, f"{titles[k]} positions")
        for k, name in pose_topics().items()
    ]
    out.append(Topic("/robot/tf", "foxglove.FrameTransform", foxglove_schema("foxglove.FrameTransform")))
    out.append(Topic("/robot/uncertainty", "robot.Uncertainty", UNCERTAINTY_SCHEMA, "the EKF's sigmas"))
    for source, kind in sorted({(r[1], r[2]) for r in log.records}):
        name = f"trlog.{titles.get(source, source)}.{KINDS.get(kind, kind).replace(' ', '_')}"
        schema = {"title": name, "type": "object", "properties": {"stamp_ms": {"type": "integer"}}}
        out.append(Topic(record_topic(source, kind), name, schema, f"the log's {source} {kind} records"))
    return out


def log_messages(log: LogFile) -> list[Message]:
    """Every message of the log's topics (in the log's record order)."""
    from modules.pc.feed import frame_transform, pose_in_frame

    base = start_ns(log)
    poses = pose_topics()
    out: list[Message] = []
    for record in log.records:
        t = base + max(0, int(record[0])) * 1_000_000
        if log.kind == "errors":
            stamp, cls, text = record
            when = {"sec": t // 1_000_000_000, "nsec": t % 1_000_000_000}
            data = {
                "timestamp": when,
                "level": LOG_LEVELS.get(cls, 0),
                "message": text,
                "name": "localisation",
            }
            out.append(Message("/log/errors", t, data))
            continue
        stamp, source, kind, payload = record
        fields = dict(payload) if isinstance(payload, dict) else {"value": payload}
        out.append(Message(record_topic(source, kind), t, {"stamp_ms": stamp, **fields}))
        if kind != "P" or source not in poses:
            continue
        x, y, psi = float(payload["x"]), float(payload["y"]), float(payload["psi"])
        out.append(Message(poses[source], t, pose_in_frame(t, x, y, psi)))
        if source == "K":
            out.append(Message("/robot/tf", t, frame_transform(t, x, y, psi)))
            sigma = payload.get("sigma")
            if isinstance(sigma, list) and len(sigma) == 3:
                out.append(
                    Message(
                        "/robot/uncertainty",
                        t,
                        {
                            "sigma_x_m": float(sigma[0]) / 1000.0,
                            "sigma_y_m": float(sigma[1]) / 1000.0,
                            "sigma_theta_rad": float(sigma[2]),
                            "source": "ekf",
                        },
                    )
                )
    return out


def convert_mcap(log: LogFile, out: str | Path) -> Counter[str]:
    """Write ``log`` as an MCAP file (via the ring's recorder: FILE.part, renamed when whole);
    the message count per topic."""
    from tokenring.observe import McapRecorder

    recorder = McapRecorder(
        out,
        ring="",
        topics=log_topics(log),
        metadata={
            "source": str(log.path.name),
            "log_kind": log.kind,
            "log_start": str(log.header.get("start", "")),
        },
        keep_partial=False,  # a conversion that failed leaves no file: it can be run again
    )
    try:
        for message in log_messages(log):
            recorder.on_message(message)
            if recorder.failure:
                break
    finally:
        recorder.close()
    if recorder.failure:
        raise UsageError(f"--out {recorder.failure}")
    return recorder.counts
