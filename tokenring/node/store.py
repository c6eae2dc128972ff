"""A node's program store: the program it was given, kept across restarts (the seed's
battery-backed RAM), and the time stamps ``load -i`` compares."""

from __future__ import annotations

import json
import logging
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

from tokenring import runtime
from tokenring.node.program import program_sha256

log = logging.getLogger("tokenring.system")

STORE_ENV = "TOKENRING_STORE"


def now_ms() -> int:
    return int(runtime.current().time() * 1000)


def file_stamp(path: Path) -> int:
    """A program file's time stamp (version): its modification time in ms."""
    return int(path.stat().st_mtime_ns // 1_000_000)


def format_stamp(stamp_ms: int) -> str:
    if not stamp_ms:
        return "-"
    return time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(stamp_ms / 1000)) + f".{stamp_ms % 1000:03d}"


def default_store_root() -> Path:
    """``$TOKENRING_STORE``, else ``$XDG_STATE_HOME/tokenring``, else ``~/.local/state/tokenring``."""
    env = os.environ.get(STORE_ENV)
    if env:
        return Path(env)
    state = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(state) / "tokenring"


@dataclass
class Installed:
    """A node's installed program: its source, digest, time stamp and (once compiled) class."""

    source: bytes
    digest: bytes
    stamp_ms: int
    filename: str
    program_class: type | None = None

    @property
    def size(self) -> int:
        return len(self.source)


class ProgramStore:
    """One node's battery-backed RAM: ``<dir>/program.json`` names ``<dir>/<sha12>/<module>.py``.

    A new program is written into its own version directory first; rewriting ``program.json``
    (atomically, ``os.replace``) is the commit, then older versions are removed. A store whose
    file does not match its recorded hash is reported and ignored (the node boots bare)."""

    META = "program.json"

    def __init__(self, directory: Path | None, module: str) -> None:
        self.directory = directory
        self.module = module

    def load(self) -> Installed | None:
        if self.directory is None:
            return None
        meta_path = self.directory / self.META
        try:
            meta = json.loads(meta_path.read_text(encoding="utf-8"))
            file = self.directory / meta["file"]
            source = file.read_bytes()
            digest = bytes.fromhex(meta["sha256"])
            stamp = int(meta["stamp_ms"])
        except FileNotFoundError:
            return None
        except (OSError, ValueError, KeyError, TypeError) as exc:
            log.warning("program store %s is unreadable (%s): booting bare", meta_path, exc)
            return None
        if program_sha256(source) != digest:
            log.warning("program store %s: %s does not match its hash: booting bare", meta_path, file)
            return None
        return Installed(source, digest, stamp, str(file))

    def save(self, source: bytes, digest: bytes, stamp_ms: int) -> str:
        """Install ``source``; returns the stored file's path. Raises OSError."""
        if self.directory is None:
            return f"<{self.module}>"
        version = self.directory / digest.hex()[:12]
        version.mkdir(parents=True, exist_ok=True)
        file = version / f"{self.module}.py"
        tmp = file.with_suffix(".py.tmp")
        tmp.write_bytes(source)
        os.replace(tmp, file)
        meta = {
            "module": self.module,
            "file": str(file.relative_to(self.directory)),
            "sha256": digest.hex(),
            "stamp_ms": stamp_ms,
            "size": len(source),
            "installed_at": time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime(runtime.current().time())),
        }
        meta_tmp = self.directory / (self.META + ".tmp")
        meta_tmp.write_text(json.dumps(meta, indent=1) + "\n", encoding="utf-8")
        os.replace(meta_tmp, self.directory / self.META)
        for other in self.directory.iterdir():
            if other.is_dir() and other != version:
                shutil.rmtree(other, ignore_errors=True)
        return str(file)


# ---------------------------------------------------------------------------------------------
# issuer side: transactions


def check_store_root(root: Path) -> Path:
    """Make sure the program store root can hold programs, before any node starts: it is
    created if missing; a root that cannot be created or written is one clear error. Writing
    is tried, not asked: ``os.access`` says yes to root everywhere, ``/proc`` included, where a
    node found out only when its first download failed."""
    import tempfile

    from tokenring.errors import UsageError

    if root.exists() and not root.is_dir():
        raise UsageError(f"--store {root}: not a directory")
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"--store {root}: cannot create it: {exc.strerror}") from None
    try:  # what a node does with it: a folder per ring and node, a file in it
        probe = Path(tempfile.mkdtemp(prefix=".tokenring-probe-", dir=root))
        try:
            (probe / "program.json").write_bytes(b"{}")
        finally:
            shutil.rmtree(probe, ignore_errors=True)
    except OSError as exc:
        raise UsageError(f"--store {root}: cannot write in it: {exc.strerror or exc}") from None
    return root
