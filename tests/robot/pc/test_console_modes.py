"""``tokenring console`` run to the end without a ring: ``-Moffline -C<file>`` (seed table 8.1)
replays the configuration's data log, and ``--ui none`` with keys from a pipe drives main's PC
link, played here by a recorder, with the [ACTION] files of a seed configuration: the first at
the start (auto), b and c as the keys say. Both tell the file's notes on stderr, once each."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from modules.localization.config import load_config
from modules.localization.localizer import LocalizationCore
from modules.localization.logs import DataLog, read_log
from modules.localization.seedconfig import read_seed_config
from tests.support.locsim import drive
from tests.support.processes import run_tokenring
from tokenring.contract import keys
from tokenring.transport import make_config, open_session
from tokenring.transport.control import answer_query


def seed_file(
    folder: Path,
    *,
    ui: str = "stdout",
    data_log: str = "run.trlog",
    offline: tuple[str, str] | None = None,
    actions: tuple[str, ...] = (),
    auto: bool = False,
) -> Path:
    """A small syncaria file (table B.1): the odometry and the walls of the square room."""
    text = f"""[Main]
sim {ui} odo 1 yes no
{data_log}
2 no
[Sensors]
odo   yes yes yes yes yes yes
walls yes yes yes yes yes yes
[Odometry]
yes
[Walls]
yes 60 1400 15 10 30 35 15 50 10
square
400 20
"""
    if offline is not None:
        text += f"[Offline]\n{offline[0]}\n{offline[1]}\nno\n"
    if actions:
        text += "[Action]\n" + ("yes" if auto else "no") + "\n" + "\n".join(actions) + "\n"
    path = folder / "operator.cfg"
    path.write_text(text)
    return path


def told(stderr: str, cfg: Path) -> list[str]:
    """The lines of ``stderr`` that tell a note of ``cfg``."""
    return [line for line in stderr.splitlines() if line.startswith(f"{cfg}:")]


# --------------------------------------------------------------------------------------------
# -Moffline


def test_offline_mode_replays_the_configurations_log_as_it_ran(tmp_path: Path) -> None:
    log, result, errors = tmp_path / "run.trlog", tmp_path / "again.trlog", tmp_path / "again.trerr"
    cfg = seed_file(tmp_path, data_log=str(log), offline=(str(result), str(errors)))
    config = load_config(cfg)
    core = LocalizationCore(config, data_log=DataLog(log, "test", config))
    for sample in drive([("s", 400.0), ("r", 90.0)], seed=3):  # the online run, as copro would
        core.feed(sample)
        core.maybe_sync()
    core.close()
    assert core.syncs > 50

    run = run_tokenring("console", "-Moffline", f"-C{cfg}", timeout=300)
    assert run.returncode == 0, run.stderr
    assert f"{result}: {core.syncs} synchronisations" in run.stdout, run.stdout
    assert "identical to the input log" in run.stdout  # from raw data, as the seed's -Moffline
    assert len(read_log(result).records) > 0 and errors.is_file()
    lines = told(run.stderr, cfg)
    assert lines == read_seed_config(cfg).note_lines()  # once each: the console and the replay read it
    assert [line.split(": ")[1] for line in lines] == [
        "[Main] Anbindung", "[Walls] max. Δd (oben / unten)", "[Walls] max. Δα (oben / unten)"
    ]  # fmt: skip
    assert lines[0].startswith(f"{cfg}:2: [Main] Anbindung: the ring is the robot either way")


# --------------------------------------------------------------------------------------------
# --ui none, keys from a pipe, on a recorded PC link


class RecordingMain:
    """main's end of the PC link (tokenring.node.pclink.server's verbs) with no ring behind it:
    it answers as an idle main does and records every request."""

    def __init__(self, endpoint: str, ring: str) -> None:
        self.requests: list[tuple[str, dict[str, Any]]] = []
        self._lock = threading.Lock()
        handlers = {
            "status": lambda _: {"id": 10},
            "read": lambda _: {"data": {"state": 0}, "visits": 1},
            "command": lambda _: {"transmitted": True, "acknowledged": True},
            "request": self._request,
        }
        self.session = open_session(make_config(listen=[endpoint], gossip=False))
        self.queryable = self.session.declare_queryable(
            keys.pc_link(ring, "*"), lambda query: answer_query(query, handlers, "the recording main")
        )

    def _request(self, request: dict[str, Any]) -> dict[str, Any]:
        with self._lock:
            self.requests.append((request["verb"], request.get("payload") or {}))
            queued = sum(verb == "actions" for verb, _ in self.requests)
        return {"running": queued > 0, "queue": ["s"] * queued}

    def actions(self) -> list[dict[str, Any]]:
        with self._lock:
            return [payload for verb, payload in self.requests if verb == "actions"]

    def close(self) -> None:
        self.queryable.undeclare()
        self.session.close()


@pytest.fixture
def recording_main(endpoint: str, ring_name: str) -> Iterator[RecordingMain]:
    main = RecordingMain(endpoint, ring_name)
    yield main
    main.close()


@pytest.mark.timeout(400)
def test_ui_none_drives_file_1_at_the_start_and_b_and_c_from_the_configuration(
    tmp_path: Path, recording_main: RecordingMain, endpoint: str, ring_name: str
) -> None:
    texts = {"first.act": "s 100\n", "second.act": "r 45\n", "third.act": "# back\ns -100\n"}
    (tmp_path / "acts").mkdir()
    for name, text in texts.items():
        (tmp_path / "acts" / name).write_text(text)
    # relative to the configuration's folder, as the seed's [ACTION] names them
    cfg = seed_file(tmp_path, actions=tuple(f"acts/{name}" for name in texts), auto=True)

    run = run_tokenring(
        "console", "-C", str(cfg), "--ui", "none", "--ring", ring_name, "--connect", endpoint,
        input="b c x\n", timeout=300,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert run.stdout == ""  # --ui none over the file's stdout: nothing shown
    sent = recording_main.actions()
    assert [(Path(p["name"]), p["text"], p["append"]) for p in sent] == [
        (tmp_path / "acts" / name, text, True) for name, text in texts.items()
    ]  # auto queued the first before any key; b and c the second and third
    assert told(run.stderr, cfg) == read_seed_config(cfg).note_lines() and told(run.stderr, cfg)


def test_messages_said_before_the_console_opened_are_shown_though_they_come_late() -> None:
    """The backlog (messages from before the console opened) joins the list after the first live
    message: the screen shows the list afresh, in order; nothing is shown twice."""
    from modules.pc.console.state import unseen_lines

    shown: list[str] = []
    assert unseen_lines(shown, ["I 900 live"]) == (["I 900 live"], False)
    late = ["I 0 localisation started", "W 10 gyro", "I 900 live"]
    assert unseen_lines(shown, late) == (["I 0 localisation started", "W 10 gyro"], True)
    assert unseen_lines(shown, [*late, "I 950 next"]) == (["I 950 next"], False)
    assert unseen_lines(shown, [*late[1:], "I 950 next", "I 950 next"]) == (["I 950 next"], False)
