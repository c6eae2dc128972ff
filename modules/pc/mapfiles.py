"""The robot's map as files: fetch it from the ring (GET_MAP through main), read the true walls
of a room, write JSON / DXF / PNG (scored against the truth when it is known), read maps back.

Used by ``tokenring map``, ``score`` and ``up --map-out``, and by the benchmarks."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from modules.description import keys as robot_keys
from tokenring import UsageError

FORMATS = (".json", ".dxf", ".png")


def map_format(path: str, option: str = "--out") -> str:
    """The format of a map file to write, from its extension; ``option`` names it in the error."""
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        raise UsageError(f"{option} {path}: unknown format {suffix or '(none)'}; use .json, .dxf or .png")
    return suffix


def check_out(path: str, option: str = "--out", force: bool = False, inputs: tuple[str, ...] = ()) -> str:
    """Refuse the map file ``option`` names before anything starts: an unknown format, an
    existing file (unless ``force``), one of the ``inputs``, a folder missing or not writable."""
    from tokenring import check_output, option_error

    suffix = map_format(path, option)
    check_output(path, inputs, force=force, error=option_error(option))
    return suffix


def fetch_map(session: Any, ring: str, timeout: float = 60.0) -> np.ndarray:
    """The ring's map in mm, via main's PC link."""
    from tokenring.host import open_link

    link = open_link(session, ring)
    got = link.request("get_map", timeout=timeout)
    return np.asarray(got["vectors"], dtype=float).reshape(-1, 4) * 10.0


def live_world(session: Any, ring: str) -> dict[str, Any] | None:
    """The running simulator's room (``world/info``), or None without a simulator."""
    from tokenring.transport import query

    for _, reply in query(session, robot_keys.world(ring, "info"), timeout=1.0):
        if reply.get("ok"):
            return reply["result"]
    return None


def true_pose(session: Any, ring: str) -> dict[str, Any] | None:
    """The world simulator's ground truth (``world/state``), or None when no world runs."""
    from tokenring.transport import query

    for _, reply in query(session, robot_keys.world(ring, "state"), timeout=1.0):
        if reply.get("ok"):
            return reply["result"]
    return None


def end_pose(session: Any, ring: str, estimate: list[float] | None) -> dict[str, Any] | None:
    """How far main's pose ``estimate`` (x mm, y mm, theta rad: the filter's, else dead
    reckoning) is from the simulator's ground truth now; None without either."""
    truth = true_pose(session, ring) if estimate is not None else None
    return pose_error(estimate, truth)


def pose_error(estimate: list[float] | None, truth: dict[str, Any] | None) -> dict[str, Any] | None:
    """How far ``estimate`` (x mm, y mm, theta rad) is from ``truth`` (the world's truth record:
    ``x_mm``, ``y_mm``, ``theta_rad``); None without either."""
    if estimate is None or truth is None:
        return None
    x, y, theta = (float(v) for v in estimate[:3])
    turned = math.remainder(theta - float(truth["theta_rad"]), math.tau)
    return {
        "estimate": [round(x, 1), round(y, 1), round(theta, 5)],
        "truth": [round(truth["x_mm"], 1), round(truth["y_mm"], 1), round(truth["theta_rad"], 5)],
        "error_mm": round(math.hypot(x - truth["x_mm"], y - truth["y_mm"]), 1),
        "heading_error_deg": round(math.degrees(turned), 2),
    }


def truth_from_info(info: dict[str, Any]) -> tuple[str, np.ndarray]:
    walls = [list(w) for w in info.get("walls", [])]
    for x, y, r in info.get("circles", []):
        a = np.linspace(0, 2 * np.pi, 33)
        xs, ys = x + r * np.cos(a), y + r * np.sin(a)
        walls += np.column_stack([xs[:-1], ys[:-1], xs[1:], ys[1:]]).tolist()
    return str(info.get("name", "world")), np.asarray(walls, dtype=float).reshape(-1, 4)


def load_truth(world: str) -> tuple[str, np.ndarray]:
    """A world's name and true walls (mm); UsageError naming the world if it cannot be read."""
    from modules.description import WorldError, load_world

    try:
        room = load_world(world)
    except WorldError as exc:
        raise UsageError(f"--world {world}: {exc}") from None
    return room.name, room.outline()


def load_map_file(path: str) -> np.ndarray:
    """Vectors (mm) from a map written by ``tokenring map`` (.json) or any DXF's LINE entities."""
    from tokenring import check_input, read_text

    file = Path(path)
    if file.suffix.lower() == ".dxf":
        import ezdxf

        check_input(file, "map file")  # a FIFO, a device or a huge file is refused before ezdxf
        try:
            doc = ezdxf.readfile(file)  # DXF text may be in an older code page: ezdxf decodes it
            lines = [e for e in doc.modelspace().query("LINE") if e.dxf.layer != "TRUTH"]
        except Exception as exc:  # ezdxf raises more than DXFError on a damaged file (StopIteration)
            raise UsageError(f"{path}: not a readable DXF file ({type(exc).__name__}: {exc})") from None
        vectors = [[e.dxf.start.x, e.dxf.start.y, e.dxf.end.x, e.dxf.end.y] for e in lines]
        return _checked(np.asarray(vectors, dtype=float).reshape(-1, 4), path)
    text = read_text(file, "map file")
    try:
        doc = json.loads(text, parse_constant=_refuse_constant)
    except json.JSONDecodeError as exc:
        raise UsageError(f"{path}:{exc.lineno}: not valid JSON: {exc.msg}") from None
    except ValueError as exc:
        raise UsageError(f"{path}: {exc}") from None
    vectors = doc.get("vectors") if isinstance(doc, dict) else None
    if not isinstance(vectors, list):
        raise UsageError(f"{path}: a map file has a 'vectors' list of [x1, y1, x2, y2] in mm")
    for i, v in enumerate(vectors):
        if not (isinstance(v, list) and len(v) == 4 and all(isinstance(c, int | float) for c in v)):
            raise UsageError(f"{path}: vectors[{i}] is not [x1, y1, x2, y2] (numbers, mm)")
    return _checked(np.asarray(vectors, dtype=float).reshape(-1, 4), path)


def _refuse_constant(name: str) -> float:
    raise ValueError(f"{name} is not a coordinate (numbers in mm only)")


def _checked(vectors: np.ndarray, path: str) -> np.ndarray:
    """Refuse coordinates that are not finite or absurdly far (1e400 reads as inf)."""
    from modules.description.roomfile import MAX_COORDINATE_MM  # what a room may span

    bad = ~np.isfinite(vectors) | (np.abs(vectors) > MAX_COORDINATE_MM)
    if bad.any():
        row = int(np.argwhere(bad)[0][0])
        raise UsageError(
            f"{path}: vectors[{row}] has a coordinate that is not a finite number of mm within ±{MAX_COORDINATE_MM:g}"
        )
    return vectors


def write_map(
    vectors: np.ndarray,
    path: str,
    truth: np.ndarray | None = None,
    world: str | None = None,
    title: str = "",
    paths: dict[str, np.ndarray] | None = None,
    end: dict[str, Any] | None = None,
    option: str = "--out",
) -> dict[str, Any] | None:
    """Write ``vectors`` (mm) in the format of ``path``'s extension; returns the score if known.
    ``paths``: robot paths (name -> N×2 mm) drawn thinly in a PNG (the true one, the mapping pose);
    ``end``: the robot's end pose against the truth (:func:`end_pose`), kept in a .json map.
    The map goes to a temporary file renamed over ``path`` once whole: a failed write (a full
    disk) is one line naming ``option`` and leaves the file that was there as it was."""
    from modules.pc.mapscore import score_map
    from tokenring import option_error, replacing

    suffix = map_format(path, option)
    score = score_map(vectors, truth) if truth is not None else None
    with replacing(path, option_error(option)) as temp:
        if suffix == ".json":
            temp.write_text(map_document(vectors, world, score, end), encoding="utf-8")
        elif suffix == ".dxf":
            write_dxf(vectors, temp, truth)
        else:
            write_png(vectors, temp, truth, title or (world or "map"), score, paths)
    return score


def map_document(
    vectors: np.ndarray, world: str | None, score: dict[str, Any] | None, end: dict[str, Any] | None = None
) -> str:
    """A map as a .json map file holds it (:func:`write_map`): vectors in mm to 0.1 mm, the world,
    the score and the end pose; the same map gives the same text, byte for byte."""
    doc: dict[str, Any] = {
        "units": "mm",
        "world": world,
        "vectors": np.round(vectors, 1).tolist(),
        "score": score,
    }
    if end is not None:
        doc["end_pose"] = end
    return json.dumps(doc, indent=1) + "\n"


def write_dxf(vectors: np.ndarray, path: str | Path, truth: np.ndarray | None) -> None:
    import logging

    import ezdxf

    logging.getLogger("ezdxf").setLevel(logging.WARNING)  # its INFO lines say what it builds, not news

    doc = ezdxf.new("R2010", units=ezdxf.units.MM)
    doc.layers.add("MAP", color=1)
    msp = doc.modelspace()
    for x1, y1, x2, y2 in vectors:
        msp.add_line((x1, y1), (x2, y2), dxfattribs={"layer": "MAP"})
    if truth is not None:
        doc.layers.add("TRUTH", color=8)
        for x1, y1, x2, y2 in truth:
            msp.add_line((x1, y1), (x2, y2), dxfattribs={"layer": "TRUTH"})
    doc.saveas(path)


def write_png(
    vectors: np.ndarray,
    path: str | Path,
    truth: np.ndarray | None,
    title: str,
    score: dict[str, Any] | None,
    paths: dict[str, np.ndarray] | None = None,
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 7), dpi=110)
    if truth is not None and len(truth):
        for x1, y1, x2, y2 in truth:
            ax.plot(
                [x1 / 1000, x2 / 1000],
                [y1 / 1000, y2 / 1000],
                color="0.75",
                lw=4,
                solid_capstyle="round",
                zorder=1,
            )
    for (name, xy), color in zip((paths or {}).items(), ("0.3", "tab:blue", "tab:green"), strict=False):
        if len(xy):
            ax.plot(xy[:, 0] / 1000, xy[:, 1] / 1000, color=color, lw=0.6, zorder=1.5, label=f"path: {name}")
    for x1, y1, x2, y2 in vectors:
        ax.plot([x1 / 1000, x2 / 1000], [y1 / 1000, y2 / 1000], color="tab:red", lw=1.8, zorder=2)
    if len(vectors):
        ends = np.vstack([vectors[:, :2], vectors[:, 2:]]) / 1000
        ax.plot(ends[:, 0], ends[:, 1], "o", color="tab:red", ms=2.5, zorder=3)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True, color="0.92", lw=0.6)
    everything = [a for a in (vectors, truth) if a is not None and len(a)]
    if everything:
        pts = np.vstack([np.vstack([a[:, :2], a[:, 2:]]) for a in everything]) / 1000
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        pad = max(0.3, 0.05 * float((hi - lo).max()))
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad - 0.3, hi[1] + pad)
        x0, y0 = lo[0], lo[1] - pad - 0.15
        ax.plot([x0, x0 + 1.0], [y0, y0], color="black", lw=3)  # the 1 m scale bar
        ax.text(x0 + 0.5, y0 + 0.05, "1 m", ha="center", va="bottom", fontsize=9)
    heading = f"{title}: {len(vectors)} vectors"
    if score is not None:
        heading += (
            f"\ncoverage {score['coverage']:.0%}, precision {score['precision']:.0%}, "
            f"orientation error {score['orientation_error_deg'] or 0:.1f}°, "
            f"corners {score['corners_closed']}/{score['corners_total']}"
        )
    ax.set_title(heading, fontsize=10)
    if truth is not None:
        ax.plot([], [], color="0.75", lw=4, label="true walls")
    ax.plot([], [], color="tab:red", lw=1.8, label="mapped vectors")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    try:
        fig.savefig(path, format="png")  # the format said: a temporary file's name has no .png
    finally:
        plt.close(fig)
