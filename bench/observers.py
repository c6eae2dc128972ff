"""What watching costs the ring: the round trip with the web view (a browser on it), an MCAP
recording and the Foxglove bridge (a client subscribed to every topic) all running, against
the same ring with none of them, in alternating windows of one run.

One ``tokenring up`` (world and the eight programs, robot idle at its menu) runs throughout;
the round master (main) times its rounds. Each window waits for ``--rounds`` new rounds and
takes main's last ``--rounds`` round times; windows alternate ``none`` / ``all`` ``--repeat``
times, so drift of the machine falls on both. The observers start before an ``all`` window
(and are proved live: the page shows a moving token counter, the bridge's client has received
messages, the recording grows) and stop, by PID, after it.

    python -m bench.observers --repeat 3 --rounds 1000 [--json F] [--speed 1] [--separate]
    python -m bench.observers --observers metrics,pcap     # what a Prometheus scrape and a capture cost
    python -m bench.observers --observers metrics,pcap --scrape 15    # at Prometheus's usual interval

The observers run as ``tokenring up --web --record --foxglove --metrics P --pcap F`` runs them:
one ``tokenring watch`` process; ``--separate`` runs ``web``, ``record``, ``foxglove``, ``watch
--metrics`` and ``record --pcap`` as five. ``metrics`` is scraped over HTTP every ``--scrape``
seconds, the first at once (proved live: a scrape returned the ring's counters); a watcher that
only serves metrics asks the nodes at each scrape. ``pcap`` is proved live by its file growing.
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from tokenring import keys
from tokenring.transport import free_port, make_config, open_session, query

REPO = Path(__file__).resolve().parent.parent
MASTER = 10  # main: the round master times its rounds
START_TIMEOUT_S = 120.0
CLOCK_TICKS = os.sysconf("SC_CLK_TCK")
OBSERVERS = ("web", "record", "foxglove", "metrics", "pcap")
SCRAPE_S = 1.0  # the metrics scraper's default interval: 15 s is usual for Prometheus, this is harsher
WINDOW_TIMEOUT_S = 300.0


def tokenring(*args: str) -> list[str]:
    return [sys.executable, "-m", "tokenring", *args]


def spawn(argv: list[str], log: Path) -> subprocess.Popen:
    """A child in its own process group, its output to ``log`` (stopped by PID in :func:`stop`)."""
    return subprocess.Popen(
        argv, stdout=log.open("w"), stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True
    )


def stop(process: subprocess.Popen, timeout: float = 10.0) -> None:
    if process.poll() is not None:
        return
    with contextlib.suppress(ProcessLookupError):
        os.killpg(process.pid, signal.SIGINT)
    try:
        process.wait(timeout)
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, signal.SIGKILL)
        process.wait(5.0)


def tree_cpu_s(root: int) -> float:
    """CPU seconds (user + system) of ``root`` and all its descendants alive now."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            with contextlib.suppress(OSError, IndexError, ValueError):
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
                children.setdefault(int(fields[1]), []).append(int(entry.name))
    total, todo = 0.0, [root]
    while todo:
        pid = todo.pop()
        todo += children.get(pid, [])
        with contextlib.suppress(OSError, IndexError, ValueError):
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / CLOCK_TICKS
    return total


def visits(session: Any, ring: str) -> int:
    replies = query(session, keys.control(ring, MASTER, "visits"), timeout=1.0)
    if replies and replies[0][1].get("ok"):
        return int(replies[0][1]["result"])
    return -1


def measure_window(session: Any, ring: str, rounds: int) -> list[float]:
    """Main's next ``rounds`` round times (seconds)."""
    start = visits(session, ring)
    deadline = time.monotonic() + WINDOW_TIMEOUT_S
    while visits(session, ring) < start + rounds:
        if time.monotonic() > deadline:
            raise RuntimeError(f"main made fewer than {rounds} rounds in {WINDOW_TIMEOUT_S:.0f} s")
        time.sleep(0.25)
    replies = query(session, keys.control(ring, MASTER, "rounds"), timeout=2.0)
    values = list(replies[0][1]["result"])
    return values[-rounds:]


class BridgeClient:
    """A Foxglove WebSocket client subscribed to every advertised channel, counting messages."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.messages = 0
        self.error: str | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        from websockets.sync.client import connect

        try:
            deadline = time.monotonic() + 30.0
            while True:
                try:
                    ws = connect(self.url, subprotocols=["foxglove.sdk.v1", "foxglove.websocket.v1"])  # type: ignore[list-item]
                    break
                except OSError:
                    if time.monotonic() > deadline:
                        raise
                    time.sleep(0.2)
            with ws:
                next_id = 1
                while not self._stop.is_set():
                    try:
                        frame = ws.recv(timeout=0.2)
                    except TimeoutError:
                        continue
                    if isinstance(frame, str):
                        message = json.loads(frame)
                        if message.get("op") == "advertise":
                            subs = []
                            for channel in message["channels"]:
                                subs.append({"id": next_id, "channelId": channel["id"]})
                                next_id += 1
                            ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
                    elif frame[:1] == b"\x01":
                        self.messages += 1
        except Exception as exc:
            self.error = f"{type(exc).__name__}: {exc}"

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5.0)


class Scraper:
    """Prometheus's part: GET the metrics page at once, then every ``interval_s``, on a thread of
    its own."""

    def __init__(self, url: str, interval_s: float = SCRAPE_S) -> None:
        self.url = url
        self.interval_s = interval_s
        self.good = 0
        self.error: str | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        import urllib.request

        wait = 0.0
        while not self._stop.wait(wait):
            try:
                with urllib.request.urlopen(self.url, timeout=5) as reply:
                    if b"tokenring_" in reply.read():
                        self.good += 1
                        wait = self.interval_s
                        continue
            except OSError as exc:
                self.error = f"{type(exc).__name__}: {exc}"
            wait = min(1.0, self.interval_s)  # not serving yet: ask again soon

    def close(self) -> None:
        self._stop.set()
        self._thread.join(10.0)


class Browser:
    """Headless Chromium (the OS package) with the web view open."""

    def __init__(self, url: str) -> None:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service

        options = webdriver.ChromeOptions()
        options.binary_location = shutil.which("chromium") or "/usr/bin/chromium"
        for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--window-size=1280,900"):
            options.add_argument(flag)
        driver_path = shutil.which("chromedriver") or "/usr/bin/chromedriver"
        self.driver = webdriver.Chrome(service=Service(driver_path), options=options)
        deadline = time.monotonic() + 30.0
        while True:
            try:
                self.driver.get(url)
                break
            except Exception:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)

    def close(self) -> None:
        self.driver.quit()


@contextlib.contextmanager
def observers(
    ring: str,
    endpoint: str,
    folder: Path,
    which: tuple[str, ...],
    separate: bool = False,
    scrape_s: float = SCRAPE_S,
) -> Iterator[dict[str, Any]]:
    """The web view with a browser on it, a recording, the bridge with a client (those in
    ``which``; one ``tokenring watch``, or a process each if ``separate``): all live, their
    process trees' CPU seconds measured by ``cpu()``."""
    web_port, bridge_port, metrics_port = free_port(), free_port(), free_port()
    ring_opts = ["--ring", ring, "-e", endpoint]
    recording = folder / "observers.mcap"
    capture = folder / "observers.pcapng"
    if separate:  # a process of each, as three tools started by hand
        commands = {
            "web": tokenring("web", "--port", str(web_port), *ring_opts),
            "record": tokenring("record", str(recording), "--force", "--quiet", *ring_opts),
            "foxglove": tokenring("foxglove", "--port", str(bridge_port), *ring_opts),
            "metrics": tokenring("watch", "--metrics", str(metrics_port), *ring_opts),
            "pcap": tokenring("record", "--pcap", str(capture), "--force", "--quiet", *ring_opts),
        }
        children = {name: spawn(commands[name], folder / f"{name}.log") for name in which}
    else:  # one watcher, as `up --web --record --foxglove` starts it
        argv = ["watch", *ring_opts]
        if "web" in which:
            argv += ["--web", "--web-port", str(web_port)]
        if "record" in which:
            argv += ["--record", str(recording), "--force"]
        if "foxglove" in which:
            argv += ["--foxglove", "--foxglove-port", str(bridge_port)]
        if "metrics" in which:
            argv += ["--metrics", str(metrics_port)]
        if "pcap" in which:
            argv += ["--pcap", str(capture), "--force"]
        children = {"watch": spawn(tokenring(*argv), folder / "watch.log")}
    browser: Browser | None = None
    client: BridgeClient | None = None
    scraper: Scraper | None = None
    try:
        if "metrics" in which:
            scraper = Scraper(f"http://127.0.0.1:{metrics_port}/metrics", scrape_s)
        if "web" in which:
            browser = Browser(f"http://127.0.0.1:{web_port}/")
        if "foxglove" in which:
            client = BridgeClient(f"ws://127.0.0.1:{bridge_port}")
        deadline = time.monotonic() + START_TIMEOUT_S
        while client is not None and client.messages < 100:
            if client.error or time.monotonic() > deadline:
                raise RuntimeError(f"the bridge's client got {client.messages} messages ({client.error})")
            time.sleep(0.2)
        while scraper is not None and scraper.good < 1:
            if time.monotonic() > deadline:
                raise RuntimeError(f"no metrics scraped ({scraper.error})")
            time.sleep(0.2)
        growing = capture.with_name(capture.name + ".part")  # the capture is FILE.part until it ends
        while "pcap" in which and (not growing.exists() or growing.stat().st_size < 10_000):
            if time.monotonic() > deadline:
                logs = " | ".join(p.read_text()[-300:] for p in folder.glob("*.log"))
                raise RuntimeError(f"the capture did not grow: {logs}")
            time.sleep(0.2)
        dead = [name for name, c in children.items() if c.poll() is not None]
        if dead:
            raise RuntimeError(f"observer {dead[0]} exited: {(folder / f'{dead[0]}.log').read_text()[-500:]}")
        roots = [c.pid for c in children.values()]
        if browser is not None:
            roots.append(browser.driver.service.process.pid)

        def cpu() -> float:
            return sum(tree_cpu_s(pid) for pid in roots)

        yield {
            "bridge_messages": lambda: client.messages if client else 0,
            "scrapes": lambda: scraper.good if scraper else 0,
            "cpu": cpu,
        }
    finally:
        if scraper is not None:
            scraper.close()
        if client is not None:
            client.close()
        if browser is not None:
            browser.close()
        for child in children.values():
            stop(child)


def run(
    repeat: int,
    rounds: int,
    speed: str,
    which: tuple[str, ...] = OBSERVERS,
    quiet: bool = False,
    separate: bool = False,
    scrape_s: float = SCRAPE_S,
) -> dict[str, Any]:
    port = free_port()
    ring = f"obs{os.getpid()}"
    endpoint = f"tcp/127.0.0.1:{port}"
    windows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="tokenring-observers-") as tmp:
        folder = Path(tmp)
        up = spawn(
            tokenring(
                "up", "--ring", ring, "--listen", endpoint, "--speed", speed, "--store", str(folder / "store")
            ),
            folder / "up.log",
        )
        try:
            with open_session(make_config(mode="peer", connect=[endpoint])) as session:
                deadline = time.monotonic() + START_TIMEOUT_S
                while visits(session, ring) < 2000:  # formed, booted, programs settled
                    if up.poll() is not None or time.monotonic() > deadline:
                        raise RuntimeError(
                            f"the ring did not start: {(folder / 'up.log').read_text()[-800:]}"
                        )
                    time.sleep(0.5)
                for i in range(repeat):
                    for condition in ("none", "all"):
                        if not quiet:
                            print(f"  window {i + 1}/{repeat}: {condition}", file=sys.stderr, flush=True)
                        if condition == "none":
                            values = measure_window(session, ring, rounds)
                            extra: dict[str, Any] = {}
                        else:
                            with observers(ring, endpoint, folder, which, separate, scrape_s) as live:
                                cpu0, t0 = live["cpu"](), time.monotonic()
                                values = measure_window(session, ring, rounds)
                                extra = {
                                    "bridge_messages": live["bridge_messages"](),
                                    "scrapes": live["scrapes"](),
                                    "observer_cpu_pct": 100
                                    * (live["cpu"]() - cpu0)
                                    / (time.monotonic() - t0),
                                }
                        ms = np.asarray(values) * 1e3
                        windows.append(
                            {
                                "condition": condition,
                                "median_ms": float(np.median(ms)),
                                "p99_ms": float(np.percentile(ms, 99)),
                                "n": len(ms),
                                **extra,
                            }
                        )
        finally:
            stop(up, 30.0)
    return summarize(windows, repeat, rounds, speed, which, separate, scrape_s)


def summarize(
    windows: list[dict[str, Any]],
    repeat: int,
    rounds: int,
    speed: str,
    which: tuple[str, ...],
    separate: bool = False,
    scrape_s: float = SCRAPE_S,
) -> dict[str, Any]:
    out: dict[str, Any] = {"repeat": repeat, "rounds": rounds, "speed": speed, "observers": list(which)}
    if "metrics" in which:
        out["scrape_s"] = scrape_s
    out["processes"] = "separate" if separate else "one watcher"
    out["windows"] = windows
    out["observer_cpu_pct"] = float(
        np.median([w["observer_cpu_pct"] for w in windows if w["condition"] == "all"])
    )
    for condition in ("none", "all"):
        mine = [w for w in windows if w["condition"] == condition]
        out[condition] = {
            "median_ms": float(np.median([w["median_ms"] for w in mine])),
            "p99_ms": float(np.median([w["p99_ms"] for w in mine])),
        }
    out["ratio_median"] = out["all"]["median_ms"] / out["none"]["median_ms"]
    out["ratio_p99"] = out["all"]["p99_ms"] / out["none"]["p99_ms"]
    return out


def format_summary(report: dict[str, Any]) -> str:
    lines = [
        f"round trip of the robot ring (--speed {report['speed']}), {report['repeat']} x {report['rounds']} rounds "
        "per condition, windows alternating",
        f"{'condition':<44} {'median ms':>10} {'p99 ms':>10}",
    ]
    watched = ", ".join(observer_name(w, report) for w in report["observers"])
    if len(report["observers"]) > 1:
        watched += f" ({report.get('processes', 'separate')})"
    labels = {"none": "nobody watching (baseline)", "all": watched}
    for condition in ("none", "all"):
        c = report[condition]
        lines.append(f"{labels[condition]:<44} {c['median_ms']:>10.3f} {c['p99_ms']:>10.3f}")
    lines.append(
        f"ratio watched / baseline: median {report['ratio_median']:.3f}x, p99 {report['ratio_p99']:.3f}x"
    )
    lines.append(
        f"the observers' processes (with the browser) used {report['observer_cpu_pct']:.0f} % of a core"
    )
    return "\n".join(lines)


OBSERVER_NAMES = {
    "web": "web view + browser",
    "record": "MCAP recording",
    "foxglove": "Foxglove bridge + client",
    "metrics": "metrics + scrapes",
    "pcap": "pcapng capture",
}


def observer_name(which: str, run: dict[str, Any]) -> str:
    """What watched, as a table names it: the metrics with their scrape interval."""
    name = OBSERVER_NAMES.get(which, which)
    if which == "metrics":
        name += f" every {run.get('scrape_s', SCRAPE_S):g} s"
    return name


def runs_of(document: dict[str, Any]) -> list[dict[str, Any]]:
    """The summaries a result file holds: itself (``--json``), or lists of them by name."""
    if "windows" in document:
        return [document]
    return [
        run for value in document.values() if isinstance(value, list) for run in value if "windows" in run
    ]


def pairs(run: dict[str, Any]) -> list[tuple[dict[str, Any], dict[str, Any]]]:
    """Each window pair of a run: nobody watching, then watched, one after the other."""
    windows = run["windows"]
    return [
        (a, b) for a, b in itertools.pairwise(windows) if a["condition"] == "none" and b["condition"] == "all"
    ]


def verdict(run: dict[str, Any], key: str) -> str:
    """A ratio with how many window pairs it held in: higher in every pair is a cost that is
    there; higher in some and lower in others is within what the pairs spread."""
    ratio = run[f"ratio_{'median' if key == 'median_ms' else 'p99'}"]
    each = pairs(run)
    higher = sum(b[key] > a[key] for a, b in each)
    if higher == len(each):
        return f"×{ratio:.3f}, higher in all {len(each)} pairs"
    if higher == 0:
        return f"×{ratio:.3f}, lower in all {len(each)} pairs"
    return f"×{ratio:.3f}, higher in {higher} of {len(each)} pairs: within the noise"


def section_md(files: list[tuple[str, dict[str, Any]]]) -> str:
    """RESULTS.md's section from the ``observers-*.json`` files (name, document): every run's
    median and p99 round trip watched against nobody watching in the same run, each ratio with
    the window pairs it held in."""
    rows = []
    for name, document in files:
        for run in runs_of(document):
            watched = ", ".join(observer_name(w, run) for w in run["observers"])
            processes = run.get("processes", "separate")
            if len(run["observers"]) > 1:
                processes = (
                    "one `tokenring watch` (as `up` starts it)"
                    if processes == "one watcher"
                    else ("a process each (`--separate`)")
                )
            else:
                processes = "one process"
            none, alls = run["none"], run["all"]
            rows.append(
                f"| {watched} | {processes} | {len(pairs(run))} × {run['rounds']} | "
                f"{none['median_ms']:.2f} / {none['p99_ms']:.2f} | {alls['median_ms']:.2f} / {alls['p99_ms']:.2f} | "
                f"{verdict(run, 'median_ms')} | {verdict(run, 'p99_ms')} | "
                f"{run['observer_cpu_pct']:.0f} % | [{name}](results/{name}) |"
            )
    if not rows:
        return ""
    speeds = sorted({str(run["speed"]) for _, document in files for run in runs_of(document)})
    return (
        "## What watching costs (`python -m bench.observers`)\n\n"
        f"The robot ring at `--speed` {' or '.join(speeds)} (world and eight programs, robot idle), main's round trip in "
        "alternating windows of nobody watching and watched, each watched window right after its "
        "baseline in the same run: medians over the windows of each window's median and p99 (ms); a "
        "ratio's pairs say in how many window pairs the watched figure was the higher one. The "
        "observers' CPU includes the browser's. Generated from the result files named (do not edit).\n\n"
        "| observers | processes | pairs × rounds | baseline median / p99 | watched median / p99 | "
        "median | p99 | observers' CPU | result |\n|---|---|---|---|---|---|---|---|---|\n"
        + "\n".join(rows)
        + "\n"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bench.observers",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--repeat", type=int, default=3, help="window pairs (default %(default)s)")
    parser.add_argument("--rounds", type=int, default=1000, help="rounds per window (default %(default)s)")
    parser.add_argument("--speed", default="1", help="the world's speed-up (default %(default)s)")
    parser.add_argument("--json", metavar="FILE", help="write the summary and every window as JSON")
    parser.add_argument(
        "--observers",
        default=",".join(OBSERVERS),
        help="which run in the watched windows (default %(default)s)",
    )
    parser.add_argument(
        "--separate",
        action="store_true",
        help="a process per observer (three tools by hand) instead of one watcher as `up` starts",
    )
    parser.add_argument(
        "--scrape",
        type=float,
        default=SCRAPE_S,
        metavar="SECONDS",
        help="the metrics scraper's interval (default %(default)s; Prometheus's is usually 15)",
    )
    parser.add_argument("--quiet", action="store_true")
    args = parser.parse_args(argv)
    if not args.scrape > 0:
        parser.error(f"--scrape: give a positive number of seconds, not {args.scrape:g}")
    which = tuple(w.strip() for w in args.observers.split(",") if w.strip())
    unknown = set(which) - set(OBSERVERS)
    if unknown or not which:
        parser.error(f"--observers: choose from {', '.join(OBSERVERS)}")
    report = run(
        args.repeat, min(args.rounds, 1024), args.speed, which, args.quiet, args.separate, args.scrape
    )
    print(format_summary(report))
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
