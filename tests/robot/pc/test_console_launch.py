"""``up --console`` gives the terminal back for a console killed outright (modules/pc/console/
launch.py): the settings from before the console, and its full screen left. On a real pseudo
terminal; the ring test of ``up --console`` is test_console_tmux.py."""

from __future__ import annotations

import os
import pty
import termios
import tty

import pytest

from modules.pc.console.launch import LEAVE_FULL_SCREEN, give_terminal_back, terminal_settings


def test_a_killed_consoles_terminal_is_given_back_as_it_was(monkeypatch: pytest.MonkeyPatch) -> None:
    master, slave = pty.openpty()
    with (
        open(slave, encoding="utf-8", closefd=False) as keyboard,
        open(slave, "w", encoding="utf-8", closefd=False) as screen,
    ):
        monkeypatch.setattr("sys.stdin", keyboard)
        monkeypatch.setattr("sys.stdout", screen)
        before = terminal_settings()
        assert before is not None and before[3] & termios.ECHO
        tty.setraw(slave)  # what the console's full screen left behind when it was killed
        assert not termios.tcgetattr(slave)[3] & termios.ECHO
        give_terminal_back(before)
        assert termios.tcgetattr(slave) == before
        written = b""
        while len(written) < len(LEAVE_FULL_SCREEN.encode()):
            written += os.read(master, 1024)
        assert written.decode() == LEAVE_FULL_SCREEN
    os.close(slave)
    os.close(master)


def test_without_a_terminal_there_is_nothing_to_give_back(monkeypatch: pytest.MonkeyPatch) -> None:
    read, write = os.pipe()
    with open(read, encoding="utf-8") as pipe:
        monkeypatch.setattr("sys.stdin", pipe)
        assert terminal_settings() is None
        give_terminal_back(None)  # nothing to restore, nothing written
    os.close(write)
