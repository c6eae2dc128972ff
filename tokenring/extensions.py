"""The one seam through which an application (the robot) plugs into the ring.

The ring knows nothing of robots, worlds or maps. An application registers an :class:`Extension`
under the entry point group ``tokenring.extensions`` (in its ``pyproject.toml``)::

    [project.entry-points."tokenring.extensions"]
    robot = "modules.plugin:RobotExtension"

and the ring asks every registered extension, and nothing else, for

* **verbs** — extra ``tokenring`` subcommands: modules with ``add_parser(sub)`` and ``run(args)``,
  exactly like :mod:`tokenring.cli.commands`;
* **programs** — the directory holding the programs for protocol.yaml's nodes (``up``, ``load``);
* **up** — options of ``tokenring up``, checked before anything starts, the optional nodes they
  start, and an :class:`UpPlan`:
  services started beside the nodes (a world simulator), how much faster emulated time runs,
  environment for the nodes, work to do once the ring runs (a mission);
* **sim** — options of ``tokenring sim`` and a :class:`SimPlan`: the optional nodes, speed-up,
  timing profile and environment, and a scenario run inside the simulation (its world, its
  programs on the simulated nodes, its mission);
* **load** — options of ``tokenring load`` and a step after it (the robot's map upload, the
  seed's ``LOAD.EXE -u``);
* **hardware** — the client a node's program gets as ``self.hw``;
* **resident program** — a node's own part of its OS, run from boot while no user program runs
  (:mod:`tokenring.node.resident`; the robot's LCD menu before the programs start);
* **feed** — its own topics in a live feed (:mod:`tokenring.observe.feed`);
* **web** — panels (static files, one ES module each), buttons and a keyboard of the web view
  (:mod:`tokenring.web`), and options of ``tokenring web``.

``TOKENRING_EXTENSIONS`` limits which are loaded: a comma-separated list of names, empty for
none (the bare ring: what the ring's own tests of a non-robot system run).
"""

from __future__ import annotations

import argparse
import os
import typing
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any

from tokenring.errors import UsageError

if TYPE_CHECKING:
    import zenoh

    from tokenring.contract.protocol import Protocol
    from tokenring.host.launcher import Launcher
    from tokenring.host.services import ServicePlan
    from tokenring.node.resident import ResidentProgram
    from tokenring.observe.feed import FeedSource

GROUP = "tokenring.extensions"
ENV = "TOKENRING_EXTENSIONS"


@dataclass
class UpPlan:
    """What an extension adds to one ``tokenring up``."""

    services: list[ServicePlan] = field(default_factory=list)
    #: emulated time runs this many times faster; the emulated wire follows it
    speedup: float = 1.0
    #: environment for the node processes (set before the launcher starts them)
    env: dict[str, str] = field(default_factory=dict)
    #: called once the nodes run their programs; may stop the launcher itself
    on_started: Callable[[Launcher], None] | None = None
    #: asked at the end: a message if the application's job failed (exit code 1)
    failure: Callable[[], str | None] | None = None
    #: seconds past ``--duration`` before the launcher gives up (the job stops the ring itself)
    grace_s: float = 0.0
    #: a hardware timing profile (``--profile``) the application's options imply, used unless
    #: the user gave ``--profile`` or ``--bitrate``
    profile: str | None = None
    #: ``up --no-start``: a line saying how a user starts the programs on this application
    #: (beside ``tokenring load --start``), given the launcher
    start_hint: Callable[[Launcher], str | None] | None = None


@dataclass
class SimPlan:
    """What an extension adds to one ``tokenring sim`` (the ring in virtual time)."""

    #: optional nodes of protocol.yaml run beside the default ring (unless ``--nodes`` is given)
    nodes: list[str] = field(default_factory=list)
    #: emulated time runs this many times faster than the ring's clock; the wire follows it
    speedup: float = 1.0
    #: a hardware timing profile the options imply, used unless the user gave ``--profile``
    profile: str | None = None
    #: environment the programs read, set in this process for the run and restored after it
    env: dict[str, str] = field(default_factory=dict)
    #: runs inside the simulation once the nodes are built, given the runtime and the
    #: :class:`~tokenring.sim.SimRing`; runs its course (``--duration``) and returns facts for
    #: the summary (JSON-able)
    scenario: Callable[[Any, Any], dict[str, Any]] | None = None
    #: lines printed under the summary, given its facts
    report: Callable[[dict[str, Any]], list[str]] | None = None
    #: a message if the application's job failed (exit code 1), given the facts
    failure: Callable[[dict[str, Any]], str | None] | None = None


@dataclass
class WebPanel:
    """An application's panel in the web view: ``directory``'s files are served under
    ``/panels/<name>/`` and the page imports ``module`` from it, an ES module exporting
    ``mount(element, view)`` (``view.on(topic, callback)``, ``view.action(name)``)."""

    name: str
    directory: Path
    module: str = "panel.js"
    title: str = ""


@dataclass
class WebAction:
    """A button of the web view: ``run(session, ring)`` does it (on a worker thread) and
    returns what the page shows (JSON-able); a :class:`UsageError` is shown as the answer."""

    name: str
    label: str
    run: Callable[[zenoh.Session, str], dict[str, Any]]


@dataclass(frozen=True)
class WebKey:
    """One key of the web view's keyboard: how the page shows it and what it means, and the
    browser's names of it (``KeyboardEvent.key``: ``"a"``, ``" "``, ``"ArrowUp"``; one entry
    may stand for several, e.g. ``x`` and ``q``)."""

    label: str
    meaning: str
    values: tuple[str, ...]


class KeyHandler(typing.Protocol):
    """What carries the web view's keys out: one per served ring, called on one worker thread,
    one key at a time in the order they were pressed."""

    def press(self, key: str) -> dict[str, Any]:
        """Carry out ``key`` (the browser's ``KeyboardEvent.key``, any key the page had focus
        for, known or not): ``{"text": one line for the page, "ok": False if it did nothing}``."""
        ...

    def idle(self) -> None:
        """Called every :attr:`WebKeys.idle_s` seconds between keys (renew what a key holds)."""
        ...

    def unattended(self) -> dict[str, Any] | None:
        """Nobody is there any more (the last page closed, a script fell silent, the view
        stops): undo what the keys hold; the answer for the log, None if nothing was held."""
        ...


@dataclass
class WebKeys:
    """The web view's keyboard: with focus on the page (not in a text field) the page posts
    each key to ``/api/key``; ``open(session, ring)`` makes the one :class:`KeyHandler` that
    carries them out (at the first key; a :class:`TokenRingError` there is the key's answer,
    and the next key tries again). ``keys`` are listed on the page (and kept from scrolling it),
    ``note`` is a line beside them (e.g. which keys are unbound)."""

    keys: list[WebKey]
    open: Callable[[zenoh.Session, str], KeyHandler]
    note: str = ""
    idle_s: float = 5.0


class Extension:
    """An application on the ring; every method has a do-nothing default."""

    name = ""

    def commands(self) -> list[ModuleType]:
        """Verb modules (``add_parser(sub)``, ``run(args)``) added to ``tokenring``. They are
        imported to list them (``tokenring --help``): cheap to import, each with its one-line
        help as ``HELP``, they are listed without building their options (:mod:`tokenring.cli.verbs`)."""
        return []

    def programs_dir(self) -> Path | None:
        """Where the programs for protocol.yaml's nodes live (``<dir>/<node name>.py``)."""
        return None

    def add_up_options(self, parser: argparse.ArgumentParser) -> None:
        """Options of ``tokenring up`` (in argument groups of their own)."""

    def up_nodes(self, args: argparse.Namespace, protocol: Protocol) -> list[str]:
        """Optional nodes of protocol.yaml that this ``up``'s options start beside the default
        ring when ``--nodes`` is not given (a given ``--nodes`` names every node itself; raise
        :class:`UsageError` if it leaves out one the options need)."""
        return []

    def plan_up(self, args: argparse.Namespace, protocol: Protocol) -> UpPlan:
        """Check this extension's ``up`` options (raise :class:`UsageError`) and plan its part."""
        return UpPlan()

    def add_sim_options(self, parser: argparse.ArgumentParser) -> None:
        """Options of ``tokenring sim`` (in argument groups of their own)."""

    def plan_sim(self, args: argparse.Namespace, protocol: Protocol) -> SimPlan | None:
        """Check this extension's ``sim`` options (raise :class:`UsageError`) and plan its part of
        the run, or None when they ask for none (the ring alone)."""
        return None

    def add_load_options(self, parser: argparse.ArgumentParser) -> None:
        """Options of ``tokenring load``."""

    def check_load(self, args: argparse.Namespace) -> None:
        """Refuse bad ``load`` options (raise :class:`UsageError`) before anything is sent."""

    def after_load(
        self, args: argparse.Namespace, session: zenoh.Session, say: Callable[[str], None]
    ) -> dict[str, Any]:
        """The extension's step after the programs are loaded; what it returns joins ``--json``."""
        return {}

    def open_hardware(self, module: str, session: zenoh.Session, ring: str) -> Any | None:
        """The hardware client for ``module``'s program, or None if it has none here."""
        return None

    def resident_program(self, module: str) -> type[ResidentProgram] | None:
        """The part of ``module``'s node OS this application adds (run from boot while no user
        program runs, with the node's hardware client), or None."""
        return None

    def feed_sources(self, protocol: Protocol, ring: str) -> list[FeedSource]:
        """The extension's topics in a live feed (:mod:`tokenring.observe.feed`): ``record``, the web
        view and the Foxglove bridge show them beside the ring's."""
        return []

    def web_panels(self) -> list[WebPanel]:
        """The extension's panels in the web view (beside the ring's own)."""
        return []

    def web_actions(self) -> list[WebAction]:
        """The extension's buttons in the web view (e.g. start and stop a job)."""
        return []

    def add_web_options(self, parser: argparse.ArgumentParser) -> None:
        """Options of ``tokenring web`` (what its keys need, e.g. files they run)."""

    def web_keys(self, args: argparse.Namespace) -> WebKeys | None:
        """The web view's keyboard (``args``: ``tokenring web``'s, or ``watch``'s without the
        extension's web options), or None; raise :class:`UsageError` for a bad option."""
        return None


def _wanted() -> set[str] | None:
    value = os.environ.get(ENV)
    if value is None:
        return None
    return {name.strip() for name in value.split(",") if name.strip()}


@cache
def loaded() -> tuple[Extension, ...]:
    """The registered extensions (those ``TOKENRING_EXTENSIONS`` names, if set), loaded once."""
    wanted = _wanted()
    if wanted == set():
        return ()  # the bare ring: not even the installed packages' metadata is read
    # imported here: importlib.metadata (email, zipfile, csv) is most of the weight of finding
    # extensions, which a node only pays for when it needs one (a program's hardware)
    from importlib.metadata import entry_points

    found: list[Extension] = []
    for point in sorted(entry_points(group=GROUP), key=lambda p: p.name):
        if wanted is not None and point.name not in wanted:
            continue
        try:
            factory = point.load()
            extension = factory()
        except Exception as exc:  # a broken plugin must not take the ring's CLI with it
            raise UsageError(f"extension {point.name!r} ({point.value}) failed to load: {exc}") from None
        if not isinstance(extension, Extension):
            raise UsageError(f"extension {point.name!r} ({point.value}) is not a tokenring Extension")
        extension.name = extension.name or point.name
        found.append(extension)
    if wanted:
        missing = wanted - {e.name for e in found}
        if missing:
            raise UsageError(f"{ENV}: no extension named {', '.join(sorted(missing))} is installed")
    return tuple(found)


def programs_dir() -> Path | None:
    """The first extension's programs directory, or None (the bare ring has no programs)."""
    for extension in loaded():
        directory = extension.programs_dir()
        if directory is not None:
            return directory
    return None


def open_hardware(module: str, session: zenoh.Session, ring: str) -> Any | None:
    """``module``'s hardware client from the first extension that has one, else None."""
    for extension in loaded():
        client = extension.open_hardware(module, session, ring)
        if client is not None:
            return client
    return None


def resident_program(module: str) -> type[ResidentProgram] | None:
    """``module``'s resident program from the first extension that has one, else None."""
    for extension in loaded():
        resident = extension.resident_program(module)
        if resident is not None:
            return resident
    return None


def web_panels() -> list[WebPanel]:
    """Every extension's web panels, in extension order."""
    return [panel for extension in loaded() for panel in extension.web_panels()]


def web_actions() -> list[WebAction]:
    """Every extension's web actions, in extension order (a name is taken by the first)."""
    actions: dict[str, WebAction] = {}
    for extension in loaded():
        for action in extension.web_actions():
            actions.setdefault(action.name, action)
    return list(actions.values())


def add_web_options(parser: argparse.ArgumentParser) -> None:
    """Every extension's options of ``tokenring web``."""
    for extension in loaded():
        extension.add_web_options(parser)


def web_keys(args: argparse.Namespace) -> WebKeys | None:
    """The first extension's web keyboard, or None (the page then takes no keys)."""
    for extension in loaded():
        keys = extension.web_keys(args)
        if keys is not None:
            return keys
    return None
