"""Processes a test starts, and the guarantee they are gone afterwards; the repository's paths."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
TOKENRING = [sys.executable, "-m", "tokenring"]


def run_tokenring(*args: str, timeout: float = 60.0, **kwargs) -> subprocess.CompletedProcess:
    """Run one ``tokenring`` command to completion (text output captured), as a user would."""
    return subprocess.run([*TOKENRING, *args], capture_output=True, text=True, timeout=timeout, **kwargs)


def pid_alive(pid: int) -> bool:
    """True if ``pid`` exists and is not a zombie."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state != "Z"


def wait_gone(pids: list[int], timeout: float) -> list[int]:
    deadline = time.monotonic() + timeout
    alive = [p for p in pids if pid_alive(p)]
    while alive and time.monotonic() < deadline:
        time.sleep(0.05)
        alive = [p for p in alive if pid_alive(p)]
    return alive


class Processes:
    """Starts processes for a test and guarantees they are gone afterwards."""

    def __init__(self) -> None:
        self.started: list[subprocess.Popen] = []
        self.extra_pids: set[int] = set()

    def start(self, args: list[str], **kwargs) -> subprocess.Popen:
        kwargs.setdefault("stdout", subprocess.PIPE)
        kwargs.setdefault("stderr", subprocess.STDOUT)
        kwargs.setdefault("text", True)
        kwargs.setdefault("cwd", REPO)
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        env.update(kwargs.pop("env", {}) or {})
        proc = subprocess.Popen(args, env=env, **kwargs)
        self.started.append(proc)
        return proc

    def tokenring(self, *args: str, **kwargs) -> subprocess.Popen:
        return self.start([*TOKENRING, *args], **kwargs)

    def watch(self, pids: list[int]) -> None:
        """Also make sure these PIDs (e.g. a launcher's children) are gone at teardown."""
        self.extra_pids.update(pids)

    def unread_output(self, limit: int = 16384) -> str:
        """What the still-open pipes hold (without blocking): the story of a failed test."""
        parts = []
        for proc in self.started:
            stream = proc.stdout
            if stream is None or stream.closed:
                continue
            try:
                os.set_blocking(stream.fileno(), False)
                text = stream.read() or ""
            except (OSError, ValueError, TypeError):
                continue
            if text:
                parts.append(f"--- pid {proc.pid}: {' '.join(map(str, proc.args))[:100]}\n{text[-limit:]}")
        return "\n".join(parts)

    def cleanup(self) -> list[str]:
        leaked: list[str] = []
        for proc in self.started:
            if proc.poll() is None:
                leaked.append(f"pid {proc.pid}: {' '.join(map(str, proc.args))[:120]}")
                with contextlib.suppress(ProcessLookupError):
                    proc.send_signal(signal.SIGTERM)
        for proc in self.started:
            try:
                proc.wait(3)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(3)
            for stream in (proc.stdout, proc.stderr):
                if stream is not None:
                    stream.close()
        for pid in wait_gone(sorted(self.extra_pids), 2.0):
            leaked.append(f"child pid {pid}")
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        return leaked
