"""``tokenring up --console``: the operator's screen in the launcher's terminal.

Once the programs run, the console starts as a child process on the same terminal (a process of
its own: its screen and the launcher's supervision never share a thread), the launcher's lines go
to a file meanwhile, and its ``x``/``q`` stops the ring, as the seed's ``x`` ended the program.
The console watches the launcher's PID and quits if the launcher ends first (``--duration``, a
kill); the launcher waits for it to give the terminal back before it says its last line.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import threading
from typing import Any

#: how long the launcher waits for the console to give the terminal back at the end
CONSOLE_EXIT_S = 10.0


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
        console = subprocess.Popen(console_command(args, os.getpid()))
        consoles.append(console)

        def wait() -> None:
            code = console.wait()
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
