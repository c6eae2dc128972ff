"""Reading an operator's file without letting it hang, exhaust or crash the tool.

Every file a user names (protocol.yaml, a world, a scenario, a configuration, an action file, a
program, a map) is read through :func:`read_text` or :func:`read_bytes`, which refuse — with one
line naming the file and what is wrong — a missing file, a directory, a FIFO or device (reading
one may block for ever or never end: ``/dev/zero``), a file over the size that kind of file can
sensibly have, and text that is not UTF-8. Nothing is parsed before these checks pass.
"""

from __future__ import annotations

import os
import stat
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
