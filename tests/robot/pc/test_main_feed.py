"""``/robot/main`` (modules/pc/feed.py's MainSource): main's action queue and navigator as the web
view's Localisation panel shows them, sent when they change; a main that stops answering is said
once and asked again only after a pause. The link is a stand-in; the live ring:
tests/robot/pc/test_web_keys_browser.py."""

from __future__ import annotations

from typing import Any

from modules.pc.feed import MainSource
from tokenring import TransportError, load_protocol


class Link:
    def __init__(self) -> None:
        self.state: dict[str, Any] | Exception = {"queue": [], "navigator": "IDLE", "running": False}
        self.asked = 0

    def request(self, verb: str, **payload: Any) -> Any:
        assert verb == "state"
        self.asked += 1
        if isinstance(self.state, Exception):
            raise self.state
        return {**self.state, "pose": [1.0, 2.0, 0.0], "finished": False}


def test_main_state_is_sent_when_it_changes_and_silence_once() -> None:
    source = MainSource(load_protocol())
    assert [t.name for t in source.topics()] == ["/robot/main"]
    link = Link()
    source._link = link
    first = source.poll(None, "t", 1)
    assert [m.topic for m in first] == ["/robot/main"]
    assert first[0].data == {
        "queue": [],
        "navigator": "IDLE",
        "running": False,
        "abort_reason": None,
        "steps": None,
    }
    assert source.poll(None, "t", 2) == []  # nothing changed (the pose is not kept: it moves)
    link.state = {"queue": ["s 1000", "r 90"], "navigator": "ACTIONS", "running": True}
    assert source.poll(None, "t", 3)[0].data["queue"] == ["s 1000", "r 90"]
    link.state = TransportError("main did not answer")
    gone = source.poll(None, "t", 4)
    assert gone[0].data == {"error": "main did not answer"}
    asked = link.asked
    assert source.poll(None, "t", 5) == [] and link.asked == asked  # a pause before asking again
    source._quiet_until = 0.0
    link.state = {"queue": [], "navigator": "IDLE", "running": False}
    assert source.poll(None, "t", 6)[0].data["navigator"] == "IDLE"


def test_a_main_never_heard_is_not_reported_as_gone() -> None:
    source = MainSource(load_protocol())
    link = Link()
    link.state = TransportError("main did not answer")
    source._link = link
    assert source.poll(None, "t", 1) == []
