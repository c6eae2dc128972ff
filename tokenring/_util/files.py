"""Reading an operator's file without letting it hang, exhaust or crash the tool.

Every file a user names (protocol.yaml, a world, a scenario, a configuration, an action file, a
program, a map) is read through :func:`read_text` or :func:`read_bytes`, which refuse — with one
line naming the file and what is wrong — a missing file, a directory, a FIFO or device (reading
one may block for ever or never end: ``/dev/zero``), a file over the size that kind of file can
sensibly have, and text that is not UTF-8. Nothing is parsed before these checks pass.

Text as Windows editors save it reads as any other: a UTF-8 byte-order mark is dropped and
the parsers take CRLF line ends; UTF-16 or UTF-32 text (which starts with its own mark) is
refused by name.
"""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from collections.abc import Callable, Iterator
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

#: builds the error to raise: ``error(where, problem)``, ``where`` the path (or ``path:line``)
ErrorFactory = Callable[[str, str], TokenRingError]


def message_error(kind: Callable[[str], TokenRingError]) -> ErrorFactory:
    """An :data:`ErrorFactory` for error classes built from one message: ``kind("where: problem")``."""
    return lambda where, problem: kind(f"{where}: {problem}")


USAGE_ERROR = message_error(UsageError)


def option_error(option: str) -> ErrorFactory:
    """An :data:`ErrorFactory` whose message starts with the option that named the file
    (``--map-out FILE: exists; ...``): the user reads which of their words it is about."""
    return lambda where, problem: UsageError(f"{option} {where}: {problem}")


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


def _open_checked(file: Path, what: str, error: ErrorFactory, limit: int) -> int:
    """A descriptor of ``file`` once it is known to be a regular file within ``limit`` bytes."""
    try:
        # O_NONBLOCK: opening a FIFO that nobody writes must not hang before we can look at it
        fd = os.open(file, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise error(str(file), f"no such {what}") from None
    except IsADirectoryError:
        raise error(str(file), f"is a directory, not a {what}") from None
    except OSError as exc:
        raise error(str(file), f"cannot read: {exc.strerror}") from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise error(str(file), f"is {_kind(info.st_mode)}, not a {what}")
        if info.st_size > limit:
            raise error(str(file), f"{info.st_size} bytes; a {what} is at most {limit} bytes")
    except BaseException:
        os.close(fd)
        raise
    return fd


def _limit(what: str, limit: int | None) -> int:
    return LIMITS.get(what, LIMITS["file"]) if limit is None else limit


def check_input(
    path: str | os.PathLike[str],
    what: str = "file",
    error: ErrorFactory = USAGE_ERROR,
    limit: int | None = None,
) -> Path:
    """The checks of :func:`read_bytes` without reading (for a file a library reads itself)."""
    file = Path(path)
    os.close(_open_checked(file, what, error, _limit(what, limit)))
    return file


def read_bytes(
    path: str | os.PathLike[str],
    what: str = "file",
    error: ErrorFactory = USAGE_ERROR,
    limit: int | None = None,
) -> bytes:
    """The whole content of the regular file ``path`` (at most ``limit`` bytes, by default the
    limit of ``what``); else ``error(path, problem)`` is raised."""
    file = Path(path)
    limit = _limit(what, limit)
    fd = _open_checked(file, what, error, limit)
    try:
        chunks = []
        left = limit + 1  # a file that grows while we read is cut here, and refused below
        while left > 0:
            try:
                chunk = os.read(fd, min(left, MIB))
            except OSError as exc:
                raise error(str(file), f"cannot read: {exc.strerror}") from None
            if not chunk:
                break
            chunks.append(chunk)
            left -= len(chunk)
        data = b"".join(chunks)
        if len(data) > limit:
            raise error(str(file), f"over {limit} bytes; a {what} is at most {limit} bytes")
        return data
    finally:
        os.close(fd)


#: byte-order marks of the Unicode encodings that are not UTF-8 (UTF-32's first: it begins like UTF-16's)
_OTHER_UNICODE = (
    (b"\xff\xfe\x00\x00", "UTF-32"),
    (b"\x00\x00\xfe\xff", "UTF-32"),
    (b"\xff\xfe", "UTF-16"),
    (b"\xfe\xff", "UTF-16"),
)


def read_text(
    path: str | os.PathLike[str],
    what: str = "file",
    error: ErrorFactory = USAGE_ERROR,
    limit: int | None = None,
) -> str:
    """:func:`read_bytes`, decoded as UTF-8 without a leading byte-order mark (a byte that is
    not UTF-8: the error says where; UTF-16 or UTF-32 text: the error names the encoding)."""
    data = read_bytes(path, what, error, limit)
    for mark, encoding in _OTHER_UNICODE:
        if data.startswith(mark):
            raise error(
                str(Path(path)), f"is {encoding} text (it starts with a byte-order mark); save it as UTF-8"
            )
    try:
        return data.decode("utf-8").removeprefix("\ufeff")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise error(
            f"{Path(path)}:{line}", f"not UTF-8 text (byte {exc.start}: 0x{data[exc.start]:02x})"
        ) from None


def check_output(
    path: str | os.PathLike[str],
    inputs: tuple[str | os.PathLike[str], ...] = (),
    *,
    force: bool = False,
    directory: bool = False,
    error: ErrorFactory = USAGE_ERROR,
) -> Path:
    """Check an output path before any work is done: never one of the ``inputs``, not an
    existing file unless ``force``, its folder present and writable. ``directory``: the output
    is a folder of files (it may exist; it must not be a file)."""
    out = Path(path)
    for source in inputs:
        src = Path(source)
        if src.exists() and out.exists() and os.path.samefile(src, out):
            raise error(str(out), f"is the input {src}; write the output to another path")
    if directory:
        if out.exists() and not out.is_dir():
            raise error(str(out), "exists and is not a directory")
        parent = out if out.exists() else out.parent
    else:
        if out.is_dir():
            raise error(str(out), "is a directory, not a file to write")
        if out.exists() and not force:
            raise error(str(out), "exists; give --force to replace it, or another path")
        parent = out.parent
    parent = parent if str(parent) else Path(".")
    if not parent.is_dir():
        raise error(str(out), f"its folder {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise error(str(out), f"its folder {parent} is not writable")
    return out


def write_failed(
    path: str | os.PathLike[str], exc: OSError, error: ErrorFactory = USAGE_ERROR
) -> TokenRingError:
    """The error for a write to ``path`` that failed (a full disk, a quota, an I/O error)."""
    return error(str(path), f"cannot write: {exc.strerror or exc}")


@contextlib.contextmanager
def replacing(path: str | os.PathLike[str], error: ErrorFactory | None = USAGE_ERROR) -> Iterator[Path]:
    """A temporary path beside ``path`` to write; renamed over ``path`` when the block ends
    normally, removed if it raises: a reader (or a crash) never sees half a file, and a failed
    write leaves the old one. An :class:`OSError` of the block or of the rename (a full disk)
    becomes ``error(path, "cannot write: ...")``, one line (``error=None``: raised as it is)."""
    out = Path(path)
    try:
        fd, name = tempfile.mkstemp(prefix=f".{out.name}.", dir=out.parent if str(out.parent) else ".")
    except OSError as exc:
        if error is None:
            raise
        raise write_failed(out, exc, error) from None
    os.close(fd)
    temp = Path(name)
    try:
        yield temp
        _sync(temp)  # the data is on the disk before the name is: a crash never leaves an empty file
        os.replace(temp, out)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            temp.unlink()
        if isinstance(exc, OSError) and error is not None:
            raise write_failed(out, exc, error) from None
        raise


def _sync(path: Path) -> None:
    """fsync ``path``'s data (a file system that reports a full disk only then reports it here)."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_atomically(
    path: str | os.PathLike[str], data: bytes | str, error: ErrorFactory | None = USAGE_ERROR
) -> None:
    """Write ``data`` to ``path`` through :func:`replacing` (a failed write: ``error``)."""
    with replacing(path, error) as temp:
        temp.write_bytes(data.encode("utf-8") if isinstance(data, str) else data)
