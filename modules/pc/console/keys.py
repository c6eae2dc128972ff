"""Keys carried out one after another on a thread of their own: a PC-link call may take seconds
(a slow ring), and neither the screen nor the next key's order may suffer for it. The same thread
renews the held speed and, when the console ends, stops what the keys started."""

from __future__ import annotations

import contextlib
import queue
import signal
import threading
from collections.abc import Callable, Iterator
from types import FrameType

from modules.pc.operator import HOLD_MS, Operator, Outcome

#: how often the runner offers the operator to renew its held speed (it renews every second)
RENEW_POLL_S = 0.2
#: how long a quitting console waits for the robot to be stopped: a ring that does not answer
#: leaves it to the dead-man (the held speed runs out within HOLD_MS)
RELEASE_S = 8.0
#: the signals that end a console (its terminal closed, a kill) as its quit key does
ENDING_SIGNALS = (signal.SIGTERM, signal.SIGHUP)


class KeyRunner:
    """Hands keys to an :class:`Operator` in the order they were pressed; ``on_outcome`` gets each
    result on the runner's thread. The held speed is renewed between keys; :meth:`stop` ends it
    all and stops the robot (:meth:`Operator.release`)."""

    def __init__(
        self, operator: Operator, on_outcome: Callable[[Outcome], None], renew_s: float = RENEW_POLL_S
    ) -> None:
        self.operator = operator
        self.on_outcome = on_outcome
        self.renew_s = renew_s
        self._keys: queue.Queue[str | None] = queue.Queue()
        self._thread = threading.Thread(target=self._run, name="console-keys", daemon=True)
        self._released: Outcome | None = None
        self._stopped = False

    def start(self) -> KeyRunner:
        self._thread.start()
        return self

    def press(self, key: str) -> None:
        self._keys.put(key)

    def stop(self, timeout: float = RELEASE_S, discard: bool = False) -> Outcome | None:
        """Carry out the keys pressed so far (none of them if ``discard``), then stop what they
        hold; wait at most ``timeout``. What the release did (None: nothing was held); a second
        call only says it again."""
        if not self._stopped:
            self._stopped = True
            if discard:
                with contextlib.suppress(queue.Empty):
                    while True:
                        self._keys.get_nowait()
            if self._thread.ident is None:  # never started: nothing else releases
                self._released = self.operator.release()
                return self._released
            self._keys.put(None)
        if self._thread.ident is None:
            return self._released
        self._thread.join(timeout)
        if self._thread.is_alive():
            return Outcome(
                "release",
                f"the ring did not stop the robot within {timeout:.0f} s: "
                f"a held speed runs out within {HOLD_MS / 1000:.0f} s",
                ok=False,
            )
        return self._released

    def _run(self) -> None:
        try:
            while True:
                try:
                    key = self._keys.get(timeout=self.renew_s)
                except queue.Empty:
                    key = ""
                if key is None:
                    return
                if key:
                    self.on_outcome(self.operator.press(key))
                lapsed = self.operator.keep_alive()
                if lapsed is not None:
                    self.on_outcome(lapsed)
        finally:
            self._released = self.operator.release()


class Ended(Exception):
    """A signal ended the console (:data:`ENDING_SIGNALS`): the exit code is 128 + its number."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.code = 128 + signum


@contextlib.contextmanager
def ending_signals(handler: Callable[[int], None] | None = None) -> Iterator[None]:
    """While inside: SIGTERM and SIGHUP call ``handler(signum)`` (default: raise :class:`Ended`
    in the main thread), so that the console's ``finally`` stops the robot; then as before."""

    def raise_ended(signum: int, frame: FrameType | None) -> None:
        raise Ended(signum)

    def call(signum: int, frame: FrameType | None) -> None:
        assert handler is not None
        handler(signum)

    saved = {sig: signal.signal(sig, raise_ended if handler is None else call) for sig in ENDING_SIGNALS}
    try:
        yield
    finally:
        for sig, previous in saved.items():
            signal.signal(sig, previous)
