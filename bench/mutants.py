"""A mutation campaign for the virtual-time ring (issue 55): ``python -m bench.mutants``.

Each mutant is a small textual patch (a file of the ``tokenring`` package, text that occurs in
it exactly once, its replacement) applied to a copy of the package in a temporary directory;
``tokenring sim --random 1..1000 --stop-at-failure`` then runs against the copy (it is first on
``sys.path``, which is checked), so the repository is never touched. A mutant is *caught* when a
seed breaks an invariant; its shrunk schedule is replayed with the mutant (it must fail again, on
the same frames) and on an unmutated copy (it must pass). A mutant no seed catches within the
seeds or the time given is a *survivor*: a finding about the checkers. The summary goes to
``bench/results/mutants-<date>.json`` and ``bench/RESULTS.md`` (``python -m bench.report``).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
RESULTS = Path(__file__).with_name("results")
SEEDS = "1..1000"
#: simulated seconds per schedule: about fifteen overlapping operations, a few seconds a seed,
#: and a failure shrinks fast; at 10 s one seed in a hundred draws no operation at all, which
#: the campaign refuses (exit 2, the campaign ends: seed 158 is the first)
DURATION_S = 20.0
SHRINK_RUNS = 40
BUDGET_MIN = 4.0  # wall minutes per mutant before its campaign is stopped (a survivor so far)
REPLAY_TIMEOUT_S = 300.0


@dataclass(frozen=True)
class Mutant:
    """A deliberately broken build: ``old`` (occurring once in ``file``) becomes ``new``."""

    name: str
    file: str  # relative to the tokenring package
    old: str
    new: str
    breaks: str  # what the bug does, one line
    kinds: str | None = None  # --kinds for its campaign (None: every operation)


MUTANTS = (
    Mutant(
        "outbox-occupied-counts-as-acked",
        "node/channels.py",
        "self.acknowledged = work[a + off.state] == off.ACKNOWLEDGED",
        "self.acknowledged = work[a + off.state] != off.FREE",
        "the sender takes a command still OCCUPIED (refused by a locked inbox) for acknowledged",
    ),
    Mutant(
        "outbox-takes-any-own-command-back",
        "node/channels.py",
        "if all(work[a + o] == v for o, v in self.ident):",
        "if True:",
        "back at the sender, any command of its own (an older one a regenerated copy kept) counts "
        "as this one's fate",
    ),
    Mutant(
        "inbox-takes-older-seqs",
        "node/channels.py",
        "return NEW if (seq - record.newest) & 0xFFFF < 0x8000 else STALE",
        "return NEW",
        "an older command of the same sender (an old token copy) is taken as new",
    ),
    Mutant(
        "inbox-acks-before-hand-over",
        "node/channels.py",
        "            self.memory.saw(sender, incarnation, seq, taken=False)\n",
        "            self.memory.saw(sender, incarnation, seq, taken=False)\n"
        "            work[a + off.state] = off.ACKNOWLEDGED\n",
        "a locked inbox acknowledges the command it refuses: acknowledged before it is handed over",
    ),
    Mutant(
        "inbox-retakes-the-last-command",
        "node/channels.py",
        "        if seq == record.taken:\n            return REPEAT\n",
        "",
        "the receiver forgets which command it took last: an old copy of it is taken again",
    ),
    Mutant(
        "inbox-takes-dead-incarnations",
        "node/channels.py",
        "return STALE if incarnation in record.retired else NEW",
        "return NEW",
        "a command of a sender's earlier incarnation (an old token copy) is taken as new",
    ),
    Mutant(
        "epoch-check-off",
        "node/tokenpath.py",
        "if R.epoch_order(epoch, origin, self._epoch, self._origin) < 0:",
        "if R.epoch_order(epoch, origin, self._epoch, self._origin) < -1:",
        "a token of an older epoch is adopted instead of answered stale: old tokens live on",
    ),
    Mutant(
        "epoch-keeps-the-round",
        "node/node_os.py",
        "        self._last_counter = -1  # a new epoch's token may carry any round (an old copy's)\n",
        "",
        "a new epoch keeps the last round seen, so its token (an older copy) is dropped as a replay",
    ),
    Mutant(
        "ping-unanswered",
        "node/recovery.py",
        "            if len(payload) == R.ACK_MESSAGE.size:\n",
        "            if len(payload) == -1:\n",
        "an excluded node does not answer the exclusion back-off's ping: a healed cut never merges",
    ),
    Mutant(
        "regeneration-guard-inverted",
        "node/recovery.py",
        "if self._last_visit and self._now() < self._last_seen + recon:",
        "if self._last_visit and self._now() >= self._last_seen + recon:",
        "the lost-token guard's comparison inverted: a ring that had a token never regenerates it",
    ),
    Mutant(
        "retries-never-give-up",
        "node/recovery.py",
        "if self._retries < R.ACK_RETRIES:",
        "if self._retries >= 0:",
        "an unanswered pass is retried for ever: a successor that does not answer is never skipped",
    ),
    Mutant(
        "exclusion-backoff-uncapped",
        "node/recovery.py",
        "value = min(0.1, previous * 2)",
        "value = max(0.1, previous * 2)",
        "the exclusion back-off doubles without its 0.1 s cap: an excluded node is pinged ever later",
    ),
    Mutant(
        "replay-rule-off",
        "node/tokenpath.py",
        "if 0 < back < 128 or (back == 0 and frame != self._accepted_frame):",
        "if 0 < back < 128:",
        "the same round with other bytes (a second token) is visited, not dropped as a replay",
    ),
    Mutant(
        "duplicate-pass-rule-off",
        "node/tokenpath.py",
        "if crc == self._accepted_crc and sid == self._accepted_sid and frame == self._accepted_frame:",
        "if False:",
        "a retry of a pass already taken is visited a second time",
    ),
)


def head_commit() -> str:
    """The commit the copies are made from."""
    done = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True, check=True)
    return done.stdout.strip()


def package_copy(directory: Path, mutant: Mutant | None, commit: str) -> Path:
    """The committed ``tokenring/`` (and the protocol file it reads beside it) of ``commit`` in
    ``directory`` (uncommitted edits in the work tree are not the build under test), with
    ``mutant`` applied; returns ``directory``."""
    directory.mkdir(parents=True, exist_ok=True)
    archive = subprocess.run(["git", "archive", commit, "tokenring", "protocol.yaml"], cwd=ROOT,
                             capture_output=True, check=True)  # fmt: skip
    subprocess.run(["tar", "-x", "-C", str(directory)], input=archive.stdout, check=True)
    if mutant is not None:
        path = directory / "tokenring" / mutant.file
        text = path.read_text()
        if text.count(mutant.old) != 1:
            raise SystemExit(
                f"{mutant.name}: the text to change occurs {text.count(mutant.old)} times in {mutant.file}"
            )
        path.write_text(text.replace(mutant.old, mutant.new))
    return directory


def environment(copy: Path) -> dict[str, str]:
    """The environment that imports the copy: first on the path (and run from inside it)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(copy) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env.pop("TOKENRING_PROTOCOL", None)
    return env


def check_imported(copy: Path, mutant: Mutant | None) -> None:
    """Refuse to go on unless ``python -m tokenring`` run this way imports the copy, mutated."""
    probe = "import tokenring.node.tokenpath as t, tokenring; print(tokenring.__file__)"
    done = subprocess.run([sys.executable, "-c", probe], cwd=copy, env=environment(copy),
                          capture_output=True, text=True, check=True)  # fmt: skip
    where = Path(done.stdout.strip()).resolve()
    if not where.is_relative_to(copy.resolve()):
        raise SystemExit(f"the copy is not what gets imported: tokenring from {where}")
    if mutant is not None and mutant.new not in (copy / "tokenring" / mutant.file).read_text():
        raise SystemExit(f"{mutant.name}: not applied")


def tokenring(*args: str) -> list[str]:
    """``tokenring sim ARGS`` as the interpreter runs it (with the copy's environment)."""
    return [sys.executable, "-m", "tokenring", "sim", *args]


def campaign(copy: Path, mutant: Mutant, args: argparse.Namespace, out: Path) -> dict[str, Any]:
    """``tokenring sim --random`` against the mutated copy until a seed fails, or until the budget
    ends (a survivor so far: the seeds it ran are its last progress line's)."""
    report = out / "campaign.json"
    argv = tokenring("--random", args.seeds, "--duration", f"{args.duration:g}", "--stop-at-failure",
                     "--shrink-runs", str(args.shrink_runs), "--out", str(out), "--json", str(report),
                     *(["--kinds", mutant.kinds] if mutant.kinds else []))  # fmt: skip
    started = time.monotonic()
    load_before = os.getloadavg()[0]
    child = subprocess.Popen(argv, cwd=copy, env=environment(copy), stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True, start_new_session=True)  # fmt: skip
    budget_ended = False
    try:
        stdout, stderr = child.communicate(timeout=args.budget_min * 60)
    except subprocess.TimeoutExpired:
        budget_ended = True
        # Ctrl-C does not stop a seed under way (the simulation records the KeyboardInterrupt as
        # one task's failure and runs on), so the campaign is terminated and its seeds are
        # counted from its progress lines
        child.terminate()
        stdout, stderr = child.communicate()
    wall = time.monotonic() - started
    if not report.exists():
        done = [int(m) for m in re.findall(r"sim \| (\d+)/\d+ seeds", stderr or "")]
        if not budget_ended:
            return {"error": (stderr or stdout).strip()[-600:], "wall_s": round(wall, 1)}
        return {
            "seeds_run": max(done, default=0),  # at least: the last progress line's count
            "wall_s": round(wall, 1),
            "seconds_to_catch": None,
            "budget_ended": True,
            "load_1min": [round(load_before, 2), round(os.getloadavg()[0], 2)],
        }
    data = json.loads(report.read_text())
    result: dict[str, Any] = {
        "seeds_run": data["seeds"],
        "wall_s": round(wall, 1),
        # the seeds' own run time, the shrinking left out: how long finding it took
        "seconds_to_catch": round(data["cpu_s"], 1) if data["failed"] else None,
        "simulated_s": data["simulated_s"],
        "faults": data["faults"],
        "commands": data["commands"],
        "budget_ended": budget_ended,
        "load_1min": [round(load_before, 2), round(os.getloadavg()[0], 2)],
    }
    if data["failed"]:
        failure = data["failed"][0]
        result.update(
            caught_by_seed=failure["seed"],
            broken=failure["broken"],
            schedule_steps=_steps(Path(failure["file"])),
            schedule_operations=_operations(failure.get("shrunk", {})),
            shrunk_steps=_steps(Path(failure["shrunk"]["file"])) if "shrunk" in failure else None,
            shrunk_operations=failure.get("shrunk", {}).get("operations"),
            shrink_runs=failure.get("shrunk", {}).get("runs"),
            replay_file=failure.get("shrunk", {}).get("file") or failure["file"],
        )
    return result


def _steps(path: Path) -> int:
    """The number of fault steps a replay file schedules (an operation is one or two: a fault and
    the step that ends it)."""
    import yaml

    return len(yaml.safe_load(path.read_text())["faults"])


def _operations(shrunk: dict[str, Any]) -> int | None:
    """The failing schedule's operations (the nemesis's units, which the shrinker removes), as
    the shrunk file's first line tells them."""
    found = re.search(r"\((\d+) operations\)", Path(shrunk["file"]).read_text()) if shrunk else None
    return int(found.group(1)) if found else None


def replay(copy: Path, file: Path, scratch: Path) -> dict[str, Any]:
    """``tokenring sim --replay FILE`` with the copy: its invariants and whether the frames were
    the recorded ones."""
    report = scratch / f"replay-{copy.name}.json"
    done = subprocess.run(tokenring("--replay", str(file), "--json", str(report), "--quiet"), cwd=copy,
                          env=environment(copy), capture_output=True, text=True, timeout=REPLAY_TIMEOUT_S)  # fmt: skip
    if not report.exists():
        return {"exit": done.returncode, "error": (done.stderr or done.stdout).strip()[-400:]}
    data = json.loads(report.read_text())
    return {
        "exit": done.returncode,
        "ok": data["ok"],
        "broken": sorted(k for k, v in data["invariants"].items() if not v),
        "same_frames": data.get("replay", {}).get("same_frames"),
    }


def run_mutant(mutant: Mutant, args: argparse.Namespace, pristine: Path) -> dict[str, Any]:
    print(f"mutants | {mutant.name}: {mutant.breaks}", file=sys.stderr, flush=True)
    with tempfile.TemporaryDirectory(prefix=f"mutant-{mutant.name}-") as scratch:
        copy = package_copy(Path(scratch) / "copy", mutant, args.commit)
        check_imported(copy, mutant)
        out = Path(scratch) / "failures"
        out.mkdir()
        result: dict[str, Any] = {
            "name": mutant.name,
            "file": f"tokenring/{mutant.file}",
            "old": mutant.old.strip(),
            "new": mutant.new.strip(),
            "breaks": mutant.breaks,
            "kinds": mutant.kinds or "all",
            **campaign(copy, mutant, args, out),
        }
        if "replay_file" in result:
            file = Path(result.pop("replay_file"))
            result["replay_mutant"] = replay(copy, file, Path(scratch))
            result["replay_unmutated"] = replay(pristine, file, Path(scratch))
            result["replay_confirmed"] = (
                result["replay_mutant"].get("ok") is False
                and result["replay_mutant"].get("same_frames") is True
                and result["replay_unmutated"].get("ok") is True
            )
            kept = args.keep / f"{mutant.name}-{file.name}" if args.keep else None
            if kept is not None:
                shutil.copy2(file, kept)
                result["replay_kept"] = str(kept)
    print(f"mutants | {mutant.name}: {_line(result)}", file=sys.stderr, flush=True)
    return result


def _line(r: dict[str, Any]) -> str:
    if "error" in r:
        return f"error: {r['error']}"
    if r.get("caught_by_seed") is None:
        return f"SURVIVED {r['seeds_run']} seeds in {r['wall_s']:.0f} s" + (
            " (budget)" if r.get("budget_ended") else ""
        )
    return (
        f"caught by seed {r['caught_by_seed']} after {r['seeds_run']} seeds, {r['seconds_to_catch']:.0f} s "
        f"({', '.join(r['broken'])}); shrunk {r['schedule_operations']} -> {r['shrunk_operations']} operations "
        f"({r['schedule_steps']} -> {r['shrunk_steps']} steps); "
        f"replay confirmed: {r.get('replay_confirmed')}"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.mutants", description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", help="comma-separated mutant names (default: all)")
    parser.add_argument("--seeds", default=SEEDS, help=f"the campaign's seeds A..B (default {SEEDS})")
    parser.add_argument("--duration", type=float, default=DURATION_S, help="simulated seconds per schedule")
    parser.add_argument("--shrink-runs", type=int, default=SHRINK_RUNS)
    parser.add_argument(
        "--budget-min", type=float, default=BUDGET_MIN, help="wall minutes per mutant at most"
    )
    parser.add_argument("--keep", type=Path, help="copy each shrunk replay file into this directory")
    parser.add_argument("--json", type=Path, help="default bench/results/mutants-<date>.json")
    parser.add_argument("--list", action="store_true", help="list the mutants and exit")
    args = parser.parse_args(argv)
    if args.list:
        for m in MUTANTS:
            print(f"{m.name:34s} {m.file:22s} {m.breaks}")
        return 0
    chosen = [m for m in MUTANTS if args.only is None or m.name in args.only.split(",")]
    if args.keep:
        args.keep.mkdir(parents=True, exist_ok=True)
    started = time.strftime("%Y-%m-%d %H:%M:%S")
    load = os.getloadavg()
    args.commit = head_commit()
    with tempfile.TemporaryDirectory(prefix="mutant-none-") as scratch:
        pristine = package_copy(Path(scratch) / "unmutated", None, args.commit)
        check_imported(pristine, None)
        results = [run_mutant(m, args, pristine) for m in chosen]
    summary = {
        "date": started,
        "command": "python -m bench.mutants " + " ".join(argv if argv is not None else sys.argv[1:]),
        "commit": args.commit,
        "seeds": args.seeds,
        "duration_s": args.duration,
        "shrink_runs": args.shrink_runs,
        "budget_min": args.budget_min,
        "jobs": 1,
        "cpus": os.cpu_count(),
        "load_1min_start_end": [round(load[0], 2), round(os.getloadavg()[0], 2)],
        "mutants": results,
        "caught": sum(1 for r in results if r.get("caught_by_seed") is not None),
        "survivors": [r["name"] for r in results if "error" not in r and r.get("caught_by_seed") is None],
    }
    path = args.json or RESULTS / f"mutants-{started[:10]}.json"
    path.write_text(json.dumps(summary, indent=1) + "\n")
    print(f"mutants | written {path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
