"""Reading an operator's file without letting it hang, exhaust or crash the tool.

Every file a user names (protocol.yaml, a world, a scenario, a configuration, an action file, a
program, a map) is read through :func:`read_text` or :func:`read_bytes`, which refuse — with one
line naming the file and what is wrong — a missing file, a directory, a FIFO or device (reading
one may block for ever or never end: ``/dev/zero``), a file over the size that kind of file can
sensibly have, and text that is not UTF-8. Nothing is parsed before these checks pass.
"""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from collections.abc import Callable
from pathlib import Path

from tokenring.errors import TokenRingError, UsageError

KIB = 1024
MIB = 1024 * KIB
#: the largest file of each kind read whole (the real ones are kilobytes)
LIMITS = {
    "protocol file": 1 * MIB,
    "YAML file": 4 * MIB,
    "program file": 16 * MIB,
    "map file": 16 * MIB,
    "file": 16 * MIB,
}

ErrorFactory = Callable[[str], TokenRingError]


def _kind(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def read_bytes(
    path: str | os.PathLike[str],
    what: str = "file",
    error: ErrorFactory = UsageError,
    limit: int | None = None,
) -> bytes:
    """The whole content of the regular file ``path`` (at most ``limit`` bytes, by default the
    limit of ``what``); ``error(message)`` is raised with the path in front otherwise."""
    file = Path(path)
    limit = LIMITS.get(what, LIMITS["file"]) if limit is None else limit
    try:
        # O_NONBLOCK: opening a FIFO that nobody writes must not hang before we can look at it
        fd = os.open(file, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise error(f"{file}: no such {what}") from None
    except IsADirectoryError:
        raise error(f"{file}: is a directory, not a {what}") from None
    except OSError as exc:
        raise error(f"{file}: cannot read: {exc.strerror}") from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise error(f"{file}: is {_kind(info.st_mode)}, not a {what}")
        if info.st_size > limit:
            raise error(f"{file}: {info.st_size} bytes; a {what} is at most {limit} bytes")
        chunks = []
        left = limit + 1  # a file that grows while we read is cut here, and refused below
        while left > 0:
            try:
                chunk = os.read(fd, min(left, MIB))
            except OSError as exc:
                raise error(f"{file}: cannot read: {exc.strerror}") from None
            if not chunk:
                break
            chunks.append(chunk)
            left -= len(chunk)
        data = b"".join(chunks)
        if len(data) > limit:
            raise error(f"{file}: over {limit} bytes; a {what} is at most {limit} bytes")
        return data
    finally:
        os.close(fd)


def read_text(
    path: str | os.PathLike[str],
    what: str = "file",
    error: ErrorFactory = UsageError,
    limit: int | None = None,
) -> str:
    """:func:`read_bytes`, decoded as UTF-8 (a byte that is not: the error says where)."""
    data = read_bytes(path, what, error, limit)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise error(
            f"{Path(path)}:{line}: not UTF-8 text (byte {exc.start}: 0x{data[exc.start]:02x})"
        ) from None


def check_output(
    path: str | os.PathLike[str],
    inputs: tuple[str | os.PathLike[str], ...] = (),
    *,
    force: bool = False,
    directory: bool = False,
    error: ErrorFactory = UsageError,
) -> Path:
    """Check an output path before any work is done: never one of the ``inputs``, not an
    existing file unless ``force``, its folder present and writable. ``directory``: the output
    is a folder of files (it may exist; it must not be a file)."""
    out = Path(path)
    for source in inputs:
        src = Path(source)
        if src.exists() and out.exists() and os.path.samefile(src, out):
            raise error(f"{out}: is the input {src}; write the output to another path")
    if directory:
        if out.exists() and not out.is_dir():
            raise error(f"{out}: exists and is not a directory")
        parent = out if out.exists() else out.parent
    else:
        if out.is_dir():
            raise error(f"{out}: is a directory, not a file to write")
        if out.exists() and not force:
            raise error(f"{out}: exists; give --force to replace it, or another path")
        parent = out.parent
    parent = parent if str(parent) else Path(".")
    if not parent.is_dir():
        raise error(f"{out}: its folder {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise error(f"{out}: its folder {parent} is not writable")
    return out


def write_atomically(path: str | os.PathLike[str], data: bytes | str) -> None:
    """Write ``data`` to ``path`` through a temporary file in its folder and a rename: a reader
    (or a crash) never sees half a file, and a failed write leaves the old one."""
    out = Path(path)
    raw = data.encode("utf-8") if isinstance(data, str) else data
    fd, temp = tempfile.mkstemp(prefix=f".{out.name}.", dir=out.parent if str(out.parent) else ".")
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(raw)
        os.replace(temp, out)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temp)
        raise
