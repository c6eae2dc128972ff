"""Seed campaigns in virtual time (``tokenring sim --random A..B``, issue 55): TigerBeetle's VOPR
and FoundationDB's simulation tests, on the ring.

Each seed draws a schedule of overlapping faults (:func:`tokenring.chaos.nemesis.generate`, the
one ``tokenring chaos --random`` draws) and runs it on the simulated ring from the same seed
(:func:`tokenring.chaos.virtual.run_virtual`), judged by the same invariants and ledgers. A
failing seed is written out as a replay file (the scenario and its ``sim:`` section with the seed
and the frame hash) and shrunk to fewer operations that still fail; ``tokenring sim --replay``
runs either exactly again. Seeds run one after another or on several cores (``jobs``), each in a
process of its own.
"""

from __future__ import annotations

import multiprocessing
import signal
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

SETTLE_S = 3.0  # after the last operation, as tokenring chaos --random
COMMAND_KEYS = ("sent", "acked", "unacked", "untransmitted", "taken", "lost", "duplicated", "phantom")
DOWNLOAD_KEYS = ("attempted", "completed", "failed")


@dataclass(frozen=True)
class CampaignSpec:
    """What every seed of a campaign shares."""

    duration_s: float
    kinds: tuple[str, ...]
    bitrate: str
    profile: str | None
    out: str
    shrink_runs: int
    nodes: tuple[str, ...]
    downloads: bool = False  # main downloads programs all along (ring.downloads)


@dataclass
class CampaignResult:
    """A campaign's figures (``--json``; ``bench/RESULTS.md`` shows a long one)."""

    seeds: int = 0
    failed: list[dict[str, Any]] = field(default_factory=list)
    simulated_s: float = 0.0
    cpu_s: float = 0.0  # the seeds' own real time, summed over the workers
    wall_s: float = 0.0
    jobs: int = 1
    faults: int = 0
    operations: int = 0
    regenerations: int = 0
    commands: dict[str, int] = field(default_factory=lambda: dict.fromkeys(COMMAND_KEYS, 0))
    downloads: dict[str, int] = field(default_factory=lambda: dict.fromkeys(DOWNLOAD_KEYS, 0))
    interrupted: bool = False

    @property
    def per_hour(self) -> float:
        """Seeds (schedules) run per hour of wall time."""
        return self.seeds * 3600.0 / self.wall_s if self.wall_s > 0 else 0.0

    def add(self, outcome: dict[str, Any]) -> None:
        self.seeds += 1
        self.simulated_s += outcome["simulated_s"]
        self.cpu_s += outcome["real_s"]
        self.faults += outcome["faults"]
        self.operations += outcome["operations"]
        self.regenerations += outcome["regenerations"]
        for key in COMMAND_KEYS:
            self.commands[key] += int(outcome["commands"].get(key, 0))
        for key in DOWNLOAD_KEYS:
            self.downloads[key] += int(outcome.get("downloads", {}).get(key, 0))
        if not outcome["ok"]:
            self.failed.append(
                {k: outcome[k] for k in ("seed", "broken", "file", "shrunk", "frames_sha256") if k in outcome}
            )

    def as_dict(self) -> dict[str, Any]:
        return {
            "seeds": self.seeds,
            "failed": self.failed,
            "simulated_s": round(self.simulated_s, 3),
            "wall_s": round(self.wall_s, 3),
            "cpu_s": round(self.cpu_s, 3),
            "jobs": self.jobs,
            "schedules_per_hour": round(self.per_hour, 1),
            "speedup": round(self.simulated_s / self.cpu_s, 2) if self.cpu_s else None,
            "operations": self.operations,
            "faults": self.faults,
            "regenerations": self.regenerations,
            "commands": self.commands,
            "downloads": self.downloads,
            "interrupted": self.interrupted,
        }


def unique_path(directory: Path, stem: str, suffix: str) -> Path:
    """``directory/stem.suffix``, or with -2, -3 ... if that exists: nothing is overwritten."""
    path = directory / f"{stem}{suffix}"
    number = 2
    while path.exists():
        path = directory / f"{stem}-{number}{suffix}"
        number += 1
    return path


def run_seed(seed: int, spec: CampaignSpec) -> dict[str, Any]:
    """One seed: draw, run, judge; a failure written out and shrunk. Plain values back (a
    worker process's answer)."""
    from tokenring.chaos.nemesis import generate, scenario_document, shrink
    from tokenring.chaos.runner import load_scenario
    from tokenring.chaos.virtual import run_virtual
    from tokenring.contract.protocol import default_protocol
    from tokenring.contract.ring import parse_bitrate

    protocol = default_protocol()
    bitrate = parse_bitrate(spec.bitrate)
    assert bitrate is not None
    ops = generate(seed, list(spec.nodes), duration=spec.duration_s, settle=SETTLE_S, kinds=spec.kinds)
    sim = {"seed": seed, "bitrate": spec.bitrate, "profile": spec.profile}

    def attempt(candidate: Sequence[Any]) -> Any:
        with tempfile.TemporaryDirectory(prefix="tokenring-sim-") as scratch:
            file = Path(scratch) / "scenario.yaml"
            file.write_text(scenario_document(candidate, settle=SETTLE_S, sim=sim, downloads=spec.downloads))
            return run_virtual(
                load_scenario(file, protocol), protocol, seed=seed, bitrate=bitrate, profile=spec.profile
            )

    run = attempt(ops)
    report = run.report
    outcome: dict[str, Any] = {
        "seed": seed,
        "ok": bool(report["ok"]),
        "broken": sorted(name for name, ok in report["invariants"].items() if not ok),
        "operations": len(ops),
        "faults": len(report["faults"]),
        "regenerations": sum(int(s["tokens_regenerated"]) for s in report["faults"]),
        "commands": {k: report.get("commands", {}).get(k, 0) for k in COMMAND_KEYS},
        "downloads": {k: report.get("downloads", {}).get(k, 0) for k in DOWNLOAD_KEYS},
        "simulated_s": run.summary.simulated_s,
        "real_s": run.summary.real_s,
        "frames_sha256": run.summary.frames_sha256,
    }
    if report["ok"]:
        return outcome
    out = Path(spec.out)
    comment = (
        f"tokenring sim --random {seed} --duration {spec.duration_s:g}: failed ({', '.join(outcome['broken'])})\n"
        "run it again exactly with: tokenring sim --replay THIS_FILE"
    )
    path = unique_path(out, f"sim-seed{seed}", ".yaml")
    path.write_text(
        scenario_document(
            ops,
            settle=SETTLE_S,
            comment=comment,
            sim={**sim, "frames_sha256": run.summary.frames_sha256},
            downloads=spec.downloads,
        )
    )
    outcome["file"] = str(path)
    if spec.shrink_runs:
        smallest, runs = shrink(ops, lambda candidate: not attempt(candidate).report["ok"], spec.shrink_runs)
        last = attempt(smallest)
        shrunk = unique_path(out, f"sim-seed{seed}-min", ".yaml")
        shrunk.write_text(
            scenario_document(
                smallest,
                settle=SETTLE_S,
                comment=f"shrunk from {path.name} ({len(ops)} operations) in {runs} runs: {len(smallest)} "
                "still fail\nrun it again exactly with: tokenring sim --replay THIS_FILE",
                sim={**sim, "frames_sha256": last.summary.frames_sha256},
                downloads=spec.downloads,
            )
        )
        outcome["shrunk"] = {"file": str(shrunk), "operations": len(smallest), "runs": runs}
    return outcome


def _worker_init() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the campaign's process handles Ctrl-C


def _run_one(task: tuple[int, CampaignSpec]) -> dict[str, Any]:
    return run_seed(*task)


def run_campaign(
    seeds: Sequence[int],
    spec: CampaignSpec,
    *,
    jobs: int = 1,
    on_outcome: Callable[[dict[str, Any], CampaignResult], None] | None = None,
    stop_at_failure: bool = False,
) -> CampaignResult:
    """Run every seed (on ``jobs`` worker processes), in order of completion, or until one fails
    (``stop_at_failure``); Ctrl-C stops the campaign with the seeds done so far
    (``interrupted``) and no worker left running."""
    result = CampaignResult(jobs=jobs)
    started = time.perf_counter()

    def outcomes() -> Iterator[dict[str, Any]]:
        if jobs <= 1:
            for seed in seeds:
                yield run_seed(seed, spec)
            return
        pool = multiprocessing.get_context("spawn").Pool(jobs, initializer=_worker_init)
        try:
            yield from pool.imap_unordered(_run_one, [(seed, spec) for seed in seeds])
            pool.close()
        finally:
            pool.terminate()
            pool.join()

    try:
        for outcome in outcomes():
            result.add(outcome)
            result.wall_s = time.perf_counter() - started
            if on_outcome is not None:
                on_outcome(outcome, result)
            if stop_at_failure and result.failed:
                break
    except KeyboardInterrupt:
        result.interrupted = True
    result.wall_s = time.perf_counter() - started
    return result
