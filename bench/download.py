"""Download throughput: all eight programs of ``modules/`` through the token, against the seed's 3-4 minutes.

``python -m bench.download [--bitrates 2.5M,max] [--repeat 1] [--json FILE]``

For each bitrate a bare ring of the eight nodes is launched (no world, no programs), then every
program is sent with ``load -a`` semantics, once raw (the seed's way: the file as it is) and once
zlib-compressed (ours), timed per program from the PC's request to the installed program. The
same run measures the ring's round trip, so the result is also given as a ratio to the ideal
pace of one 30-byte chunk per round. The seed (2.5 Mbit/s ARCNET, 8051s at 16 MHz, a 9600-baud
serial line to the PC) needed 3-4 minutes for all programs and 20-40 s for two or three.
"""

from __future__ import annotations

import argparse
import io
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

SEED_ALL_S = (180.0, 240.0)
CHUNK_BYTES = 30


def run_bitrate(bitrate: str, repeat: int, store: Path) -> dict[str, Any]:
    from modules.plugin import PROGRAMS_DIR
    from tokenring import default_protocol, keys
    from tokenring.host import Launcher, Loader, open_link, plans_from_protocol
    from tokenring.transport import free_port, query

    protocol = default_protocol()
    ring = f"dl{int(time.time() * 1000) % 10**8}"
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    launcher = Launcher(
        plans_from_protocol(protocol, None, None),
        ring=ring,
        bitrate=bitrate,
        listen=[endpoint],
        log_level="warning",
        output=io.StringIO(),
        extra_node_args=["--store", str(store)],
    )
    launcher.start()
    try:
        assert launcher.session is not None
        link = open_link(launcher.session, ring, wait=30.0)
        loader = Loader(link, progress=False, say=lambda _: None, poll_s=0.02)
        ids = {n.id for n in protocol.default_nodes}
        nodes = loader.scan(ids, wait=30.0)
        if {n["id"] for n in nodes} != ids:
            raise SystemExit(f"{bitrate}: only {sorted(n['id'] for n in nodes)} answered the scan")
        items = loader.plan(nodes, "all", PROGRAMS_DIR)
        runs: dict[str, list[dict[str, Any]]] = {"raw": [], "zlib": []}
        for _ in range(repeat):
            for mode in ("raw", "zlib"):
                loader.compress = mode == "zlib"
                per_program = []
                t0 = time.monotonic()
                for item in items:
                    outcome = loader.download(item, start=False)
                    if not outcome.ok:
                        raise SystemExit(f"{bitrate} {mode}: {item.node['name']}: {outcome.error}")
                    per_program.append(
                        {
                            "name": item.node["name"],
                            "source_bytes": len(item.source),
                            "wire_bytes": outcome.bytes,
                            "chunks": outcome.chunks,
                            "seconds": outcome.seconds,
                            "rounds": outcome.extra.get("rounds", 0),
                        }
                    )
                runs[mode].append({"seconds": time.monotonic() - t0, "programs": per_program})
        main_stats = query(launcher.session, keys.control(ring, 10, "stats"))[0][1]["result"]
        round_ms = main_stats["round_ms"]
    finally:
        launcher.stop()
    source = sum(len(i.source) for i in items)
    out: dict[str, Any] = {"bitrate": bitrate, "source_bytes": source, "round_ms": round_ms}
    for mode, series in runs.items():
        seconds = [r["seconds"] for r in series]
        chunks = sum(p["chunks"] for p in series[0]["programs"])
        wire = sum(p["wire_bytes"] for p in series[0]["programs"])
        median = float(np.median(seconds))
        ideal = chunks * round_ms["median"] / 1000.0
        rounds = sum(p["rounds"] for p in series[0]["programs"])
        busy = sum(p["seconds"] for p in series[0]["programs"])
        out[mode] = {
            "seconds_median": median,
            "seconds_all": seconds,
            "chunks": chunks,
            "wire_bytes": wire,
            "source_bytes_per_s": source / median,
            "wire_bytes_per_s": wire / median,
            "ideal_s": ideal,
            "vs_ideal": median / ideal if ideal else None,
            "rounds": rounds,
            "rounds_per_chunk": rounds / chunks if chunks else None,
            "ms_per_round_downloading": 1000.0 * busy / rounds if rounds else None,
            "vs_seed": [s / median for s in SEED_ALL_S],
            "programs": series[0]["programs"],
        }
    return out


def main(argv: list[str] | None = None) -> int:
    from tokenring import parse_bitrate
    from tokenring.cli import format_table, write_json

    parser = argparse.ArgumentParser(prog="python -m bench.download", description=__doc__.split("\n\n")[0])
    parser.add_argument("--bitrates", default="2.5M,max", help="comma-separated (default %(default)s)")
    parser.add_argument("--repeat", type=int, default=1, help="runs per bitrate and mode (default 1)")
    parser.add_argument("--json", metavar="FILE", help="write the results as JSON ('-' for stdout)")
    args = parser.parse_args(argv)
    bitrates = [b.strip() for b in args.bitrates.split(",") if b.strip()]
    for b in bitrates:
        parse_bitrate(b)
    results = []
    with tempfile.TemporaryDirectory(prefix="tokenring-bench-store-") as store:
        for bitrate in bitrates:
            print(f"bitrate {bitrate}: launching eight bare nodes, sending all programs ...", file=sys.stderr)
            results.append(run_bitrate(bitrate, args.repeat, Path(store)))
    rows = []
    for r in results:
        for mode in ("raw", "zlib"):
            m = r[mode]
            rows.append(
                [
                    r["bitrate"],
                    mode,
                    r["source_bytes"],
                    m["wire_bytes"],
                    m["chunks"],
                    f"{m['rounds_per_chunk']:.3f}",
                    f"{r['round_ms']['median']:.2f}",
                    f"{m['ms_per_round_downloading']:.2f}",
                    f"{m['seconds_median']:.1f}",
                    f"{m['source_bytes_per_s']:.0f}",
                    f"{m['vs_ideal']:.2f}x",
                    f"{m['vs_seed'][0]:.0f}-{m['vs_seed'][1]:.0f}x",
                ]
            )
    print("all eight programs of modules/ through the token (one 30-byte chunk per round)")
    print(
        format_table(
            rows,
            [
                "bitrate",
                "mode",
                "source B",
                "wire B",
                "chunks",
                "rounds/chunk",
                "round ms idle",
                "ms/round loading",
                "seconds",
                "B/s",
                "vs ideal",
                "faster than seed",
            ],
        )
    )
    print(
        f"seed: {SEED_ALL_S[0]:.0f}-{SEED_ALL_S[1]:.0f} s for all programs; ideal = chunks x idle median round; "
        "ms/round loading = time per token round while programs travel (incl. the PC's polls)"
    )
    if args.json:
        write_json(args.json, results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
