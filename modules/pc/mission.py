"""The robot's jobs through main's PC link: exploration requests, and the mission of
``tokenring up --explore N --map-out FILE`` (explore, write the map, stop the ring)."""

from __future__ import annotations

import threading
import time
from typing import Any

from tokenring import UsageError
from tokenring.host import open_link


def request(link: Any, action: str) -> dict[str, Any]:
    """Send one exploration request over a :class:`~tokenring.host.pclink.PcLink`."""
    if action in ("1", "2"):
        return link.request("explore", mode=int(action))
    if action == "stop":
        return link.request("stop")
    if action == "calibrate":
        return link.request("calibrate")
    return link.request("state")


def describe_map(report: dict[str, Any] | None) -> str:
    """Explore 2's own view of its map's completeness, for the run's last line."""
    if not report:
        return ""
    return (
        f"; outline {'closed' if report.get('outline_closed') else 'NOT closed'}, "
        f"{report.get('islands_found', 0)} island(s), {report.get('probes', 0)} probe(s) into the interior, "
        f"interior {'seen' if report.get('interior_seen') else 'NOT all seen'}"
    )


def describe(state: dict[str, Any]) -> str:
    pose = state.get("pose")
    where = f" at ({pose[0]:.0f}, {pose[1]:.0f}) mm" if pose else ""
    return (
        f"navigator {state.get('navigator')} (mode {state.get('mode')}), step {state.get('steps')}, "
        f"last abort {state.get('abort_reason')}{where}"
    )


class Mission:
    """``tokenring up --explore N --map-out FILE``: explore, then write the map, then stop the ring.

    Runs beside the launcher: waits for main, starts the exploration, follows it until it
    finishes or the run's ``duration`` is nearly over (keeping time to fetch the map), stops it
    (copro flushes its held-back vectors), fetches the map through main and writes it (scored
    against the simulator's true walls), then asks the launcher to stop."""

    def __init__(
        self,
        launcher: Any,
        mode: int | None,
        map_out: str | None,
        duration: float | None,
        actions: tuple[str, str, int] | None = None,
    ) -> None:
        self.launcher = launcher
        self.mode = mode
        self.actions = actions  # (file name, text, speed %) for `up --actions`
        self.map_out = map_out
        self.duration = duration
        self.error: str | None = None
        self.score: dict[str, Any] | None = None
        self.map_written = False
        self.thread = threading.Thread(target=self._run, name="mission", daemon=True)

    def start(self) -> None:
        self.started = time.monotonic()
        self.thread.start()

    def say(self, text: str) -> None:
        self.launcher.say(text, name="explore")

    def failure(self, wait: float = 5.0) -> str | None:
        """Why the mission did not do its job (the run's exit code 1), or None: asked once the
        ring has stopped, it waits a moment for a map being written; a ``--map-out`` that was
        never written is a failure, whatever stopped the ring first."""
        self.thread.join(wait)
        if self.error is not None:
            return self.error
        if self.map_out and not self.map_written:
            text = f"--map-out {self.map_out}: no map written (the ring stopped before it was fetched)"
            self.say(text)
            return text
        return None

    def _stopping(self) -> bool:
        return self.launcher.stopping

    def _run(self) -> None:
        try:
            self._mission()
        except Exception as exc:  # reported as the run's failure, the ring still stops cleanly
            self.error = f"{type(exc).__name__}: {exc}" if not isinstance(exc, UsageError) else str(exc)
            self.say(f"failed: {self.error}")
        finally:
            self.launcher.request_stop()

    def _calibrate_compass(self, link: Any, end: float | None) -> None:
        """The compass's CALIBRATE turn first, so that the filter can trust its heading."""
        try:
            if not link.command("compass", "CALIBRATE", timeout=10.0).get("acknowledged"):
                return
        except UsageError:
            return  # no compass on this ring
        deadline = time.monotonic() + 60.0
        if end is not None:
            deadline = min(deadline, self.started + 0.5 * (end - self.started))
        seen_calibrating = False
        while time.monotonic() < deadline and not self._stopping():
            state = link.read("compass.data")["state"]
            seen_calibrating = seen_calibrating or state == 3
            if state == 1 and seen_calibrating:
                self.say("compass calibrated")
                return
            time.sleep(0.5)
        self.say("the compass did not finish calibrating: exploring anyway")

    def _mission(self) -> None:
        link = open_link(self.launcher.session, self.launcher.ring, wait=60.0)
        deadline = time.monotonic() + 30.0
        while True:  # main's node answers before its program runs
            try:
                link.request("state")
                break
            except UsageError:
                if time.monotonic() > deadline or self._stopping():
                    raise
                time.sleep(0.2)
        end = None
        if self.duration is not None:
            fetch_time = min(15.0, max(3.0, 0.15 * self.duration))
            end = self.started + self.duration - fetch_time
        if self.actions is not None:
            name, text, speed = self.actions
            self._calibrate_compass(link, end)
            state = link.request("actions", text=text, name=name, speed_pct=speed)
            self.say(f"driving {name}")
            while state.get("running") and not self._stopping() and (end is None or time.monotonic() < end):
                time.sleep(0.5)
                state = link.request("state")
            finished = (state.get("finished") or {}).get("why") if not state.get("running") else "time is up"
            self.say(f"{name} finished: {finished}")
            if state.get("running") and not self._stopping():
                link.request("stop")
        if self.mode is not None:
            self._calibrate_compass(link, end)
            state = request(link, str(self.mode))
            self.say(f"Explore {self.mode} started: {describe(state)}")
            last_report = 0.0
            while not self._stopping() and (end is None or time.monotonic() < end):
                time.sleep(0.5)
                state = link.request("state")
                if not state.get("running"):
                    finished = state.get("finished") or {}
                    self.say(
                        f"exploration finished: {finished.get('why')}{describe_map(finished.get('map'))}"
                    )
                    break
                if time.monotonic() - last_report > 10.0:
                    self.say(describe(state))
                    last_report = time.monotonic()
            if self._stopping():
                return
            if state.get("running"):
                link.request("stop")
                self.say("exploration stopped (time is up)")
        if self.map_out and not self._stopping():
            from modules.pc.mapfiles import end_pose, live_world, truth_from_info, write_map

            got = link.request("get_map", timeout=60.0)
            import numpy as np

            vectors = np.asarray(got["vectors"], dtype=float).reshape(-1, 4) * 10.0
            info = live_world(self.launcher.session, self.launcher.ring)
            world, truth = truth_from_info(info) if info is not None else (None, None)
            end = end_pose(self.launcher.session, self.launcher.ring, link.request("state").get("pose"))
            self.score = write_map(vectors, self.map_out, truth, world, end=end, option="--map-out")
            self.map_written = True
            line = f"wrote {len(vectors)} vectors to {self.map_out}"
            if self.score is not None:
                s = self.score
                line += (
                    f": coverage {s['coverage']:.0%}, precision {s['precision']:.0%}, "
                    f"orientation error {s['orientation_error_deg'] or 0:.1f}°, "
                    f"corners {s['corners_closed']}/{s['corners_total']} ({world})"
                )
            if end is not None:
                line += f"; the robot's pose ends {end['error_mm']:.0f} mm, {end['heading_error_deg']:+.1f}° off the truth"
            self.say(line)


class IncompleteWatch:
    """The modules that said their run is not whole (liveliness ``robot/incomplete/<module>/<what>``:
    copro's logs cut short by a full disk): each is named once as it appears, and makes the run's
    exit code 1 (:meth:`failure`). Tokens declared before :meth:`start` are seen too (history)."""

    def __init__(self) -> None:
        self.seen: list[str] = []
        self._lock = threading.Lock()
        self._subscriber: Any = None

    def start(self, launcher: Any) -> None:
        import zenoh

        from modules.description import keys as robot_keys

        def on_token(sample: zenoh.Sample) -> None:
            if sample.kind != zenoh.SampleKind.PUT:
                return
            module, what = str(sample.key_expr).split("/")[-2:]
            text = f"{module}'s {what} were cut short (its line above names the file): this run is not whole"
            with self._lock:
                if text in self.seen:
                    return
                self.seen.append(text)
            launcher.say(text, name="robot")

        key = robot_keys.incomplete(launcher.ring)
        self._subscriber = launcher.session.liveliness().declare_subscriber(key, on_token, history=True)

    def failure(self) -> str | None:
        with self._lock:
            return "; ".join(self.seen) or None
