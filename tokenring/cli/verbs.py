"""``tokenring``'s verbs in its parser: each one listed by its one-line help, its own parser (its
options, and what they import) built only once the command line names it.

A verb module (:mod:`tokenring.cli.commands`, an extension's ``commands()``) that gives its help as
``HELP`` promises that its ``add_parser(sub)`` adds exactly one verb, named after the module
(underscores as dashes), with ``help=HELP``: ``tokenring --help`` then shows it without calling
``add_parser``. A module without ``HELP`` is built at once, as it always was.
"""

from __future__ import annotations

import argparse
import importlib
import os
from collections.abc import Sequence
from importlib.machinery import all_suffixes
from types import ModuleType
from typing import TYPE_CHECKING, Any, cast

from tokenring.errors import UsageError

if TYPE_CHECKING:
    _SubParsers = argparse._SubParsersAction[argparse.ArgumentParser]
else:
    _SubParsers = argparse._SubParsersAction


def module_names(package: ModuleType) -> list[str]:
    """The modules of ``package`` (its files and sub-packages), private ones (``_name``) left out,
    by name; nothing is imported (:func:`pkgutil.iter_modules` would import :mod:`inspect` for it)."""
    suffixes = all_suffixes()
    found: set[str] = set()
    for directory in package.__path__:
        try:
            entries = list(os.scandir(directory))
        except OSError:
            continue
        for entry in entries:
            if entry.is_dir():
                if os.path.exists(os.path.join(entry.path, "__init__.py")):
                    found.add(entry.name)
                continue
            found.update(entry.name[: -len(s)] for s in suffixes if entry.name.endswith(s))
    return sorted(name for name in found if name.isidentifier() and not name.startswith("_"))


def verb_modules(package: ModuleType) -> list[ModuleType]:
    """Every module of ``package`` (:func:`module_names`), imported: an application's verbs, each a
    module like :mod:`tokenring.cli.commands`' (``add_parser``, ``run`` and ``HELP``)."""
    return [importlib.import_module(f"{package.__name__}.{name}") for name in module_names(package)]


def verb_name(module: ModuleType) -> str:
    """The verb a module adds: its own name, underscores read as dashes."""
    return module.__name__.rpartition(".")[2].replace("_", "-")


#: the parser of a verb not built yet (parsing builds it before it is used)
_UNBUILT = cast(argparse.ArgumentParser, None)


class Verbs(_SubParsers):
    """The subcommands' action (``add_subparsers(action=Verbs)``): a verb with a ``HELP`` is a
    placeholder until parsing picks it; then its module's ``add_parser`` builds it in its place."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._unbuilt: dict[str, ModuleType] = {}

    def build_verb(self, module: ModuleType) -> list[str]:
        """Build ``module``'s verbs now (its ``add_parser``); the names it added."""
        before = set(self._name_parser_map)
        module.add_parser(self)
        return [name for name in self._name_parser_map if name not in before]

    def add_verb(self, module: ModuleType) -> list[str]:
        """List ``module``'s verb by its ``HELP``, built when chosen (built now if it has no
        ``HELP``); the names it added."""
        summary = getattr(module, "HELP", None)
        if not isinstance(summary, str):
            return self.build_verb(module)
        name = verb_name(module)
        if name in self._name_parser_map:
            raise argparse.ArgumentError(self, f"conflicting subparser: {name}")  # as add_parser
        # its row in the help and its name among the choices, as add_parser makes them, but no
        # parser yet: an ArgumentParser each (its -h, its groups) is most of a listing's cost
        self._choices_actions.append(self._ChoicesPseudoAction(name, (), summary))
        self._name_parser_map[name] = _UNBUILT
        self._unbuilt[name] = module
        return [name]

    def _build(self, name: str) -> None:
        """Replace ``name``'s placeholder by the parser its module builds."""
        module = self._unbuilt.pop(name, None)
        if module is None:
            return
        built = Verbs(option_strings=[], prog=self._prog_prefix, parser_class=self._parser_class)
        added = built.build_verb(module)
        if added != [name]:
            raise UsageError(
                f"{module.__name__} has HELP but adds {', '.join(added) or 'no verb'}, not {name!r}: "
                "a module with HELP adds its own verb only"
            )
        self._name_parser_map[name] = built._name_parser_map[name]

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: str | Sequence[Any] | None,
        option_string: str | None = None,
    ) -> None:
        if isinstance(values, Sequence) and values and isinstance(values[0], str):
            self._build(values[0])
        super().__call__(parser, namespace, values, option_string)
