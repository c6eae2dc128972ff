"""``tokenring console``: the operator's screen on a running ring, driven by the seed's keys.

The Darmstadt program (seed 000 §6.6, §8) showed every sensor's data, the synchronisation and the
position store live and drove the robot from the keyboard (table 8.2). This attaches to a ring
(the ring goes on when the console quits or is killed), shows the same and takes the same keys:
``e`` motors on, the arrows to drive, space to stop, ``a``/``b``/``c`` the action files, ``k`` a
circle, ``s`` a square, ``d`` motors off, ``x``/``q`` quit.

The seed's command line (table 8.1) is taken as it was spelled: ``-Online`` (the default),
``-Moffline`` (replay the configuration's data log through the filter, without the ring) and
``-C<file>`` (the configuration: the seed's format or tokenring's YAML; user interface and action
files come from it unless given here). Without ``-C``, a ``default.cfg`` in the working directory
is read, as the seed's program did.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from tokenring import UsageError

HELP = "the operator's screen: sensors, synchronisation, positions live; drive with the seed's keys"

EXAMPLES = """examples:
  tokenring console                              # attach to the default ring, full screen
  tokenring console --action actions/square-3-laps.act   # bound to the key a
  tokenring console -Online -Cconfig/syncaria.cfg        # the seed's own command line (table 8.1)
  tokenring console --ui stdout                  # only the messages, as lines (the seed's stdout UI)
  echo "e up up left space x" | tokenring console --ui none   # keys by name from a pipe
  tokenring console -Moffline -Cconfig/syncaria.cfg      # the seed's offline mode: replay its log

keys (table 8.2): a/b/c action file 1/2/3, d motors off, e motors on, x/q quit, space stop (clears
the queue), ↑ accelerate, ↓ brake, ← left, → right, k circle, s square
"""

UIS = ("ncurses", "stdout", "none")
#: the configuration read when no -C is given, from the working directory (seed table 8.1)
DEFAULT_CONFIG = "default.cfg"


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring.cli import add_ring_options, with_examples

    p = sub.add_parser("console", help=HELP, description=__doc__, **with_examples(EXAMPLES))
    p.add_argument("--ui", choices=UIS, help="the screen (default: the configuration's, else ncurses)")
    p.add_argument(
        "-C",
        "--config",
        metavar="FILE",
        help="the configuration (seed format .cfg, or YAML): user interface, action files, offline log "
        f"(default: ./{DEFAULT_CONFIG} if there is one)",
    )
    p.add_argument("-O", dest="seed_online", metavar="nline", help="-Online: attach to the ring (default)")
    p.add_argument("-M", dest="seed_mode", metavar="MODE", help="-Moffline or -Monline (seed table 8.1)")
    p.add_argument(
        "--action",
        action="append",
        default=[],
        metavar="FILE",
        help="an action file for a, then b, then c (up to three; before the configuration's)",
    )
    p.add_argument("--auto", action="store_true", help="run the first action file at once ([ACTION] auto)")
    p.add_argument("--force", action="store_true", help="-Moffline: replace existing result and error files")
    p.add_argument("--owner-pid", type=int, metavar="PID", help=argparse.SUPPRESS)  # up --console's launcher
    add_ring_options(p, listen=False)


def program_mode(args: argparse.Namespace) -> str:
    """online or offline, from ``-Online``/``-Moffline`` (seed table 8.1)."""
    if args.seed_online is not None and args.seed_online != "nline":
        raise UsageError(f"-O{args.seed_online}: the seed's option is -Online")
    mode = (args.seed_mode or "online").lower()
    if mode not in ("online", "offline"):
        raise UsageError(f"-M{args.seed_mode}: the mode is online or offline (-Moffline)")
    if args.seed_online is not None and mode == "offline":
        raise UsageError("-Online and -Moffline both given: one mode")
    return mode


def settings(args: argparse.Namespace) -> dict[str, Any]:
    """The user interface, action files and auto-run: the command line's, else the configuration's."""
    chosen: dict[str, Any] = {"ui": None, "files": [], "auto": False, "offline": None}
    if args.config:
        chosen.update(_from_config(args.config))
    if len(args.action) > 3:
        raise UsageError(f"--action takes up to three files (a, b, c), got {len(args.action)}")
    files = list(args.action) + list(chosen["files"])[len(args.action) :]
    for file in files:
        if file is not None and not Path(file).is_file():
            raise UsageError(f"action file {file}: no such file")
    chosen["files"] = files[:3]
    chosen["ui"] = args.ui or chosen["ui"] or "ncurses"
    chosen["auto"] = args.auto or chosen["auto"]
    return chosen


def _from_config(path: str) -> dict[str, Any]:
    """What the console takes from a configuration file: ``ui``, action ``files``, ``auto``, and
    the ``offline`` settings (the seed's format: its [Main] and [Action]; tokenring's YAML: its
    ``ui`` and ``actions`` keys)."""
    from modules.localization.config import ConfigError, load_config, read_seed_file
    from modules.localization.seedconfig import looks_like_seed_config
    from tokenring import message_error, read_text

    text = read_text(Path(path), "configuration file", message_error(ConfigError))
    if path.endswith(".cfg") or looks_like_seed_config(text):
        seed = read_seed_file(path)
        files = [str(f) if f is not None else None for f in seed.actions.files]
        return {"ui": seed.ui, "files": files, "auto": seed.actions.auto, "offline": seed.offline}
    config = load_config(path)  # action files come back resolved from the file's folder
    actions = config.get("actions") or {}
    files = [str(f) if f else None for f in actions.get("files") or []]
    return {"ui": config.get("ui"), "files": files, "auto": bool(actions.get("auto")), "offline": None}


def run(args: argparse.Namespace) -> int:
    from modules.localization.config import seed_notes

    # the seed file's values that do not apply here, once each on stderr (under up --console,
    # up has said them)
    with seed_notes(quiet=bool(args.owner_pid)):
        return _run(args)


def _run(args: argparse.Namespace) -> int:
    mode = program_mode(args)
    if args.config is None and not args.owner_pid and Path(DEFAULT_CONFIG).is_file():
        import sys

        args.config = DEFAULT_CONFIG
        print(f"console: reading {DEFAULT_CONFIG} (no -C given; seed table 8.1)", file=sys.stderr)
    chosen = settings(args)
    if mode == "offline":
        return _offline(args, chosen)
    if chosen["auto"] and not chosen["files"]:
        raise UsageError("--auto runs the first action file, and none is given")
    from modules.navigation.actions import load_actions

    seed = False
    for file in chosen["files"]:
        if file is not None:
            load_actions(file, seed=seed)  # a bad file is named now, before the screen opens
    return _online(args, chosen)


def _online(args: argparse.Namespace, chosen: dict[str, Any]) -> int:
    from modules.pc.console.keys import KeyRunner
    from modules.pc.console.state import ConsoleState
    from modules.pc.operator import Operator
    from tokenring import load_protocol
    from tokenring.cli import tap_session
    from tokenring.host import open_link
    from tokenring.observe import Feed, feed_sources

    protocol = load_protocol(args.protocol)
    session = tap_session(args)
    try:
        link = open_link(session, args.ring)
        state = ConsoleState()
        feed = Feed(session, args.ring, feed_sources(protocol, args.ring))
        feed.add_sink(state.on_message)
        operator = Operator(link, chosen["files"])
        with feed:
            if args.owner_pid:
                watch_owner(args.owner_pid)
            if chosen["auto"]:
                first = operator.press("a")
                if not first.ok:
                    raise UsageError(f"[ACTION] auto: {first.text}")
            if chosen["ui"] == "ncurses":
                from modules.pc.console.screen import ConsoleScreen, run_screen

                def runner_for(on_outcome: Any) -> KeyRunner:
                    return KeyRunner(operator, on_outcome)

                title = f"tokenring console — ring {args.ring}"
                return run_screen(ConsoleScreen(state, runner_for, lambda: state.poll_main(link), title))
            from modules.pc.console.plain import run_plain

            return run_plain(state, operator, show=chosen["ui"] == "stdout")
    finally:
        session.close()


def watch_owner(pid: int) -> None:
    """Quit (as on SIGINT) once the launcher that started this console is gone."""
    import os
    import signal
    import threading
    import time

    def watch() -> None:
        while True:
            time.sleep(0.5)
            try:
                os.kill(pid, 0)
            except ProcessLookupError:
                os.kill(os.getpid(), signal.SIGINT)
                return
            except PermissionError:
                continue

    threading.Thread(target=watch, name="console-owner", daemon=True).start()


def _offline(args: argparse.Namespace, chosen: dict[str, Any]) -> int:
    """The seed's offline mode (§8.3): the configuration's data log through the filter, no ring,
    as ``tokenring replay`` (the [Offline] section's result and error files)."""
    offline = chosen.get("offline")
    if not args.config or offline is None:
        raise UsageError(
            "-Moffline replays the data log that the configuration names: give -C<file> with an [Offline] section"
        )
    from modules.pc.commands import replay

    replay_args = argparse.Namespace(
        log=str(offline.input),
        out=str(offline.result),
        config=args.config,
        mode="sync" if offline.synchronised else "raw",
        errors=str(offline.errors),
        force=args.force,
        salvage=False,
        check=False,
        json=False,
    )
    return int(replay.run(replay_args))
