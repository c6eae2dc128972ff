"""Sub-commands of ``tokenring``: every module here with ``add_parser(sub)`` and ``run(args)``
becomes ``tokenring <module name>`` (underscores read as dashes). Add a file to add a verb."""

from __future__ import annotations

import importlib
import pkgutil
from types import ModuleType


def discover() -> list[ModuleType]:
    """All command modules, in a stable order (``up`` first, then alphabetical)."""
    names = sorted(m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_"))
    names.sort(key=lambda n: (n != "up", n))
    return [importlib.import_module(f"{__name__}.{n}") for n in names]
