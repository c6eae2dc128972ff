"""bench/RESULTS.md and its PNG plots, generated from one suite run (``bench/results/<date>.json``).

The tables come from the run's summary alone (the committed ``<date>.json``); the plots of
figures in the summary are drawn from it too, and those of per-round samples (the profile's
histogram) from the run's raw record, ``bench/results/raw/<date>.json``, which only the machine
that ran the suite has: without it (a fresh clone regenerating the report) the existing plot is
kept, and the report says so on stderr.

Sections the run did not include are filled from the latest earlier result file that has them,
and say so with that file's date; the Nemesis, seed and robot sections come from their own
result files (``nemesis-*.json``, ``seedmode-*.json``, ``darmstadt-*.json``, ``localization-*.json``,
``mapping-*.json``). RESULTS.md is a reference, all of it generated: nothing of the file it
replaces is kept, so never edit it by hand. Its first lines name the command that wrote it
again from the same result file (``python -m bench.report FILE``, running nothing) and the one
that measures it all again (``python -m bench``).
"""

from __future__ import annotations

import argparse
import io
import json
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np

from bench.ownshare import pairs_for
from bench.sections import SECTIONS, has_samples, raw_path, summary_section
from tokenring.perf import ROUTER_FROM

#: how many bare/ring pairs the suite runs per size, as the scaling table's text says it
PAIRS_TEXT = f"{pairs_for(64, False)} up to 64 nodes, {pairs_for(65, False)} beyond"

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
REPRODUCE = "python -m bench"


def md_table(rows: list[list[Any]], head: list[str]) -> str:
    """A Markdown table; a short row (e.g. a run that failed) is padded with empty cells."""
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    lines += [
        "| " + " | ".join(str(c) for c in [*row, *[""] * (len(head) - len(row))]) + " |" for row in rows
    ]
    return "\n".join(lines)


def f(value: Any, digits: int = 2) -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "-"
    return f"{value:.{digits}f}"


def verdict(ok: bool | None) -> str:
    return "-" if ok is None else ("**met**" if ok else "**missed**")


def previous_section(name: str, out_dir: Path, current: Path | None) -> tuple[dict[str, Any], str] | None:
    """The latest earlier run's ``name`` section (or bench/recovery.py's own file) and its date.

    Latest by the date the run recorded, not by the file's time: a checkout gives every result
    file the same mtime, and the report would take an older run's figures at random."""
    found = previous_run(name, out_dir, current)
    return None if found is None else found[:2]


def previous_run(name: str, out_dir: Path, current: Path | None) -> tuple[dict[str, Any], str, Path] | None:
    """``previous_section`` and the file it comes from."""
    found: list[tuple[str, float, dict[str, Any], str, Path]] = []
    for path in out_dir.glob("*.json"):
        if current is not None and path.resolve() == current.resolve():
            continue
        try:
            data = json.loads(path.read_text())
        except (OSError, ValueError):
            continue
        if not isinstance(data, dict):
            continue
        order = (str(data.get("date", "")), path.stat().st_mtime)
        if name in data.get("sections", {}):
            found.append((*order, data["sections"][name], f"{data['date']} ({path.name})", path))
        elif (
            name == "recovery"
            and data.get("benchmark") == "recovery"
            and data.get("topology", "peers") == "peers"
        ):
            found.append((*order, data, f"{data['date']} ({path.name}, `python -m bench.recovery`)", path))
    if not found:
        return None
    _, _, section, source, path = max(found, key=lambda item: item[:2])
    return section, source, path


def raw_section(name: str, path: Path | None, section: dict[str, Any]) -> dict[str, Any] | None:
    """Section ``name`` with its samples: ``section`` itself if it has them (an older result
    file, written before summaries), else from the raw record beside ``path``; None if neither."""
    if has_samples(name, section):
        return section
    if path is None:
        return None
    try:
        data = json.loads(raw_path(path).read_text())
    except (OSError, ValueError):
        return None
    found = data.get("sections", {}).get(name) if isinstance(data, dict) else None
    return found if has_samples(name, found) else None


# ---------------------------------------------------------------------------------------------
# plots


def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_png(fig: Any, path: Path) -> None:
    """``fig`` as a PNG of 256 colours (a third of the full-colour file's size, the same to the
    eye: the plots are a few flat colours on white) and close it."""
    from PIL import Image

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    _plt().close(fig)
    buffer.seek(0)
    with Image.open(buffer) as image:
        image.convert("RGB").quantize(256, method=Image.Quantize.MEDIANCUT).save(path, optimize=True)


#: how the report names a topology of the scaling section
TOPOLOGY_NAMES = {"peer": "peers", "router": "routers", "links": "direct links"}


def plural(topology: str) -> str:
    """``peers``, ``routers``, ``direct links``: a topology as the report's sentences name it."""
    return TOPOLOGY_NAMES.get(topology, f"{topology}s")


def plot_scaling(runs: list[dict[str, Any]], path: Path) -> None:
    plt = _plt()
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.5))
    styles = {"peer": ("tab:blue", "o"), "router": ("tab:red", "s"), "links": ("tab:green", "^")}
    for topology, (color, marker) in styles.items():
        good = [r for r in runs if r["topology"] == topology and "rtt_ms" in r]
        bare = [r for r in runs if r["topology"] == topology and "bare_rtt_ms" in r]
        if good:
            n = [r["nodes"] for r in good]
            ax1.plot(
                n,
                [r["rtt_ms"]["median"] for r in good],
                marker=marker,
                color=color,
                label=f"tokenring, {plural(topology)}",
            )
            ax1.plot(
                n,
                [r["rtt_ms"]["p99"] for r in good],
                marker=marker,
                color=color,
                ls=":",
                alpha=0.6,
                label=f"p99, {plural(topology)}",
            )
            ax2.plot(
                n,
                [r["per_hop_us"] for r in good],
                marker=marker,
                color=color,
                label=f"tokenring, {plural(topology)}",
            )
        if bare:
            n = [r["nodes"] for r in bare]
            ax1.plot(
                n,
                [r["bare_rtt_ms"]["median"] for r in bare],
                marker=marker,
                color=color,
                ls="--",
                mfc="none",
                label=f"bare Zenoh, {plural(topology)}",
            )
            ax2.plot(
                n,
                [r["bare_rtt_ms"]["median"] * 1e3 / r["nodes"] for r in bare],
                marker=marker,
                color=color,
                ls="--",
                mfc="none",
                label=f"bare Zenoh, {plural(topology)}",
            )
    ax1.axhline(BIG_RING_P99_AIM_MS, color="grey", lw=0.8, ls="-.")
    ax1.text(
        2.1,
        BIG_RING_P99_AIM_MS * 1.1,
        f"aim: p99 ≤ {BIG_RING_P99_AIM_MS:.0f} ms at 255",
        fontsize=8,
        color="grey",
    )
    for ax in (ax1, ax2):
        ax.set_xscale("log", base=2)
        ax.set_xlabel("nodes in the ring")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    ax1.set_yscale("log")
    ax1.set_ylabel("token round trip (ms)")
    ax1.set_title("round trip vs ring size (bitrate max)")
    ax2.set_ylabel("median round trip / N (µs per hop)")
    ax2.set_title("per-hop cost")
    fig.tight_layout()
    save_png(fig, path)


def plot_resources(runs: list[dict[str, Any]], path: Path) -> None:
    plt = _plt()
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4))
    for topology, color in (("peer", "tab:blue"), ("router", "tab:red"), ("links", "tab:green")):
        good = [r for r in runs if r["topology"] == topology and "rtt_ms" in r]
        if not good:
            continue
        n = [r["nodes"] for r in good]
        ax1.plot(
            n,
            [r["rss_mb"]["mean"] for r in good],
            "o-",
            color=color,
            label=f"RSS per node, {plural(topology)}",
        )
        ax2.plot(
            n,
            [r["cpu_all_nodes_pct"] for r in good],
            "o-",
            color=color,
            label=f"all nodes, {plural(topology)}",
        )
        ax2.plot(
            n,
            [r["launcher_cpu_pct"] for r in good],
            "x--",
            color=color,
            label=f"launcher (router), {plural(topology)}",
        )
    ax1.set_ylabel("MB")
    ax2.set_ylabel("% of one core")
    ax2.axhline(200, color="grey", lw=0.8)
    ax2.text(2.1, 205, "the machine: 2 cores", fontsize=8, color="grey")
    for ax in (ax1, ax2):
        ax.set_xscale("log", base=2)
        ax.set_xlabel("nodes")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    ax1.set_title("memory per node process")
    ax2.set_title("CPU while circulating at bitrate max")
    fig.tight_layout()
    save_png(fig, path)


def plot_transports(runs: list[dict[str, Any]], path: Path) -> None:
    plt = _plt()
    good = [r for r in runs if "rtt_ms" in r]
    sizes = sorted({r["nodes"] for r in good})
    fig, axes = plt.subplots(1, len(sizes), figsize=(5.5 * len(sizes), 4), squeeze=False)
    for ax, n in zip(axes[0], sizes, strict=True):
        rows = [r for r in good if r["nodes"] == n]
        labels = [label_transport(r) for r in rows]
        med = [r["rtt_ms"]["median"] for r in rows]
        p99 = [r["rtt_ms"]["p99"] for r in rows]
        x = np.arange(len(rows))
        ax.bar(x - 0.2, med, 0.4, label="median")
        ax.bar(x + 0.2, p99, 0.4, label="p99", alpha=0.6)
        ax.axhline(
            rows[0]["bare_rtt_ms"]["median"], color="k", ls="--", lw=1, label="bare Zenoh ring (median)"
        )
        ax.set_xticks(x, labels, fontsize=8)
        ax.set_ylabel("round trip (ms)")
        ax.set_title(f"{n} nodes, bitrate max")
        ax.legend(fontsize=8)
        ax.grid(True, axis="y", alpha=0.3)
    fig.tight_layout()
    save_png(fig, path)


def plot_profile(section: dict[str, Any], path: Path) -> None:
    """The round trips' histogram: ``section`` is the raw record's (with ``rounds_s``)."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 4))
    lo, hi = section["seed_ms"]
    ax.axvspan(lo, hi, color="tab:green", alpha=0.15, label=f"seed: {lo:.0f}-{hi:.0f} ms (7 computers)")
    for run, color in zip(section["runs"], ("tab:grey", "tab:blue"), strict=False):
        values = np.array(run["rounds_s"]) * 1e3
        ax.hist(
            values,
            bins=40,
            range=(10, 50),
            alpha=0.6,
            color=color,
            label=f"{run['label']}: median {np.median(values):.1f} ms",
        )
    ax.set_xlabel("token round trip (ms)")
    ax.set_ylabel("rounds")
    ax.set_title("--profile arcnet, the seed's seven computers at 2.5 Mbit/s")
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_png(fig, path)


def label_transport(r: dict[str, Any]) -> str:
    return f"{r['transport']} ({plural(r['topology'])})" if r["transport"] == "zenoh" else r["transport"]


# ---------------------------------------------------------------------------------------------
# sections


def pick(runs: list[dict[str, Any]], topology: str, n: int) -> dict[str, Any] | None:
    return next((r for r in runs if r["topology"] == topology and r["nodes"] == n and "rtt_ms" in r), None)


def defaults_note(runtime: dict[str, Any], n: int, topology: str) -> str:
    """The runtime section's pair on Zenoh's default runtime, for the same size: the ratio moves
    with the baseline, which that runtime slows more than tokenring's own work."""
    for r in runtime.get("runs", []):
        if (r["nodes"], r["topology"], r["runtime"]) == (n, topology, "zenoh defaults") and "ratio" in r:
            return (
                f"; both rings on Zenoh's default runtime: {r['ratio']:.2f}× "
                f"({f(r['rtt_ms']['median'], 3)} vs {f(r['bare_rtt_ms']['median'], 3)} ms, both slower)"
            )
    return ""


def defaults_growth_note(runtime: dict[str, Any], topology: str) -> str:
    """Per-hop growth from 8 to 64 nodes with both rings on Zenoh's default runtime, if the
    runtime section measured both sizes in this topology."""
    found = {
        r["nodes"]: r
        for r in runtime.get("runs", [])
        if r["topology"] == topology and r["runtime"] == "zenoh defaults" and "per_hop_us" in r
    }
    if 8 not in found or 64 not in found:
        return ""
    a, b = found[8]["per_hop_us"], found[64]["per_hop_us"]
    return (
        f"; both rings on Zenoh's default runtime: {b['ring'] / a['ring']:.2f}× "
        f"({a['ring']:.0f} → {b['ring']:.0f} µs; bare {b['baseline'] / a['baseline']:.2f}×)"
    )


#: issue 23: a 255-node ring's p99 round trip on the 2-core machine (issue 8's aim was 100 ms)
BIG_RING_P99_AIM_MS = 80.0


def steal_note(r: dict[str, Any]) -> str:
    """What the host's steal time did to a size's pairs: how many were within the limit and the
    own share over every pair taken (empty for a run from before steal was recorded)."""
    from bench.ownshare import screened_pairs
    from tokenring.perf import describe

    screened = screened_pairs(r)
    if not screened:
        return ""
    calm, taken, limit = screened
    worst = max(max(pair) for pair in r["pair_steal_pct"])
    if calm == taken:
        return f"; all {taken} pairs within {limit:.0f} % steal time (worst {worst:.1f} %)"
    return (
        f"; {calm} of {taken} pairs within {limit:.0f} % steal time (worst {worst:.1f} %), "
        f"over all {taken}: {describe(r['own_share_all_us'])}"
    )


def interleaved_note(interleaved: dict[str, Any]) -> str:
    """The own share from interleaved windows (both rings up at once, taking turns): over the
    pairs within the steal limit, and over every pair."""
    from tokenring.perf import describe

    return (
        f"{describe(interleaved['own_share_us'])}, both rings up at once taking turns in "
        f"{interleaved['window_s']:.1f} s windows ({interleaved['own_share_us']['n']} of "
        f"{interleaved['pairs']} pairs within {interleaved['steal_limit_pct']:.0f} % steal; every pair: "
        f"{describe(interleaved['own_share_all_us'])})"
    )


def calm_tail_note(r: dict[str, Any]) -> str:
    """The p99 over the interleaved windows within the steal limit, ring / bare, where a size
    has them: what the tail is when the host does not take the CPUs (the aim is judged on the
    whole run's p99)."""
    calm = (r.get("interleaved") or {}).get("calm_p99_ms") or {}
    if calm.get("ring") is None or calm.get("bare") is None:
        return ""
    return (
        f"; in the interleaved windows within {r['interleaved']['steal_limit_pct']:.0f} % steal: "
        f"{f(calm['ring'], 1)} / {f(calm['bare'], 1)} ms"
    )


def own_share_aims(runs: list[dict[str, Any]]) -> list[list[Any]]:
    """Rows for tokenring's own share per hop (its 95 % interval's top against the aim) and for
    the outside tap's round trip against the ring's own, per ring size that measured them."""
    from bench.ownshare import OWN_SHARE_AIM_US
    from tokenring.perf import describe

    rows: list[list[Any]] = []
    for r in runs:
        share = r.get("own_share_us")
        interleaved = r.get("interleaved")
        if interleaved and r["nodes"] in (8, 64, 255):
            calm = interleaved["own_share_us"]
            rows.append(
                [
                    f"tokenring's own share per hop, {r['nodes']} nodes ({plural(r['topology'])})",
                    f"≤ {OWN_SHARE_AIM_US:.0f} µs (top of the 95 % interval)",
                    interleaved_note(interleaved)
                    + (f"; separate runs: {describe(share)}" + steal_note(r) if share else ""),
                    verdict(calm["n"] >= 2 and calm["hi"] <= OWN_SHARE_AIM_US),
                ]
            )
        elif share and r["nodes"] in (8, 64, 255):
            load = r.get("load_before", [float("nan")])[0]
            rows.append(
                [
                    f"tokenring's own share per hop, {r['nodes']} nodes ({plural(r['topology'])})",
                    f"≤ {OWN_SHARE_AIM_US:.0f} µs (top of the 95 % interval)",
                    f"{describe(share)}; load {load:.1f}" + steal_note(r),
                    verdict(bool(share["met"])),
                ]
            )
        tap = r.get("tap")
        if tap:
            rows.append(
                [
                    f"outside tap vs the ring's own round trip, {r['nodes']} nodes ({plural(r['topology'])})",
                    f"within {tap['aim_pct']:.0f} %",
                    f"{tap['difference_pct']:+.1f} % ({f(tap['tap_rtt_ms']['median'], 3)} vs "
                    f"{f(tap['ring_rtt_ms']['median'], 3)} ms)",
                    verdict(abs(tap["difference_pct"]) <= tap["aim_pct"]),
                ]
            )
    return rows


def aims(sections: dict[str, Any]) -> str:
    rows: list[list[Any]] = []
    runs = sections.get("scaling", {}).get("runs", [])
    r8 = pick(runs, "peer", 8)
    if r8 and "ratio_median" in r8:
        rows.append(
            [
                "8-node round trip vs bare Zenoh ring (peers, same run)",
                "≤ 1.2×",
                f"{r8['ratio_median']:.2f}× ({f(r8['rtt_ms']['median'], 3)} vs {f(r8['bare_rtt_ms']['median'], 3)} ms"
                + (
                    f"; {len(r8['pair_ratios'])} alternating pairs pooled, each "
                    + ", ".join(f"{x:.2f}×" for x in r8["pair_ratios"])
                    if len(r8.get("pair_ratios", [])) > 1
                    else ""
                )
                + ")"
                + defaults_note(sections.get("runtime", {}), 8, "peer"),
                verdict(r8["ratio_median"] <= 1.2),
            ]
        )
    for topology in ("peer", "router"):
        a, b = pick(runs, topology, 8), pick(runs, topology, 64)
        if a and b:
            growth = b["per_hop_us"] / a["per_hop_us"]
            measured = f"{growth:.2f}× ({a['per_hop_us']:.0f} → {b['per_hop_us']:.0f} µs)"
            if "bare_rtt_ms" in a and "bare_rtt_ms" in b:
                # the same run's bare ring: how much of the growth is Zenoh's and the machine's
                bare_a = a["bare_rtt_ms"]["median"] * 1e3 / a["nodes"]
                bare_b = b["bare_rtt_ms"]["median"] * 1e3 / b["nodes"]
                measured += (
                    f"; bare Zenoh {bare_b / bare_a:.2f}× ({bare_a:.0f} → {bare_b:.0f} µs); "
                    f"tokenring's own share {a['per_hop_us'] - bare_a:.0f} → {b['per_hop_us'] - bare_b:.0f} µs"
                )
            measured += defaults_growth_note(sections.get("runtime", {}), topology)
            rows.append(
                [
                    f"per-hop cost flat from 8 to 64 nodes ({plural(topology)})",
                    "within 1.5×",
                    measured,
                    verdict(growth <= 1.5),
                ]
            )
    rows += own_share_aims(runs)
    biggest = max((r["nodes"] for r in runs if "rtt_ms" in r), default=0)
    for big in (r for r in runs if "rtt_ms" in r and r["nodes"] == biggest and biggest >= 128):
        rows.append(
            [
                f"{big['nodes']} nodes circulate, p99 round trip ({plural(big['topology'])})",
                f"≤ {BIG_RING_P99_AIM_MS:.0f} ms",
                f"{f(big['rtt_ms']['p99'], 1)} ms (median {f(big['rtt_ms']['median'], 1)})"
                + (
                    f"; bare Zenoh ring p99 {f(big['bare_rtt_ms']['p99'], 1)} (median {f(big['bare_rtt_ms']['median'], 1)})"
                    if "bare_rtt_ms" in big
                    else ""
                )
                + calm_tail_note(big),
                verdict(big["rtt_ms"]["p99"] <= BIG_RING_P99_AIM_MS and big["nodes"] == 255),
            ]
        )
    prof = sections.get("profile")
    if prof and prof.get("runs"):
        busy = prof["runs"][-1]
        lo, hi = prof["seed_ms"]
        med = busy["rtt_ms"]["median"]
        rows.append(
            [
                "--profile arcnet, 7 nodes with programs",
                f"seed {lo:.0f}-{hi:.0f} ms",
                f"median {f(med, 1)} ms (p10-p90 {f(busy['rounds_ms']['p10'], 1)}-{f(busy['rtt_ms']['p90'], 1)})",
                verdict(lo <= med <= hi),
            ]
        )
    rec = sections.get("recovery")
    for run, where in ((rec, ""), ((rec or {}).get("links"), ", direct links")):
        for kind, s in (run or {}).get("summary", {}).items():
            if s.get("aim_ms") and s.get("median_ms") is not None:
                rows.append(
                    [
                        f"recovery after {kind} (median, 8 nodes{where})",
                        f"< {s['aim_ms']:.0f} ms",
                        f"{s['median_ms']:.1f} ms",
                        verdict(s["median_ms"] < s["aim_ms"]),
                    ]
                )
    rows += spurious_aim(sections.get("spurious"))
    if not rows:
        return ""
    return "## Aims\n\n" + md_table(rows, ["aim", "target", "measured", ""]) + "\n"


def pairs_text(runs: list[dict[str, Any]]) -> str:
    """How many bare/ring pairs the sizes had: the suite's default, or what ``--pairs`` set."""
    counted = [r for r in runs if "pairs" in r]
    if all(r["pairs"] == pairs_for(r["nodes"], False) for r in counted):
        return PAIRS_TEXT
    counts = {r["pairs"] for r in counted}
    if len(counts) == 1:
        return f"{counts.pop()} for every size"
    return ", ".join(f"{r['pairs']} at {r['nodes']} {plural(r['topology'])}" for r in counted)


def scaling_md(section: dict[str, Any], plots: Path) -> str:
    runs = section["runs"]
    rows = []
    for r in runs:
        if "rtt_ms" not in r:
            rows.append(
                [
                    r["topology"],
                    r["nodes"],
                    f(r.get("bare_rtt_ms", {}).get("median"), 3),
                    "failed: " + r.get("error", "?")[:60],
                ]
            )
            continue
        bare = r.get("bare_rtt_ms", {})
        rows.append(
            [
                r["topology"],
                r["nodes"],
                f(bare.get("median"), 3),
                f(r["rtt_ms"]["median"], 3),
                f(r["rtt_ms"]["p90"], 3),
                f(r["rtt_ms"]["p99"], 3),
                f(r["rtt_ms"]["max"], 2),
                f(r.get("ratio_median")) + "×",
                f(r["per_hop_us"], 0),
                f(bare.get("median", np.nan) * 1e3 / r["nodes"], 0),
                f(r["handler_us"]["median"], 0),
                f(r["rss_mb"]["mean"], 0),
                f(r["cpu_per_node_pct"], 1),
                f(r["launcher_cpu_pct"], 0),
                f(r["form_s"], 1),
                "/".join(f(x, 1) for x in r.get("load_after", [])[:1]),
            ]
        )
    head = [
        "topology",
        "N",
        "bare median ms",
        "median ms",
        "p90",
        "p99",
        "max",
        "ratio",
        "µs/hop",
        "bare µs/hop",
        "handler µs",
        "RSS MB/node",
        "CPU %/node",
        "launcher CPU %",
        "forms in s",
        "load",
    ]
    rows = [row + [""] * (len(head) - len(row)) for row in rows]
    text = [
        "## Round trip vs ring size",
        "",
        "Bitrate max, adaptive acks; every tokenring ring against a bare Zenoh ring (N processes forwarding 514 bytes, no OS work) of the same size and topology, measured right before it. *peers*: a full mesh of Zenoh peers (the default of `tokenring up`); *routers*: every node a client of the launcher's Zenoh router (`tokenring up --router`); *links*: the router for everything but the token, whose every pass goes on a direct link to the successor (`tokenring up --router --links`). The round trip is timed by the round master (the lowest ID); `handler` is the median time a node holds the token, from its arrival to the put that passes it on (the visit's bookkeeping runs after the put); CPU is per node while circulating, `launcher` is the launcher process with the router in it; `load` is the 1-minute load average after the run (the machine is shared). Each size is measured as alternating bare/ring pairs ("
        + pairs_text(runs)
        + "), pooled; the aims table gives the own share per hop as the mean over pairs with its 95 % interval.",
        "",
    ]
    text.append(md_table(rows, head))
    for r in section["runs"]:
        for kind, errors in r.get("failed_pairs", {}).items():
            for error in errors:
                text.append(
                    f"\n{r['topology']} {r['nodes']}: a {kind} run failed and is not pooled: {error[:120]}"
                )
    text += [
        "",
        f"![round trip and per-hop cost vs N]({plots}/scaling.png)",
        "",
        f"![memory and CPU vs N]({plots}/resources.png)",
        "",
    ]
    fits = section.get("fits", {})
    for topology, fit in fits.items():
        text.append(
            f"* **{plural(topology)}** ({', '.join(map(str, fit['sizes']))} nodes): round trip ≈ {fit['rtt_ms_intercept']:.2f} ms + "
            f"{fit['rtt_ms_per_node'] * 1e3:.0f} µs × N (R² {fit['r2']:.3f}); as a power law N^{fit['power_law_exponent']:.2f}; "
            f"RSS {fit['rss_mb_per_node']:.0f} MB per node process, so memory grows linearly (255 nodes ≈ {fit['rss_mb_per_node'] * 255 / 1024:.1f} GB)."
        )
    text.append("")
    text.append(topology_choice(runs))
    return "\n".join(text) + "\n"


def topology_choice(runs: list[dict[str, Any]]) -> str:
    both = sorted(
        {r["nodes"] for r in runs if r["topology"] == "peer" and "rtt_ms" in r}
        & {r["nodes"] for r in runs if r["topology"] == "router" and "rtt_ms" in r}
    )
    lines = [
        "**Topology.** Peers reach each other directly (one TCP hop per pass) but every pair keeps a link: N(N−1)/2 links, each with its own keep-alives, and N sessions gossiping. Through a router every pass is two hops (node → router → node) and the router process carries all traffic, but each node keeps one link."
    ]
    for n in both:
        p, r = pick(runs, "peer", n), pick(runs, "router", n)
        assert p is not None and r is not None
        lines.append(
            f"At {n} nodes: peers {f(p['rtt_ms']['median'], 2)} ms (p99 {f(p['rtt_ms']['p99'], 2)}), router {f(r['rtt_ms']['median'], 2)} ms (p99 {f(r['rtt_ms']['p99'], 2)}); the ring formed in {f(p['form_s'], 1)} s vs {f(r['form_s'], 1)} s."
        )
    for n in sorted({r["nodes"] for r in runs if r["topology"] == "links" and "rtt_ms" in r}):
        k, r = pick(runs, "links", n), pick(runs, "router", n)
        assert k is not None
        against = (
            f" against {f(r['rtt_ms']['median'], 2)} ms (p99 {f(r['rtt_ms']['p99'], 2)}) through the router"
            if r
            else ""
        )
        lines.append(
            f"On direct links (`--links`: each pass one TCP link to the successor, the router for everything else) {n} nodes took {f(k['rtt_ms']['median'], 2)} ms (p99 {f(k['rtt_ms']['p99'], 2)}){against}."
        )
    lines.append(
        f"So `tokenring up` keeps peers for the robot's eight nodes, and `tokenring bench --topology auto` uses a router from {ROUTER_FROM} nodes on; 255 peers (32 385 links) are not attempted."
    )
    return " ".join(lines) + "\n"


def transports_md(section: dict[str, Any], plots: Path) -> str:
    rows = []
    for r in section["runs"]:
        if "rtt_ms" not in r:
            rows.append(
                [
                    r["nodes"],
                    label_transport(r),
                    "failed: " + r.get("error", "?")[:60],
                ]
            )
            continue
        rows.append(
            [
                r["nodes"],
                label_transport(r),
                f(r["rtt_ms"]["median"], 3),
                f(r["rtt_ms"]["p99"], 3),
                f(r["ratio_to_bare_zenoh"]) + "×",
                f(r["per_hop_us"], 0),
                f(r["handler_us"]["median"], 0),
                f(r["rss_mb"]["mean"], 0),
                f(r["cpu_per_node_pct"], 1),
                f(r["form_s"], 1),
            ]
        )
    text = [
        "## Zenoh against what users would otherwise pick",
        "",
        "The same node OS and ring (acks, recovery, channels) over each backend of the transport boundary (`tokenring/transport/`, python-can style: `tokenring node --transport zenoh|udp|zmq`). `udp`: one datagram per frame on loopback; `zmq`: PUSH/PULL sockets of ZeroMQ; both learn membership from a small TCP registry in the launcher (a closed connection = a crashed node). The ratio is to the bare Zenoh ring (peers) of the same run.",
        "",
        md_table(
            rows,
            [
                "N",
                "transport",
                "median ms",
                "p99 ms",
                "vs bare Zenoh",
                "µs/hop",
                "handler µs",
                "RSS MB/node",
                "CPU %/node",
                "forms in s",
            ],
        ),
        "",
        f"![transports]({plots}/transports.png)",
        "",
        "What Zenoh costs: a Rust runtime per process (threads, memory) and a routing layer on every put, so raw sockets pass the token faster on one host. What it buys: the key space that `sniff`, `monitor`, `status`, `fault` and the world simulator use to reach every node without knowing addresses; liveliness tokens instead of a hand-made registry; routers, so a ring spans hosts (`--router`, across network namespaces in the tests) and scales past a full mesh; TLS and access control from its configuration. The socket backends carry only the token path; their nodes still use Zenoh for the control plane.",
    ]
    return "\n".join(text) + "\n"


def runtime_md(section: dict[str, Any]) -> str:
    rows = []
    by_case: dict[tuple[int, str], dict[str, dict[str, Any]]] = {}
    for r in section["runs"]:
        by_case.setdefault((r["nodes"], r["topology"]), {})[r["runtime"]] = r
        if "rtt_ms" not in r:
            rows.append([r["nodes"], r["topology"], r["runtime"], "failed: " + r.get("error", "?")[:60]])
            continue
        rows.append(
            [
                r["nodes"],
                r["topology"],
                r["runtime"],
                f(r["bare_rtt_ms"]["median"], 3),
                f(r["rtt_ms"]["median"], 3),
                f(r["rtt_ms"]["p99"], 3),
                f(r["ratio"]) + "×",
                f(r["per_hop_us"]["ring"] - r["per_hop_us"]["baseline"], 0),
                f(r["handler_us"]["median"], 0),
                f(r["cpu_per_node_pct"], 1),
            ]
        )
    gains, direct = [], []
    for (n, topology), runs in sorted(by_case.items()):
        ours, zenoh = runs.get("tokenring", {}), runs.get("zenoh defaults", {})
        threaded = runs.get("callback on a Python thread", {})
        if "rtt_ms" in ours and "rtt_ms" in threaded:
            direct.append(
                f"{n} nodes ({plural(topology)}): tokenring {f(threaded['rtt_ms']['median'], 3)} → {f(ours['rtt_ms']['median'], 3)} ms "
                f"({f(ours['rtt_ms']['median'] / threaded['rtt_ms']['median'])}×), the bare ring "
                f"{f(threaded['bare_rtt_ms']['median'], 3)} → {f(ours['bare_rtt_ms']['median'], 3)} ms"
            )
        if "rtt_ms" in ours and "rtt_ms" in zenoh:
            gains.append(
                f"{n} nodes ({plural(topology)}): tokenring {f(zenoh['rtt_ms']['median'], 3)} → {f(ours['rtt_ms']['median'], 3)} ms "
                f"({f(ours['rtt_ms']['median'] / zenoh['rtt_ms']['median'])}×), the bare ring "
                f"{f(zenoh['bare_rtt_ms']['median'], 3)} → {f(ours['bare_rtt_ms']['median'], 3)} ms"
            )
    text = [
        "## Zenoh's runtime: one thread for a node's frames, the callback on it",
        "",
        "Zenoh runs its I/O on async runtimes, by default six threads per process (rx ×2, tx, net, acc, app), "
        "so a frame is read on one thread, handed to Python, and the frame passed on written by another. "
        "tokenring's node processes (and the bare ring's) set "
        f"`ZENOH_RUNTIME={section['node_runtime']}`, one worker thread receiving and sending; the process "
        f"that hosts the router (`tokenring up`, `bench`) `{section.get('host_runtime', '(rx:(worker_threads:1))')}`, "
        "sending on a thread of its own (a router that also sends on its one worker stalls on a burst of "
        "reliable messages), unless the user's "
        "environment sets `ZENOH_RUNTIME` (`()` gives Zenoh's defaults). zenoh-python by default hands every "
        "received sample to a Python thread of its own, a thread switch and a wake per hop; the token's "
        "subscriber runs its callback on the receiving thread instead (`indirect=False`; "
        "`TOKENRING_ZENOH_DIRECT=0` restores the default). Both rings of every comparison in "
        "this report run under the same configuration; here each pair runs under each "
        "(`extra µs/hop`: tokenring's per-hop cost over the bare ring's).",
        "",
        md_table(
            rows,
            [
                "N",
                "topology",
                "configuration",
                "bare median ms",
                "median ms",
                "p99 ms",
                "ratio",
                "extra µs/hop",
                "handler µs",
                "CPU %/node",
            ],
        ),
        "",
    ]
    if gains:
        text += ["tokenring's runtime against Zenoh's defaults: " + "; ".join(gains) + ".", ""]
    if direct:
        text += [
            "The callback on the receiving thread against a Python thread: " + "; ".join(direct) + ".",
            "",
        ]
    return "\n".join(text) + "\n"


def load_md(section: dict[str, Any]) -> str:
    rows = [
        [
            r["label"],
            f(r["rtt_ms"]["median"], 3),
            f(r["rtt_ms"]["p90"], 3),
            f(r["rtt_ms"]["p99"], 3),
            f(r["handler_us"]["median"], 0),
            f(r["handler_us"]["p99"], 0),
            f(r["cpu_per_node_pct"], 1),
            f(r["rss_mb"]["mean"], 0),
        ]
        for r in section["runs"]
    ]
    ratio = ""
    if len(section["runs"]) == 2:
        ratio = f"\nWith every program reading and writing its channels the round trip is {section['runs'][1]['rtt_ms']['median'] / section['runs'][0]['rtt_ms']['median']:.2f}× the idle ring's.\n"
    return (
        "## Real channel load\n\nThe robot's eight nodes at bitrate max: idle (no programs) and with all eight programs running against the world simulator (room `office`), each copying the channels it unlocked at every visit.\n\n"
        + md_table(
            rows,
            ["ring", "median ms", "p90", "p99", "handler µs median", "handler p99", "CPU %/node", "RSS MB"],
        )
        + "\n"
        + ratio
    )


def commands_md(section: dict[str, Any], plots: Path) -> str:
    rows = [
        [
            s["label"],
            s["commands"],
            s["acknowledged"],
            s["lost"],
            f(s["ms"]["median"], 2),
            f(s["ms"]["p99"], 2),
            f(s["ms"]["max"], 2),
            f(s["rounds"]["median"], 0),
            f(s["rounds"]["max"], 0),
            f(s["waited_rounds"]["median"], 0),
            f(s["waited_rounds"]["max"], 0),
            section["seed_worst_rounds"],
        ]
        for s in section["scenarios"]
    ]
    return (
        "## Command latency\n\n"
        f"`send_command` until the command is back at the sender acknowledged, on the robot's {section['nodes']} nodes at bitrate max (program `bench/programs/commander.py`). *rounds* are the sender's token visits in that time; *waited* are the rounds its outbox found the inbox occupied by another sender's command. The seed's worst case is n − 2 = {section['seed_worst_rounds']} rounds of waiting.\n\n"
        + md_table(
            rows,
            [
                "scenario",
                "commands",
                "acked",
                "lost",
                "median ms",
                "p99 ms",
                "max ms",
                "rounds median",
                "rounds max",
                "waited median",
                "waited max",
                "seed worst",
            ],
        )
        + "\n"
    )


def profile_md(section: dict[str, Any], plots: Path) -> str:
    m = section["model"]
    lo, hi = section["seed_ms"]
    rows = [["seed robot (2001): 7 computers, 2.5 Mbit/s, 8051 at 16 MHz", f"{lo:.0f}-{hi:.0f}", "", ""]]
    for r in section["runs"]:
        q = r["rounds_ms"]
        rows.append(
            [
                f"tokenring `--profile arcnet`, {r['label']}",
                f(q["median"], 1),
                f"{q['p10']:.1f}-{q['p90']:.1f}",
                f(q["max"], 1),
            ]
        )
    return (
        "## The seed's timing: `--profile arcnet`\n\n"
        f"Seven nodes (the seed's seven computers: {', '.join(section['nodes'])}) at 2.5 Mbit/s with the profile of `tokenring/node/pacing.py`: per pass {m['wire_ms_per_hop']:.3f} ms wire time, {m['visit_ms']:.3f} ms of 8051 interrupt and header work, {m['byte_us']:.0f} µs per byte of each unlocked channel the node copies, and on the sonar the 10.2 ms interrupt lock of every 15 ms measurement (the token waits {m['sonar_mean_hold_ms']:.1f} ms there on average). Without any channel copied the model gives {m['no_copy_ms']:.1f} ms a round.\n\n"
        + md_table(rows, ["", "round trip median ms", "p10-p90 ms", "max ms"])
        + f"\n\n![profile arcnet]({plots}/profile.png)\n"
    )


def recovery_md(section: dict[str, Any]) -> str:
    text = recovery_table_md(section, "")
    links = section.get("links")
    if links:
        text += "\n" + recovery_table_md(links, "direct links: ")
    return "## Recovery\n\n" + text


def recovery_table_md(section: dict[str, Any], where: str) -> str:
    """One run of bench/recovery.py as a paragraph and a table."""
    topology = (
        "the launcher the nodes' router and the hop on direct links, the wire captured by tcpdump on every link port and out of the router"
        if section.get("topology") == "links"
        else "a full mesh of peers, the wire seen by a subscriber of every token key"
    )
    rows = []
    for kind, s in section["summary"].items():
        rows.append(
            [
                kind,
                s["trials"],
                f(s["median_ms"], 1),
                f(s["p90_ms"], 1),
                f(s["max_ms"], 1),
                "-" if s["aim_ms"] is None else f"< {s['aim_ms']:.0f}",
                s["not_recovered"],
                s["tokens_regenerated"],
                s["duplicates_eliminated"],
            ]
        )
    load = section.get("machine", {}).get("load_1min")
    return (
        f"{where}`bench/recovery.py`: faults injected at run time into an {section['nodes']}-node ring at bitrate max ({topology}), recovery timed from the wire (until one token has gone round every node that should be in the ring), load {f(load, 1)} at its end.\n\n"
        + md_table(
            rows,
            [
                "fault",
                "trials",
                "median ms",
                "p90 ms",
                "max ms",
                "aim",
                "not recovered",
                "tokens regenerated",
                "duplicates eliminated",
            ],
        )
        + "\n"
    )


def download_md(section: dict[str, Any]) -> str:
    rows = []
    for r in section["runs"]:
        for mode in ("raw", "zlib"):
            m = r[mode]
            rows.append(
                [
                    r["bitrate"],
                    mode,
                    m["wire_bytes"],
                    m["chunks"],
                    f(m["rounds_per_chunk"], 2),
                    f(r["round_ms"]["median"], 2),
                    f(m["seconds_median"], 1),
                    f(m["source_bytes_per_s"], 0),
                    f"{m['vs_seed'][0]:.0f}-{m['vs_seed'][1]:.0f}×",
                ]
            )
    return (
        "## Program download\n\n`bench/download.py`: all eight programs of `modules/` through the token of the eight-node ring, one 30-byte chunk per round (the seed needed 3-4 minutes for all).\n\n"
        + md_table(
            rows,
            [
                "bitrate",
                "sent as",
                "bytes on the ring",
                "chunks",
                "rounds/chunk",
                "round ms (idle)",
                "seconds",
                "program B/s",
                "faster than the seed",
            ],
        )
        + "\n"
    )


def zero_bound_per_hour(seconds: float) -> float:
    """The 95 % upper bound of a rate per hour when no event was seen in ``seconds`` (Poisson: 3 / T)."""
    return 3.0 * 3600.0 / seconds if seconds > 0 else float("inf")


def spurious_aim(section: dict[str, Any] | None) -> list[list[Any]]:
    """The aims row: no spurious regeneration at the default pace without a hog."""
    if not section:
        return []
    quiet = [r for r in section["runs"] if "error" not in r and r["key"] in ("idle", "robot")]
    if not quiet:
        return []
    seconds = sum(r["seconds"] for r in quiet)
    count = sum(r["by_cause"]["spurious"] for r in quiet)
    parts = [
        f"{r['by_cause']['spurious']} in {r['seconds'] / 60:.1f} min ({r['key']}, load {f(r['load1']['median'], 1)})"
        for r in quiet
    ]
    measured = ", ".join(parts) + (
        f"; with none seen the rate is below {zero_bound_per_hour(seconds):.0f}/h (95 %)"
        if count == 0
        else f" = {count * 3600 / seconds:.1f}/h"
    )
    return [["spurious token regenerations, default pace, no CPU hog", "none", measured, verdict(count == 0)]]


def spurious_md(section: dict[str, Any]) -> str:
    """bench/spurious.py's table: regenerations with no fault per configuration."""
    rows = []
    for r in section["runs"]:
        if "error" in r:
            rows.append([r["label"], f"failed: {r['error']}"])
            continue
        gaps = r["gaps_at_highest"]
        rate = r["per_hour"]
        bound = f" (< {zero_bound_per_hour(r['seconds']):.0f})" if r["regenerated"] == 0 else ""
        rows.append(
            [
                r["label"],
                f(r["seconds"] / 60, 1),
                r["rounds"],
                f(r["round_ms"]["median"], 1),
                f(r["recon_ms"]["median"], 0),
                f"{f(gaps['p999_ms'], 0)} / {f(gaps['max_ms'], 0)}",
                gaps["over_recon"],
                r["regenerated"],
                r["by_cause"]["spurious"],
                f(rate, 1) + bound,
                f"{f(r['load1']['median'], 1)} / {f(r['load1']['max'], 1)}",
            ]
        )
    hog = next((r["hog"] for r in section["runs"] if r.get("hog")), None)
    return (
        "## Spurious regenerations\n\n"
        f"`bench/spurious.py` (`python -m bench --sections spurious`): the eight-node ring launched by `tokenring up` runs {section['minutes']:g} minutes per configuration with no fault injected; "
        "every token regeneration in that time is spurious (the token was late, not lost). Regenerations are the sum of the nodes' `tokens_regenerated` deltas, the spurious ones as the nodes' ledgers count them "
        "(no fault on any node, no node come or gone in the seconds before; `tokenring status` shows both per hour). "
        f"The CPU hog is {hog or 'a busy loop per core'}, started once the ring circulates. Gaps are the round times of the highest node (rank 0: the first to regenerate a token it misses) against its reconfiguration timeout. "
        "The machine is shared: the load average (1 min, median / max over the run) includes other work.\n\n"
        + md_table(
            rows,
            [
                "configuration",
                "min",
                "rounds",
                "round ms",
                "timeout ms",
                "gap p99.9 / max ms",
                "gaps > timeout",
                "regenerations",
                "spurious",
                "per hour (95 % bound)",
                "load",
            ],
        )
        + "\n"
        + spurious_findings(section)
    )


def spurious_findings(section: dict[str, Any]) -> str:
    """What the regenerating nodes saw (their ledgers' details), per pace, summed over its runs."""
    lines = []
    for pace, keys in (("default pace", ("idle", "robot")), ("--speed 10", ("speed10",))):
        details = [
            d
            for r in section["runs"]
            if r.get("key", "").split("+")[0] in keys
            for d in r.get("regenerations", [])
        ]
        if not details:
            continue
        n = len(details)
        rank0 = [d for d in details if d.get("rank") == 0]
        queued = sum(1 for d in details if d.get("queued"))
        stalled = sum(1 for d in details if d.get("stalled"))
        # on time: the highest rank decided within a quarter of its timeout after the timeout
        on_time = sum(
            1
            for d in rank0
            if d.get("since_seen_ms") and d["since_seen_ms"] < 1.25 * d.get("recon_ms", float("inf"))
        )
        lines.append(
            f"* {pace}, {n} regenerations with details: {len(rank0)} by the highest node (rank 0), {on_time} "
            f"of them within a quarter of the timeout after it (its watchdog on time, the token elsewhere and "
            f"late); {n - len(rank0)} by lower ranks, whose own slot passed before the highest node's token or "
            f"its announcement reached them; {stalled} right after the node's watchdog woke more than a slot "
            f"late (its own process starved too); {queued} with the token already in hand (taken off the wire, "
            "queued for the node's token thread, not yet visited)."
        )
    if not lines:
        return ""
    return (
        "\nWhat the regenerating nodes saw, from their ledgers (each node keeps its last 16 regenerations, "
        "the run at most 40):\n\n" + "\n".join(lines) + "\n"
    )


def robot_md(out_dir: Path) -> str:
    lines = [
        "## The robot's own benchmarks",
        "",
        "Slow (minutes each), so the suite does not run them; their latest result files:",
        "",
    ]
    for name, command in (
        ("localization", "python -m bench.localization --json bench/results/localization-DATE.json"),
        ("mapping", "python -m bench.mapping --json bench/results/mapping-DATE.json"),
    ):
        files = sorted(out_dir.glob(f"{name}-*.json"))
        if files:
            lines.append(
                f"* `{name}`: [{files[-1].name}](results/{files[-1].name}) (`{command.split(' --json')[0]}`)"
            )
        else:
            lines.append(f"* `{name}`: no result file yet — `{command}`")
    return "\n".join(lines) + "\n"


def seedtable_md(out_dir: Path) -> str:
    """The 2001 robot beside ours, from the latest ``seedmode-*.json`` of each part; empty without."""
    from bench.seedreport import latest, section_md

    parts = latest(out_dir)
    return section_md(parts) if parts else ""


def seed_list(seeds: list[int]) -> str:
    """``1-20`` for a run of consecutive seeds, else ``5, 10, 11``."""
    if len(seeds) > 2 and seeds == list(range(seeds[0], seeds[0] + len(seeds))):
        return f"{seeds[0]}-{seeds[-1]}"
    return ", ".join(map(str, seeds))


def newest_result(out_dir: Path, pattern: str) -> tuple[Path, dict] | None:
    """The newest (by its ``date``) readable result file matching ``pattern``, or None."""
    found = []
    for path in out_dir.glob(pattern):
        try:
            result = json.loads(path.read_text())
            found.append((str(result["date"]), path, result))
        except (OSError, ValueError, KeyError, TypeError):
            continue
    if not found:
        return None
    _, path, result = max(found, key=lambda item: item[0])
    return path, result


def newest_section(out_dir: Path, pattern: str, render: Any) -> str:
    """``render(result, name)`` of the newest result file matching ``pattern``; empty without
    one, or when that one lacks what the section needs."""
    newest = newest_result(out_dir, pattern)
    try:
        return render(newest[1], newest[0].name) if newest else ""
    except (KeyError, TypeError):
        return ""


def collisions_md(out_dir: Path) -> str:
    """Explore 2's collisions and clearance in process (``closedloop-*.json`` that count them), by date."""
    from bench.closedloop import section_md

    found = []
    for path in out_dir.glob("closedloop-*.json"):
        try:
            document = json.loads(path.read_text())
            found.append((str(document["date"]), path.name, document))
        except (OSError, ValueError, KeyError, TypeError):
            continue
    return section_md([(name, document) for _, name, document in sorted(found, key=lambda f: f[0])])


def darmstadt_ring_md(out_dir: Path) -> str:
    """The Darmstadt filters on the ring (``python -m bench.darmstadt_ring``)."""
    from bench.darmstadt_ring import section_md

    return newest_section(out_dir, "darmstadt_ring-*.json", section_md)


def darmstadt_md(out_dir: Path) -> str:
    """The Darmstadt sensors beside the seed (``python -m bench.darmstadt``)."""
    from bench.darmstadt import section_md

    return newest_section(out_dir, "darmstadt-*.json", section_md)


def observers_md(out_dir: Path) -> str:
    """What watching costs the round trip (``python -m bench.observers``): every ``observers-*.json``."""
    from bench.observers import section_md

    found = []
    for path in sorted(out_dir.glob("observers-*.json")):
        try:
            found.append((path.name, json.loads(path.read_text())))
        except (OSError, ValueError):
            continue
    try:
        return section_md(found)
    except (KeyError, TypeError):
        return ""


def nemesis_md(out_dir: Path) -> str:
    """The Nemesis section from ``nemesis-*.json`` (``python -m bench.nemesis``): per result file
    its runs summed; empty without one."""
    rows = []
    for path in sorted(out_dir.glob("nemesis-*.json")):
        try:
            runs = json.loads(path.read_text())["runs"]
        except (OSError, ValueError, KeyError, TypeError):
            continue
        good = [r for r in runs if "error" not in r]
        loads = [r["load_1min_at_start"] for r in good if r.get("load_1min_at_start") is not None]

        def total(key: str, good: list[dict[str, Any]] = good) -> int:
            return sum(r.get(key) or 0 for r in good)

        rows.append(
            [
                f"[{path.name}](results/{path.name})",
                len(runs),
                seed_list([r["seed"] for r in runs]),
                f"{sum(r['duration_s'] for r in runs):g}",
                total("faults"),
                total("regenerated"),
                total("sent"),
                total("acked"),
                total("lost"),
                total("duplicated"),
                f"{sum(1 for r in good if r.get('one_token_at_end'))}/{len(runs)}",
                f"{sum(1 for r in good if r.get('ok'))}/{len(runs)}",
                f"{f(float(np.median(loads)), 0)} / {f(max(loads), 0)}" if loads else "-",
            ]
        )
    if not rows:
        return ""
    return (
        "## Nemesis: seeded random faults (`python -m bench.nemesis`)\n\n"
        "`tokenring chaos --random SEED` per seed, one run after the other, against the 8-node ring at "
        "bitrate max with the probe workload; commands judged from the probes' ledgers, one token by the "
        "wire once the ring converged. Per result file, its runs summed (load: the 1-minute load average "
        "at the start of a run, median / max).\n\n"
        + md_table(
            rows,
            [
                "file",
                "runs",
                "seeds",
                "s",
                "faults",
                "regenerated",
                "sent",
                "acked",
                "lost",
                "duplicated",
                "one token at end",
                "ok",
                "load",
            ],
        )
        + "\n"
    )


def _mutants_section(result: dict[str, Any], name: str) -> str:
    rows = []
    for m in result["mutants"]:
        caught = m.get("caught_by_seed")
        replay = "-"
        if "replay_mutant" in m:
            replay = (
                f"{'fails' if m['replay_mutant'].get('ok') is False else 'PASSES'}"
                f"{' (same frames)' if m['replay_mutant'].get('same_frames') else ''} / "
                f"{'passes' if m['replay_unmutated'].get('ok') else 'FAILS'} unmutated"
            )
        rows.append(
            [
                f"`{m['name']}`",
                f"`{m['file'].removeprefix('tokenring/')}`",
                m["breaks"],
                caught
                if caught is not None
                else ("**survived**" if "error" not in m else f"error: {m['error']}"),
                m.get("seeds_run", "-"),
                f(m.get("seconds_to_catch"), 0) if caught is not None else f(m.get("wall_s"), 0),
                ", ".join(m.get("broken", [])) or "-",
                f"{m['shrunk_operations']} ({m['shrunk_steps']} steps) of {m['schedule_operations']}"
                if m.get("shrunk_operations") is not None
                else "-",
                replay,
            ]
        )
    survivors = ", ".join(f"`{n}`" for n in result["survivors"]) or "none"
    load = result["load_1min_start_end"]
    return (
        "## Mutation campaign: broken builds against the virtual-time campaign (`python -m bench.mutants`)\n\n"
        f"Each mutant is a small patch to a copy of the `tokenring` package (commit {result['commit'][:10]}); "
        f"`tokenring sim --random {result['seeds']} --duration {result['duration_s']:g} --stop-at-failure` runs "
        f"against it on one core until a seed breaks an invariant (at most {result['budget_min']:g} wall minutes "
        "a mutant), the failing schedule is shrunk, and the shrunk file is replayed with the mutant (it must fail "
        "on the same frames) and without it (it must pass). Seconds: the seeds' own run time up to the catch "
        "(a survivor: the campaign's wall time); shrunk: operations left of the failing schedule. "
        f"{result['caught']} of {len(result['mutants'])} caught; survivors: {survivors}. "
        f"From [{name}](results/{name}), {result['date']}; load average {load[0]} at the start, {load[1]} at the "
        f"end, {result['cpus']} cores.\n\n"
        + md_table(
            rows,
            [
                "mutant",
                "file",
                "what it breaks",
                "caught by seed",
                "seeds",
                "s",
                "invariant broken",
                "shrunk",
                "replay",
            ],
        )
        + "\n"
    )


def mutants_md(out_dir: Path) -> str:
    """The mutation campaign (``python -m bench.mutants``): the newest ``mutants-*.json``."""
    return newest_section(out_dir, "mutants-*.json", _mutants_section)


def _simcampaign_section(result: dict[str, Any], name: str) -> str:
    c = result["commands"]
    load = result["load_1min"]
    row = [
        result["seeds"],
        f"{result['wall_s'] / 60:.1f}",
        result["jobs"],
        f"{result['simulated_h']:.2f}",
        f"{result['schedules_per_hour']:.0f}",
        result["operations"],
        result["faults"],
        result["regenerations"],
        c["sent"],
        c["acked"],
        c["unacked"],
        c["lost"],
        c["duplicated"],
        c["phantom"],
        result["failures"],
        f"{load['median']} / {load['max']}",
    ]
    files: dict[str, str] = {}  # seed -> its replay file, the shrunk one where there is one
    for file in result.get("failure_files", []):
        seed = file.split("sim-seed")[-1].split("-")[0].split(".")[0]
        if seed not in files or file.endswith("-min.yaml"):
            files[seed] = file
    failed = "".join(
        f"\n* seed {x['seed']}: {', '.join(x.get('broken', []))}"
        + (f" ([replay file](results/{files[str(x['seed'])]}))" if str(x["seed"]) in files else "")
        for x in result.get("failed", [])
    )
    return (
        "## Seed campaign in virtual time (`python -m bench.simcampaign`)\n\n"
        f"`tokenring sim --random` over consecutive seeds from {result['first_seed']}, each a nemesis schedule of "
        f"{result['duration_s']:g} simulated seconds on the 8-node ring (probe workload, every fault kind), judged "
        f"by the chaos invariants and the probes' ledgers, for {result['minutes']:g} wall minutes on "
        f"{result['jobs']} processes ({result['cpus']} cores; the issue's aim: 10 000 schedules an hour). "
        "Lost: acknowledged and taken by no incarnation; duplicated: taken twice. "
        f"From [{name}](results/{name}), {result['date']}, the build at commit {result['commit'][:10]}; "
        "load: the 1-minute load average over the run, median / max.\n\n"
        + md_table(
            [row],
            [
                "seeds",
                "min",
                "jobs",
                "simulated h",
                "schedules/h",
                "operations",
                "faults",
                "regenerated",
                "sent",
                "acked",
                "unacked",
                "lost",
                "duplicated",
                "phantom",
                "failures",
                "load",
            ],
        )
        + "\n"
        + failed
        + ("\n" if failed else "")
    )


def simcampaign_md(out_dir: Path) -> str:
    """The timed seed campaign (``python -m bench.simcampaign``): the newest ``simcampaign-*.json``."""
    return newest_section(out_dir, "simcampaign-*.json", _simcampaign_section)


def regenerate_command(out_dir: Path, current: Path) -> str:
    """The command, run from the repository's root, that writes the report of result file
    ``current`` in ``out_dir`` again, running nothing (a path outside the repository is given
    whole)."""

    def shown(path: Path) -> str:
        path = Path(path).resolve()
        return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)

    out = "" if Path(out_dir).resolve() == HERE / "results" else f" --out {shown(out_dir)}"
    return f".venv/bin/python -m bench.report{out} {shown(current)}"


def write_report(
    results: dict[str, Any],
    out_dir: Path,
    md_path: Path | None = None,
    current: Path | None = None,
    raw: dict[str, Any] | None = None,
) -> Path:
    """Write the PNGs under ``out_dir/plots`` and RESULTS.md beside ``out_dir``; returns its path.

    ``results`` is a run's summary (a raw record is summarised first: the tables never see a
    sample); ``raw`` its raw record, else ``raw/<name of current>`` if there is one. Sections
    missing from ``results`` come from the latest other result file in ``out_dir`` (``current``:
    the file ``results`` was written to, never its own source), their samples from its raw record.
    A plot whose samples are in no raw record is left as it is, and stderr says so."""
    out_dir = Path(out_dir)
    md_path = md_path or out_dir.parent / "RESULTS.md"
    plots = out_dir / "plots"
    plots.mkdir(parents=True, exist_ok=True)
    sections = {name: summary_section(name, s) for name, s in results["sections"].items()}
    records: dict[str, Any] = dict(results["sections"])  # for the plots: with samples if any
    if raw is not None:
        records.update(raw.get("sections", {}))
    sources: dict[str, Path | None] = dict.fromkeys(sections, current)
    borrowed: dict[str, str] = {}
    for name in SECTIONS:
        if name not in sections:
            found = previous_run(name, out_dir, current)
            if found is not None:
                records[name], borrowed[name], sources[name] = found
                sections[name] = summary_section(name, records[name])
    m = results["machine"]
    again = [] if current is None else [regenerate_command(out_dir, current)]
    head = [
        "# Benchmark results",
        "",
        "Generated — do not edit. From the repository's root, "
        + (
            "the first command writes this file again from its result files (running nothing), "
            "the second measures everything again:"
            if again
            else "this measures everything again:"
        ),
        "",
        "```",
        *again,
        f".venv/bin/{REPRODUCE}        # about 30 minutes; --quick: under 2 minutes",
        "```",
        "",
        f"This run: `{results['command']}` on {results['date']}.",
        "",
        f"Machine: {m['cpus']} cores, {m['memory_gib']} GiB, Python {m['python']}, Zenoh {m['zenoh']}, Linux {m['kernel']}; "
        f"token path in {m.get('token_path', 'Python')} "
        f"(`tokenring/{'_tokenpath.c' if m.get('token_path') == 'C' else 'node/tokenpath.py'}`); "
        f"shared with other work: load average {results['load_start'][0]} at the start, {results['load_end'][0]} at the end of the run "
        f"({results['seconds'] / 60:.0f} min). Times are medians unless marked; ratios compare runs of the same suite run.",
        "",
    ]
    if borrowed:
        head.append(
            "Not run this time, taken from earlier runs: "
            + "; ".join(f"{k} from {v}" for k, v in borrowed.items())
            + ".\n"
        )
    if results.get("errors"):
        head.append(
            "Sections that failed in this run: "
            + "; ".join(f"{k}: {v}" for k, v in results["errors"].items())
            + "\n"
        )
    parts = ["\n".join(head), aims(sections)]
    rel = Path(os.path.relpath(plots, md_path.parent))
    if "scaling" in sections:
        plot_scaling(sections["scaling"]["runs"], plots / "scaling.png")
        plot_resources(sections["scaling"]["runs"], plots / "resources.png")
        parts.append(scaling_md(sections["scaling"], rel))
    if "transports" in sections:
        plot_transports(sections["transports"]["runs"], plots / "transports.png")
        parts.append(transports_md(sections["transports"], rel))
    if "runtime" in sections:
        parts.append(runtime_md(sections["runtime"]))
    if "load" in sections:
        parts.append(load_md(sections["load"]))
    if "commands" in sections:
        parts.append(commands_md(sections["commands"], rel))
    if "profile" in sections:
        samples = raw_section("profile", sources["profile"], records["profile"])
        if samples is not None:
            plot_profile(samples, plots / "profile.png")
        else:
            where = sources["profile"]
            sys.stderr.write(
                f"{plots / 'profile.png'}: "
                + ("kept as it is" if (plots / "profile.png").exists() else "not drawn")
                + f": the profile's round trips are in no raw record ({raw_path(where) if where else 'none given'})\n"
            )
        parts.append(profile_md(sections["profile"], rel))
    if "recovery" in sections:
        parts.append(recovery_md(sections["recovery"]))
    if "download" in sections:
        parts.append(download_md(sections["download"]))
    if "spurious" in sections:
        parts.append(spurious_md(sections["spurious"]))
    parts.append(observers_md(out_dir))
    parts.append(nemesis_md(out_dir))
    parts.append(simcampaign_md(out_dir))
    parts.append(mutants_md(out_dir))
    parts.append(seedtable_md(out_dir))
    parts.append(darmstadt_md(out_dir))
    parts.append(darmstadt_ring_md(out_dir))
    parts.append(collisions_md(out_dir))
    parts.append(robot_md(out_dir))
    md_path.write_text("\n".join(p for p in parts if p).rstrip() + "\n")
    return md_path


def latest_result(out_dir: Path) -> Path | None:
    """The suite's latest result file in ``out_dir``, by the date it recorded."""
    found = []
    for path in out_dir.glob("*.json"):
        try:
            data = json.loads(path.read_text())
        except (OSError, ValueError):
            continue
        if isinstance(data, dict) and "sections" in data and "machine" in data:
            found.append((str(data.get("date", "")), path.name, path))
    return max(found)[2] if found else None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bench.report",
        description="Rebuild bench/RESULTS.md and its plots from a suite result file, running nothing.",
    )
    parser.add_argument("result", nargs="?", help="a suite result file (default: the latest in --out)")
    parser.add_argument(
        "--out", default=str(HERE / "results"), help="results directory (default bench/results)"
    )
    args = parser.parse_args(argv)
    out_dir = Path(args.out)
    path = Path(args.result) if args.result else latest_result(out_dir)
    if path is None:
        sys.stderr.write(f"python -m bench.report: no suite result file in {out_dir}\n")
        return 2
    md = write_report(json.loads(path.read_text()), out_dir, current=path)
    sys.stderr.write(f"written {md} from {path}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
