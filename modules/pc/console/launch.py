"""``tokenring up --console``: the operator's screen in the launcher's terminal.

Once the programs run, the console starts as a child process on the same terminal (a process of
its own: its screen and the launcher's supervision never share a thread), the launcher's lines go
to a file meanwhile, and its ``x``/``q`` stops the ring, as the seed's ``x`` ended the program.
The console watches the launcher's PID and quits if the launcher ends first (``--duration``, a
kill); the launcher waits for it to give the terminal back before it says its last line. A
console killed outright (SIGKILL) cannot give it back: the launcher restores the terminal's
settings as they were before the console, leaves the console's full screen and stops the ring.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import subprocess
import sys
import tempfile
import termios
import threading
from typing import Any

#: how long the launcher waits for the console to give the terminal back at the end
CONSOLE_EXIT_S = 10.0
#: what a full-screen program undoes as it quits: its alternate screen, mouse and focus
#: reports, bracketed paste and keyboard protocol off, the cursor shown, lines wrapped
LEAVE_FULL_SCREEN = (
    "\x1b[?1049l\x1b[?1000l\x1b[?1003l\x1b[?1015l\x1b[?1006l\x1b[?1004l\x1b[?2004l\x1b[<u\x1b[?25h\x1b[?7h"
)


def terminal_settings() -> list[Any] | None:
    """The terminal's settings (termios) before the console takes it; None: no terminal."""
    try:
        return termios.tcgetattr(sys.stdin.fileno()) if sys.stdin.isatty() else None
    except (OSError, ValueError, termios.error):
        return None


def give_terminal_back(settings: list[Any] | None) -> None:
    """What a console killed outright left undone: the settings, and its full screen left."""
    if settings is None:
        return
    with contextlib.suppress(OSError, ValueError, termios.error):
        termios.tcsetattr(sys.stdin.fileno(), termios.TCSADRAIN, settings)
        if sys.stdout.isatty():
            sys.stdout.write(LEAVE_FULL_SCREEN)
            sys.stdout.flush()


def console_command(args: argparse.Namespace, owner_pid: int) -> list[str]:
    """The ``tokenring console`` for this ``up``: its ring, its endpoint, its action file."""
    command = [
        sys.executable,
        "-m",
        "tokenring",
        "console",
        "--ring",
        args.ring,
        "--owner-pid",
        str(owner_pid),
    ]
    for endpoint in args.listen or args.connect or []:
        command += ["--connect", endpoint.replace("0.0.0.0", "127.0.0.1")]
    if getattr(args, "zenoh_config", None):
        command += ["--zenoh-config", args.zenoh_config]
    if getattr(args, "protocol", None):
        command += ["--protocol", args.protocol]
    if getattr(args, "localizer", None):  # the seed's one file: its [Main] screen and [Action] keys too
        from modules.localization.config import config_path

        command += ["--config", str(config_path(args.localizer).resolve())]
    return command


def with_console(plan: Any, args: argparse.Namespace) -> None:
    """Add the console to an ``up`` plan: started after the plan's own start, waited for at its end."""
    started, failed = plan.on_started, plan.failure
    consoles: list[subprocess.Popen[bytes]] = []

    def start(launcher: Any) -> None:
        if started is not None:
            started(launcher)
        log = tempfile.NamedTemporaryFile(  # noqa: SIM115 - open while the console runs
            "w", prefix=f"tokenring-up-{args.ring}-", suffix=".log", delete=False, encoding="utf-8"
        )
        launcher.say(f"the console takes the terminal; the launcher's lines go to {log.name}")
        previous = launcher.divert_output(log)
        settings = terminal_settings()
        console = subprocess.Popen(console_command(args, os.getpid()))
        consoles.append(console)

        def wait() -> None:
            code = console.wait()
            if code < 0:  # killed by a signal it could not handle: it left the terminal as it was
                give_terminal_back(settings)
            launcher.divert_output(previous)
            log.close()
            launcher.say(
                f"the console ended (exit code {code}): stopping the ring; its lines are in {log.name}"
            )
            launcher.request_stop()

        threading.Thread(target=wait, name="console-wait", daemon=True).start()

    def failure() -> str | None:
        for console in consoles:
            try:
                code = console.wait(CONSOLE_EXIT_S)
            except subprocess.TimeoutExpired:
                console.terminate()
                code = console.wait(CONSOLE_EXIT_S)
            if code not in (0, None):
                return f"the console ended with exit code {code}"
        return failed() if failed is not None else None

    plan.on_started = start
    plan.failure = failure
