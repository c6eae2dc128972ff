"""A small disk for full-disk tests: a tmpfs of a few pages, mounted for one test and unmounted
after it (mounting needs root: without it the test is skipped, saying why)."""

from __future__ import annotations

import contextlib
import os
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

PAGE = 4096


@contextlib.contextmanager
def small_disk(where: Path, size: int) -> Iterator[Path]:
    """``where`` (made if missing) as a tmpfs of ``size`` bytes (whole pages) while the block runs."""
    where.mkdir(parents=True, exist_ok=True)
    mount = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)], capture_output=True, text=True
    )
    if mount.returncode != 0:
        if os.geteuid() != 0:
            pytest.skip(f"mounting a tmpfs needs root: {mount.stderr.strip()}")
        raise RuntimeError(f"mount tmpfs on {where} failed: {mount.stderr.strip()}")
    try:
        yield where
    finally:
        subprocess.run(["umount", "-l", str(where)], check=True)


def fill(disk: Path, leave: int = 0) -> Path:
    """Fill ``disk`` with one file until fewer than ``leave`` + one page are free; that file."""
    filler = disk / ".filler"
    with filler.open("wb", buffering=0) as out:
        while True:
            info = os.statvfs(disk)
            spare = info.f_bavail * info.f_frsize - leave
            if spare < PAGE:
                break
            try:
                out.write(b"\0" * (min(spare, 1 << 20) // PAGE * PAGE))
            except OSError:
                break
    return filler


def listing(directory: Path) -> list[str]:
    """Every name in ``directory`` (hidden ones too), but the filler."""
    return sorted(p.name for p in directory.iterdir() if p.name != ".filler")
