"""Which runtime is in force in this process: the real one unless a simulation is using another."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

from tokenring.runtime.real import RealRuntime

_current: Any = RealRuntime()


def current() -> Any:
    """The runtime in force: the real one unless a simulation is :func:`using` another."""
    return _current


@contextlib.contextmanager
def using(runtime: Any) -> Iterator[Any]:
    """Make ``runtime`` the one in force for the duration (a simulation: one per process)."""
    global _current
    before, _current = _current, runtime
    try:
        yield runtime
    finally:
        _current = before
