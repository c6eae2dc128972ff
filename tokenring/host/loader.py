"""The PC side of program download (the seed's ``LOAD.EXE``), used by ``tokenring load`` and ``up``.

Everything goes through main's PC link: ``scan`` (ARCNET_SCAN + ARCNET_GET_CONFIG of every node),
``download`` (main relays the program chunk by chunk through the token; a job the loader polls
for its progress bar), ``start``/``stop`` and ``errors`` (the ARCNET_ERROR reports main
collected). A program's time stamp is its file's modification time in ms.
"""

from __future__ import annotations

import contextlib
import errno
import os
import sys
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from tokenring._util.tables import format_table
from tokenring.errors import ProgramError, TransportError, UsageError
from tokenring.node.program import inspect_program, program_digest
from tokenring.node.store import file_stamp, format_stamp


@dataclass
class PlanItem:
    """One program the loader will send (or re-stamp, or leave)."""

    node: dict[str, Any]
    file: Path
    source: bytes
    stamp_ms: int
    action: str  # "download", "restamp" (same content, newer file) or "skip"
    reason: str


@dataclass
class Outcome:
    """What happened to one node."""

    node: dict[str, Any]
    file: str
    action: str
    ok: bool
    bytes: int = 0
    chunks: int = 0
    seconds: float = 0.0
    error: str | None = None
    started: bool = False
    extra: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        return {
            "id": self.node["id"],
            "name": self.node["name"],
            "file": self.file,
            "action": self.action,
            "ok": self.ok,
            "bytes": self.bytes,
            "chunks": self.chunks,
            "seconds": round(self.seconds, 3),
            "error": self.error,
            "started": self.started,
        }


def check_program_file(path: Path, node_name: str | None = None) -> tuple[bytes, str]:
    """Read and check a program file on the PC first, without running it; returns (source,
    module name). The node compiles and runs it (and reports what fails there).

    Raises :class:`UsageError` naming the file for a file that is missing or not a module."""
    from tokenring._util.files import read_bytes

    source = read_bytes(path, "program file")
    try:
        module = inspect_program(source, str(path)) or path.stem  # parsed, never run here
    except ProgramError as exc:
        raise UsageError(str(exc)) from None
    if node_name is not None and module != node_name:
        raise UsageError(f"{path} is the program of {module!r}, not of node {node_name!r}")
    return source, module


def check_program_dir(programs_dir: Path, names: Iterable[str]) -> dict[str, Path]:
    """Each node's program file in ``programs_dir`` (``<name>.py``), by name; a ``<name>.py``
    that is there but cannot be a program (a symbolic link loop, a link to nothing, a
    directory) is refused naming it, where leaving it out would skip the node's program
    without a word. The files are not read or parsed here."""
    found = {}
    for name in names:
        path = programs_dir / f"{name}.py"
        if not os.path.lexists(path):
            continue
        try:
            path.stat()
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                raise UsageError(f"{path}: a symbolic link loop, not the program of node {name!r}") from None
            if path.is_symlink():
                raise UsageError(
                    f"{path}: a symbolic link to {os.readlink(path)}, which does not exist"
                ) from None
            raise UsageError(f"{path}: cannot read: {exc.strerror}") from None
        if not path.is_file():
            kind = "a directory" if path.is_dir() else "not a regular file"
            raise UsageError(f"{path}: {kind}, not the program of node {name!r}")
        found[name] = path
    return found


def programs_in(programs_dir: Path) -> list[str]:
    """The program files (``*.py``) ``programs_dir`` holds, by name (for saying why nothing is sent)."""
    try:
        return sorted(entry.name for entry in os.scandir(programs_dir) if entry.name.endswith(".py"))
    except OSError:
        return []


class Loader:
    """Scan, plan, download with a progress bar, start/stop, report."""

    def __init__(
        self,
        link: Any,
        *,
        out: IO[str] | None = None,
        progress: bool | None = None,
        compress: bool = True,
        say: Callable[[str], None] | None = None,
        cancelled: Callable[[], bool] | None = None,
        poll_s: float = 0.1,
    ) -> None:
        self.link = link
        self.out = out or sys.stdout
        self.progress = (
            progress if progress is not None else bool(getattr(self.out, "isatty", lambda: False)())
        )
        self.compress = compress
        self._say = say
        self.cancelled = cancelled or (lambda: False)
        self.poll_s = poll_s

    def say(self, text: str) -> None:
        if self._say is not None:
            self._say(text)
        else:
            self.out.write(text + "\n")
            self.out.flush()

    # -- scan -----------------------------------------------------------------------------------
    def scan(self, expect: set[int] | None = None, wait: float = 0.0) -> list[dict[str, Any]]:
        """The ring's nodes with name, ID, time stamp, size and state; with ``expect``, repeat
        the scan for up to ``wait`` seconds until all those IDs answer."""
        deadline = time.monotonic() + wait
        while True:
            nodes = self.link.call("scan", {}, timeout=15.0)["nodes"]
            found = {n["id"] for n in nodes}
            if not expect or expect <= found or time.monotonic() >= deadline or self.cancelled():
                return nodes
            time.sleep(0.2)

    def scan_table(self, nodes: list[dict[str, Any]]) -> str:
        rows = [
            [
                n["name"],
                n["id"],
                format_stamp(n["stamp_ms"]),
                n["size"] or "-",
                n["sha256"][:8] or "-",
                n["state"],
            ]
            for n in nodes
        ]
        return format_table(rows, ["node", "ID", "time stamp", "bytes", "sha256", "program"])

    # -- plan -----------------------------------------------------------------------------------
    def plan(
        self, nodes: list[dict[str, Any]], mode: str, programs_dir: Path | None, file: Path | None = None
    ) -> list[PlanItem]:
        """``mode`` is ``incremental`` (-i), ``all`` (-a) or ``single`` (-s FILE)."""
        by_name = {n["name"]: n for n in nodes}
        items: list[PlanItem] = []
        if mode == "single":
            assert file is not None
            source, module = check_program_file(file)
            node = by_name.get(module)
            if node is None:
                names = ", ".join(f"{n['name']}={n['id']}" for n in nodes) or "none"
                raise UsageError(f"{file}: node {module!r} is not on the ring (the scan found: {names})")
            items.append(PlanItem(node, file, source, file_stamp(file), "download", "asked for"))
            return items
        assert programs_dir is not None
        files = check_program_dir(programs_dir, [n["name"] for n in nodes])
        for node in nodes:
            path = files.get(node["name"])
            if path is None:
                continue
            source, _ = check_program_file(path, node["name"])
            stamp = file_stamp(path)
            digest = program_digest(source)[:16]
            if mode == "all":
                items.append(PlanItem(node, path, source, stamp, "download", "all"))
            elif not node["stamp_ms"]:
                items.append(PlanItem(node, path, source, stamp, "download", "no program"))
            elif stamp > node["stamp_ms"] and digest != node["sha256"]:
                items.append(PlanItem(node, path, source, stamp, "download", "newer"))
            elif stamp > node["stamp_ms"]:
                items.append(PlanItem(node, path, source, stamp, "restamp", "newer time stamp, same content"))
            elif digest != node["sha256"]:
                items.append(
                    PlanItem(
                        node, path, source, stamp, "skip", "the node's program is newer (-a or -s sends it)"
                    )
                )
            else:
                items.append(PlanItem(node, path, source, stamp, "skip", "up to date"))
        return items

    # -- download -------------------------------------------------------------------------------
    def download(self, item: PlanItem, start: bool) -> Outcome:
        """Send one program through main; ``start`` (re)starts it once installed."""
        node = item.node
        outcome = Outcome(node, str(item.file), item.action, ok=False)
        request = {
            "target": node["id"],
            "source": item.source,
            "stamp_ms": item.stamp_ms,
            "compress": self.compress,
            "start": start,
            "restamp": item.action == "restamp",
        }
        t0 = time.monotonic()
        try:
            job = self.link.call("download", request, timeout=10.0)
        except (UsageError, TransportError) as exc:
            outcome.error = str(exc)
            return outcome
        outcome.bytes, outcome.chunks = job["bytes"], job["chunks"]
        label = f"{node['name']} ({node['id']})"
        state: dict[str, Any] = {}
        last_line = 0.0
        try:
            while True:
                try:
                    state = self.link.call(
                        "job", {"job": job["job"], "cancel": self.cancelled()}, timeout=5.0
                    )
                except TransportError as exc:
                    outcome.error = f"lost the PC link during the download: {exc}"
                    return outcome
                if state["done"]:
                    break
                if self.progress and time.monotonic() - last_line > 0.1:
                    self._bar(label, state, outcome, time.monotonic() - t0)
                    last_line = time.monotonic()
                time.sleep(self.poll_s)
        except KeyboardInterrupt:  # Ctrl-C: main drops the transfer (the node keeps its program)
            with contextlib.suppress(TransportError, UsageError):
                self.link.call("job", {"job": job["job"], "cancel": True}, timeout=2.0)
            raise
        outcome.seconds = time.monotonic() - t0
        outcome.extra["rounds"] = state.get("rounds", 0)
        if self.progress:
            self._bar(label, state, outcome, outcome.seconds, final=True)
        if state["error"] is None:
            outcome.ok = True
            outcome.started = start
            return outcome
        outcome.error = state["error"]
        if state.get("failed_command") == "ARCNET_START_PROGRAM":
            outcome.extra["installed"] = True
            outcome.error = f"installed, but its start failed: {state['error']}"
        return outcome

    def _bar(
        self, label: str, state: dict[str, Any], outcome: Outcome, seconds: float, final: bool = False
    ) -> None:
        chunks = max(outcome.chunks, 1)
        done = min(max(state["step"] - 1, 0), chunks) if not final else chunks
        fraction = done / chunks
        width = 30
        bar = "#" * round(fraction * width)
        sent = round(outcome.bytes * fraction)
        rate = sent / seconds if seconds > 0 else 0.0
        line = (
            f"\r  {label:<14} [{bar:<{width}}] {fraction:4.0%}  {sent / 1024:6.1f}/{outcome.bytes / 1024:.1f} KiB"
            f"  {rate / 1024:5.1f} KiB/s"
        )
        self.out.write(line + ("\n" if final else ""))
        self.out.flush()

    # -- start, stop, errors ----------------------------------------------------------------------
    def start(self, target: int | str | None = None) -> list[int]:
        return self._start_stop("start", target)

    def stop(self, target: int | str | None = None) -> list[int]:
        return self._start_stop("stop", target)

    def _start_stop(self, verb: str, target: int | str | None) -> list[int]:
        result = self.link.call(verb, {"target": target}, timeout=15.0)
        if result.get("error"):
            raise UsageError(result["error"])
        return list(result["nodes"])

    def errors(self, since: int = 0) -> list[dict[str, Any]]:
        return list(self.link.call("errors", {"since": since})["errors"])

    def last_error_number(self) -> int:
        errors = self.errors()
        return max((e["n"] for e in errors), default=0)


def report_table(outcomes: list[Outcome]) -> str:
    rows = []
    for o in outcomes:
        what = "sent" if o.action == "download" else "re-stamped" if o.action == "restamp" else o.action
        result = "ok" + (", started" if o.started else "") if o.ok else f"FAILED: {o.error}"
        rows.append([o.node["name"], o.node["id"], what, o.bytes, o.chunks, f"{o.seconds:.2f}", result])
    return format_table(rows, ["node", "ID", "program", "bytes", "chunks", "seconds", "result"])


def run_load(
    loader: Loader,
    *,
    mode: str | None,
    programs_dir: Path | None,
    file: Path | None = None,
    start: bool | str = False,
    stop: bool | str = False,
    expect: set[int] | None = None,
    wait: float = 0.0,
    settle_s: float = 0.6,
    quiet_scan: bool = False,
) -> dict[str, Any]:
    """The whole LOAD.EXE run: scan (printed), stop, downloads with progress, start, report.

    ``start``/``stop`` are True for the whole system or a node name/ID for one program.
    Returns a dict with the scan, the outcomes, started/stopped nodes and error reports;
    ``failed`` names every node that failed and why."""
    result: dict[str, Any] = {"outcomes": [], "failed": [], "errors": []}
    nodes = loader.scan(expect, wait)
    result["scan"] = nodes
    if not quiet_scan:
        loader.say(f"scan: {len(nodes)} node(s) on the ring")
        for line in loader.scan_table(nodes).splitlines():
            loader.say("  " + line)
    if expect:
        missing = sorted(expect - {n["id"] for n in nodes})
        if missing:
            result["failed"].append({"id": None, "error": f"node(s) {missing} did not answer the scan"})
            loader.say(f"node(s) {missing} did not answer the scan")
    since = loader.last_error_number()
    if stop:
        target = None if stop is True else stop
        result["stopped"] = loader.stop(target)
        loader.say(f"stopped: {_names(nodes, result['stopped'])}")
    items = loader.plan(nodes, mode, programs_dir, file) if mode else []
    sending = [i for i in items if i.action != "skip"]
    if mode:
        current = [i.node["name"] for i in items if i.action == "skip" and i.reason == "up to date"]
        loader.say(
            f"{len(sending)} program(s) to send"
            + (f", {len(current)} up to date ({', '.join(current)})" if current else "")
        )
        for item in items:
            if item.action == "skip" and item.reason != "up to date":
                loader.say(f"{item.node['name']} ({item.node['id']}): not sent: {item.reason}")
    t0 = time.monotonic()
    for item in sending:
        if loader.cancelled():
            break
        restart = item.node["state"] in ("RUNNING", "SETTING_UP", "FAILED") and start is not True
        outcome = loader.download(item, start=restart)
        result["outcomes"].append(outcome)
        if not outcome.ok:
            result["failed"].append(
                {"id": outcome.node["id"], "name": outcome.node["name"], "error": outcome.error}
            )
        if not loader.progress:
            loader.say(
                f"{item.node['name']} ({item.node['id']}): "
                + (
                    f"{outcome.bytes} bytes in {outcome.chunks} chunks, {outcome.seconds:.2f} s"
                    + (", restarted" if outcome.started else "")
                    if outcome.ok
                    else f"FAILED: {outcome.error}"
                )
            )
    result["seconds"] = time.monotonic() - t0
    if loader.cancelled():
        loader.say("cancelled")
        result["cancelled"] = True
        return result
    if start:
        target = None if start is True else start
        result["started"] = loader.start(target)
        loader.say(f"started: {_names(nodes, result['started'])}")
    if start or any(o.started for o in result["outcomes"]):
        time.sleep(settle_s)  # a program that raises at once reports through ARCNET_ERROR
    errors = loader.errors(since)
    result["errors"] = errors
    for error in errors:
        loader.say(f"ARCNET_ERROR from {error['name']} ({error['node']}, {error['about']}): {error['text']}")
        if not any(f.get("id") == error["node"] for f in result["failed"]):
            result["failed"].append({"id": error["node"], "name": error["name"], "error": error["text"]})
    if result["outcomes"]:
        sent = sum(o.bytes for o in result["outcomes"] if o.ok)
        loader.say(
            f"changed: {sum(o.ok for o in result['outcomes'])} of {len(result['outcomes'])} program(s), "
            f"{sent} bytes in {result['seconds']:.1f} s"
        )
        for line in report_table(result["outcomes"]).splitlines():
            loader.say("  " + line)
    elif mode:
        loader.say("nothing to send: " + nothing_sent(items, programs_dir, nodes))
    for failure in result["failed"]:
        if failure.get("id") is not None:
            loader.say(f"FAILED: {failure['name']} ({failure['id']}): {failure['error']}")
    return result


def nothing_sent(items: list[PlanItem], programs_dir: Path | None, nodes: list[dict[str, Any]]) -> str:
    """Why ``load -i``/``-a`` sent nothing: every program up to date, or no program to send at all
    (an empty directory, or none of its files for a node on the ring)."""
    if items:
        if all(i.reason == "up to date" for i in items):
            return "every program is up to date"
        return "no program there is newer than its node's"
    held = programs_in(programs_dir) if programs_dir is not None else []
    if not held:
        return f"{programs_dir} holds no programs (one <node>.py per node)"
    ring = ", ".join(n["name"] for n in nodes) or "none"
    shown = ", ".join(held[:8]) + (", ..." if len(held) > 8 else "")
    return f"no program in {programs_dir} is for a node on the ring ({shown}; the ring: {ring})"


def _names(nodes: list[dict[str, Any]], ids: list[int]) -> str:
    names = {n["id"]: n["name"] for n in nodes}
    return ", ".join(f"{names.get(i, f'node{i}')} ({i})" for i in ids) or "none"
