"""How fast ``tokenring`` answers: ``--version``, ``--help`` and a verb's ``--help`` against a bare
``python -c pass``, measured side by side in one run.

Every repetition runs each command once, in turn (interleaved, so a busy machine slows all of them
alike); a first untimed round warms the page cache and the bytecode caches. Per command: the wall
time and the CPU time (user + system, from the child's own rusage) as median and 99th percentile
over the repetitions, and the medians' ratio to the bare interpreter's; the peak RSS as the median
of a few runs under GNU time (``/usr/bin/time``, if installed: a child forked from this Python
would report this process's RSS as its own peak, which exec keeps).

Every command reads its bytecode from a cache of this run's own (``PYTHONPYCACHEPREFIX``, a
temporary directory the warm-up round fills, removed at the end), as an installed tokenring
does from its ``__pycache__``: an environment with ``PYTHONDONTWRITEBYTECODE`` and no cache in the
tree would otherwise compile every module of tokenring at every start. ``--as-is`` keeps the
environment's own bytecode settings instead.

    python -m bench.cli_start [--repeat 20] [--as-is] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from tokenring.cli import format_table


def tokenring_command() -> str:
    """The ``tokenring`` console script beside this interpreter (a venv's), else on PATH."""
    beside = Path(sys.executable).parent / "tokenring"
    if beside.exists():
        return str(beside)
    found = shutil.which("tokenring")
    if found is None:
        raise SystemExit("python -m bench.cli_start: no 'tokenring' command (pip install -e .)")
    return found


def commands() -> dict[str, list[str]]:
    """The measured commands, the bare interpreter first (the ratios' base)."""
    tokenring = tokenring_command()
    return {
        "python -c pass": [sys.executable, "-c", "pass"],
        "tokenring --version": [tokenring, "--version"],
        "tokenring --help": [tokenring, "--help"],
        "tokenring up --help": [tokenring, "up", "--help"],
        "tokenring status --help": [tokenring, "status", "--help"],
    }


GNU_TIME = "/usr/bin/time"
RSS_RUNS = 3


def run_once(argv: list[str], env: dict[str, str]) -> dict[str, float]:
    """One run: wall seconds and CPU seconds (user + system) of the child."""
    start = time.perf_counter()
    child = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    _, status, usage = os.wait4(child.pid, 0)
    wall = time.perf_counter() - start
    code = os.waitstatus_to_exitcode(status)
    if code != 0:
        raise SystemExit(f"python -m bench.cli_start: {' '.join(argv)} exited {code}")
    return {"wall": wall, "cpu": usage.ru_utime + usage.ru_stime}


def peak_rss_mb(argv: list[str], env: dict[str, str]) -> float | None:
    """The command's peak RSS in MB as GNU time reports it (None without GNU time)."""
    if not os.access(GNU_TIME, os.X_OK):
        return None
    with tempfile.NamedTemporaryFile("r", suffix=".time") as out:
        done = subprocess.run(
            [GNU_TIME, "-f", "%M", "-o", out.name, *argv],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            env=env,
            check=False,
        )
        text = out.read().strip().splitlines()
    if done.returncode != 0 or not text or not text[-1].isdigit():
        return None
    return int(text[-1]) / 1024


def percentile(values: list[float], q: float) -> float:
    """The ``q``-th percentile (nearest rank: a figure that was measured)."""
    ordered = sorted(values)
    return ordered[max(0, math.ceil(q / 100 * len(ordered)) - 1)]


def measure(repeat: int, as_is: bool = False) -> dict[str, Any]:
    """``repeat`` interleaved rounds of every command; the figures per command."""
    with tempfile.TemporaryDirectory(prefix="cli-start-pycache-") as cache:
        env = dict(os.environ)
        if not as_is:
            env.pop("PYTHONDONTWRITEBYTECODE", None)
            env["PYTHONPYCACHEPREFIX"] = cache
        return _measure(repeat, env, as_is)


def _measure(repeat: int, env: dict[str, str], as_is: bool) -> dict[str, Any]:
    argvs = commands()
    for argv in argvs.values():  # warm-up: page cache, the bytecode cache
        run_once(argv, env)
    samples: dict[str, list[dict[str, float]]] = {name: [] for name in argvs}
    for _ in range(repeat):
        for name, argv in argvs.items():
            samples[name].append(run_once(argv, env))
    figures: dict[str, Any] = {}
    for name, runs in samples.items():
        figure: dict[str, Any] = {"argv": argvs[name][1:] if name.startswith("tokenring") else argvs[name]}
        for key in ("wall", "cpu"):
            values = [run[key] for run in runs]
            figure[f"{key}_median"] = statistics.median(values)
            figure[f"{key}_p99"] = percentile(values, 99)
        rss = [peak_rss_mb(argvs[name], env) for _ in range(RSS_RUNS)]
        known = [value for value in rss if value is not None]
        figure["rss_mb_median"] = statistics.median(known) if known else None
        figures[name] = figure
    bare = figures["python -c pass"]
    for figure in figures.values():
        for key in ("wall", "cpu", "rss_mb"):
            base, value = bare[f"{key}_median"], figure[f"{key}_median"]
            figure[f"{key}_ratio"] = value / base if base and value is not None else None
    bytecode = "as the environment has it" if as_is else "cached (PYTHONPYCACHEPREFIX)"
    return {"repeat": repeat, "cpus": os.cpu_count(), "bytecode": bytecode, "commands": figures}


def report(result: dict[str, Any]) -> str:
    rows = []
    for name, f in result["commands"].items():
        ratios = [f"{f[key]:.1f}x" if f[key] is not None else "-" for key in ("wall_ratio", "cpu_ratio")]
        rss = f"{f['rss_mb_median']:.1f}" if f["rss_mb_median"] is not None else "-"
        rows.append(
            [
                name,
                f"{f['wall_median'] * 1e3:.0f}",
                f"{f['wall_p99'] * 1e3:.0f}",
                f"{f['cpu_median'] * 1e3:.0f}",
                f"{f['cpu_p99'] * 1e3:.0f}",
                *ratios,
                rss,
                f"{f['rss_mb_ratio']:.1f}x" if f["rss_mb_ratio"] is not None else "-",
            ]
        )
    headers = ["command", "wall ms", "p99", "CPU ms", "p99", "wall/bare", "CPU/bare", "RSS MB", "RSS/bare"]
    head = f"{result['repeat']} interleaved runs each (medians, p99), bytecode {result['bytecode']}\n"
    return head + format_table(rows, headers)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.cli_start", description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=20, help="rounds of every command (default 20)")
    parser.add_argument(
        "--as-is", action="store_true", help="keep the environment's bytecode settings (no cache of our own)"
    )
    parser.add_argument("--json", metavar="FILE", help="write the figures as JSON to FILE ('-': stdout)")
    args = parser.parse_args(argv)
    if args.repeat < 1:
        parser.error("--repeat: give at least 1")
    result = measure(args.repeat, args.as_is)
    if args.json == "-":
        print(json.dumps(result, indent=2))
        return 0
    print(report(result))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
