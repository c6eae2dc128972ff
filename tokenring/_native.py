"""The compiled token path (``_tokenpath.c``), where it was built, and what uses it outside the
node: the transports' subscriber callbacks (:func:`payload_call`)."""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

log = logging.getLogger("tokenring.node")


def _load_native() -> ModuleType | None:
    """The compiled token path module, or None (not built, or ``TOKENRING_NATIVE=0``)."""
    if os.environ.get("TOKENRING_NATIVE", "1") == "0":
        return None
    try:
        from tokenring import _tokenpath  # type: ignore[attr-defined]
    except ImportError:
        return None
    source = Path(__file__).with_name("_tokenpath.c")
    library = Path(_tokenpath.__file__)
    if source.exists() and source.stat().st_mtime > library.stat().st_mtime:
        log.warning(
            "%s is newer than its build %s; the token path runs in Python until it is rebuilt "
            "(pip install -e .)",
            source,
            library.name,
        )
        return None
    module: ModuleType = _tokenpath
    return module


def payload_call(handler: Callable[[bytes], object]) -> Callable[[Any], object]:
    """A Zenoh subscriber callback: ``handler(sample.payload.to_bytes())``. In C where the token
    path is: a Python function here would be the one frame of bytecode left per hop."""
    if compiled is not None:
        call: Callable[[Any], object] = compiled.PayloadCall(handler)
        return call

    def python_call(sample: Any) -> object:
        return handler(sample.payload.to_bytes())

    return python_call


#: the compiled module, or None where the token path runs in Python
compiled: ModuleType | None = _load_native()
