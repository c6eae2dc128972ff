"""Sub-commands of ``tokenring``: every module here with ``add_parser(sub)`` and ``run(args)``
becomes ``tokenring <module name>`` (underscores read as dashes). Add a file to add a verb.

A verb's module is imported whenever ``tokenring --help`` lists it, so it stays cheap to import:
at module level the standard library's light modules (argparse, sys, os, ...) and the CLI's own
argparse pieces (:mod:`tokenring.cli.args`) only, and its one-line help as ``HELP`` (which its
``add_parser`` passes as ``help=``; see :mod:`tokenring.cli.verbs`). ``add_parser`` runs only when
the command line names the verb and imports what its options show (choices, defaults); ``run``
imports what the verb does (Zenoh, numpy, the launcher, ...)."""

from __future__ import annotations

import importlib
import sys
from types import ModuleType

from tokenring.cli.verbs import module_names


def names() -> list[str]:
    """The verbs' module names, in a stable order (``up`` first, then alphabetical); none imported."""
    return sorted(module_names(sys.modules[__name__]), key=lambda n: (n != "up", n))


def verb_module(name: str) -> ModuleType:
    """The verb module ``name`` (one of :func:`names`); not ``load``, which is a verb's name."""
    return importlib.import_module(f"{__name__}.{name}")
