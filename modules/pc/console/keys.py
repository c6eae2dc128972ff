"""Keys carried out one after another on a thread of their own: a PC-link call may take seconds
(a slow ring), and neither the screen nor the next key's order may suffer for it."""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable

from modules.pc.operator import Operator, Outcome


class KeyRunner:
    """Hands keys to an :class:`Operator` in the order they were pressed; ``on_outcome`` gets each
    result on the runner's thread. The held speed is renewed while no key comes."""

    def __init__(
        self, operator: Operator, on_outcome: Callable[[Outcome], None], renew_s: float = 5.0
    ) -> None:
        self.operator = operator
        self.on_outcome = on_outcome
        self.renew_s = renew_s
        self._keys: queue.Queue[str | None] = queue.Queue()
        self._thread = threading.Thread(target=self._run, name="console-keys", daemon=True)

    def start(self) -> KeyRunner:
        self._thread.start()
        return self

    def press(self, key: str) -> None:
        self._keys.put(key)

    def stop(self, timeout: float = 5.0) -> None:
        self._keys.put(None)
        self._thread.join(timeout)

    def _run(self) -> None:
        while True:
            try:
                key = self._keys.get(timeout=self.renew_s)
            except queue.Empty:
                self.operator.keep_alive()
                continue
            if key is None:
                return
            self.on_outcome(self.operator.press(key))
