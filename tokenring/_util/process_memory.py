"""A process's memory as Linux counts it: RSS (resident, shared pages counted in full) and USS
(unique: the pages only this process holds, what stopping it would give back).

A ring of N node processes shares the interpreter's and Zenoh's code pages, so N x RSS
overstates what the ring needs; N x USS plus one RSS is closer. Read from
``/proc/PID/smaps_rollup`` (Linux 4.14+), else ``/proc/PID/status`` (RSS only).
"""

from __future__ import annotations

import sys
from pathlib import Path

#: modules a node's runtime does not need (issue 23): numeric and plotting libraries, package
#: metadata, asyncio, the robot's code and the ring's other verbs; a node whose program needs
#: one imports it then
HEAVY_MODULES = (
    "numpy",
    "scipy",
    "matplotlib",
    "ezdxf",
    "PIL",
    "importlib.metadata",
    "asyncio",
    "modules",
    "tokenring.host",
    "tokenring.observe",
    "tokenring.chaos",
    "tokenring.perf",
    "tokenring.web",
)


def memory_kb(pid: int | str = "self") -> dict[str, int]:
    """``{"rss_kb", "uss_kb"}`` of process ``pid`` (-1 for a figure that cannot be read)."""
    rss = uss = -1
    try:
        for line in Path(f"/proc/{pid}/smaps_rollup").read_text().splitlines():
            name, _, rest = line.partition(":")
            if name == "Rss":
                rss = int(rest.split()[0])
            elif name in ("Private_Clean", "Private_Dirty"):
                uss = max(uss, 0) + int(rest.split()[0])
    except (OSError, ValueError, IndexError):
        try:
            for line in Path(f"/proc/{pid}/status").read_text().splitlines():
                if line.startswith("VmRSS:"):
                    rss = int(line.split()[1])
        except (OSError, ValueError, IndexError):
            pass
    return {"rss_kb": rss, "uss_kb": uss}


def heavy_modules() -> list[str]:
    """Which of :data:`HEAVY_MODULES` (or their submodules) this process has imported."""
    loaded = set(sys.modules)
    return [name for name in HEAVY_MODULES if name in loaded or any(m.startswith(name + ".") for m in loaded)]


def memory_report() -> dict[str, object]:
    """This process's memory and imports (a node's ``memory`` control verb): RSS, USS, how many
    modules, the heavy ones among them, and every module's name."""
    modules = sorted(sys.modules)
    return {**memory_kb(), "modules_count": len(modules), "heavy": heavy_modules(), "modules": modules}
