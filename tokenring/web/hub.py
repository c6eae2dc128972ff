"""What the web view shows, coalesced: the latest value of every topic, numbered so that each
browser gets only what changed since its last update (at most every 100 ms).

The feed's thread writes (:meth:`Hub.on_message`), the server's loop reads (:meth:`Hub.changes`);
a browser never sees every frame. Three topics are folded instead of kept as they come:

* ``/ring/frame`` (one message per pass of the token) becomes ``/web/token``: how many frames
  were seen, who holds the token now (the last frame's DID), its round counter and epoch;
* ``/ring/roundtrip`` keeps a window of its last samples (the page's sparkline);
* a topic shaped like foxglove.SceneUpdate (``entities``/``deletions``: the map, the walls)
  accumulates its entities by ID, so a browser that opens late still sees the whole map.
"""

from __future__ import annotations

import threading
from collections import deque
from typing import Any

from tokenring.observe.feed import Message

#: the derived topic of the token's passes
TOKEN_TOPIC = "/web/token"
#: how many round trips the sparkline keeps
ROUNDTRIP_WINDOW = 150


class Hub:
    """The latest value per topic, each with the version it was last changed at."""

    def __init__(self, window: int = ROUNDTRIP_WINDOW) -> None:
        self._lock = threading.Lock()
        self._version = 0
        self._values: dict[str, Any] = {}
        self._versions: dict[str, int] = {}
        self._frames = 0
        self._roundtrips: deque[list[float]] = deque(maxlen=window)
        self._entities: dict[str, dict[str, Any]] = {}

    @property
    def version(self) -> int:
        with self._lock:
            return self._version

    def on_message(self, message: Message) -> None:
        """A feed sink: fold one message into the state (called on the feed's thread)."""
        with self._lock:
            topic, data = message.topic, message.data
            if topic == "/ring/frame":
                self._frames += 1
                token = {"frames": self._frames, "holder": data.get("did"), "time_ns": message.time_ns}
                for name in ("sid", "counter", "epoch", "syscmd", "problem"):
                    if name in data:
                        token[name] = data[name]
                self._set(TOKEN_TOPIC, token)
            elif topic == "/ring/roundtrip":
                self._roundtrips.append([message.time_ns / 1e6, float(data.get("ms", 0.0))])
                self._set(topic, {"samples": list(self._roundtrips), **data})
            elif isinstance(data, dict) and ("entities" in data or "deletions" in data):
                entities = self._entities.setdefault(topic, {})
                for deletion in data.get("deletions") or ():
                    if deletion.get("type") == 1:  # foxglove.SceneEntityDeletion ALL
                        entities.clear()
                    else:
                        entities.pop(str(deletion.get("id")), None)
                for entity in data.get("entities") or ():
                    entities[str(entity.get("id"))] = entity
                self._set(topic, {"entities": list(entities.values())})
            else:
                self._set(topic, data)

    def _set(self, topic: str, value: Any) -> None:
        self._version += 1
        self._values[topic] = value
        self._versions[topic] = self._version

    def changes(self, since: int = 0) -> tuple[int, dict[str, Any]]:
        """The version now and every topic changed after ``since`` (0: everything)."""
        with self._lock:
            changed = {t: self._values[t] for t, v in self._versions.items() if v > since}
            return self._version, changed
