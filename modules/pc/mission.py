"""The robot's jobs through main's PC link: exploration requests, and the mission of
``tokenring up --explore N --map-out FILE`` (explore, write the map, stop the ring)."""

from __future__ import annotations

import threading
from typing import Any

from tokenring import UsageError
from tokenring.runtime import current as current_runtime


def request(link: Any, action: str) -> dict[str, Any]:
    """Send one exploration request over a :class:`~tokenring.host.pclink.PcLink`."""
    if action in ("1", "2"):
        return link.request("explore", mode=int(action))
    if action == "stop":
        return link.request("stop")
    if action == "calibrate":
        return link.request("calibrate")
    return link.request("state")


def action_job(path: str, speed_pct: int, seed: bool) -> tuple[str, str, int]:
    """``--actions FILE``: the file checked (a bad one is refused, file:line, before anything
    starts; the seed's main takes v/c without a time) and the job a mission drives:
    (file name, text as main parses it, speed %)."""
    from pathlib import Path

    from modules.navigation.actions import load_actions
    from tokenring import read_text

    load_actions(path, seed=seed)
    return Path(path).name, read_text(path, "action file"), speed_pct


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
    against the simulator's true walls), then asks the launcher to stop.

    Its clock, sleeps and thread are the runtime's, and it reaches main and the world through
    :meth:`open_link`, :meth:`world_info` and :meth:`true_pose` (Zenoh here): ``tokenring sim``
    runs this same mission in virtual time on a PC link and a world in its own process."""

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
        #: fetch the map at the end even without ``map_out`` (the map's text: :attr:`map_text`)
        self.fetch_map = bool(map_out)
        self.map_text: str | None = None
        self.vectors: Any = None
        self.rt = current_runtime()
        self.thread: Any = None

    def start(self) -> None:
        self.started = self.rt.monotonic()
        self.thread = self.rt.spawn(self._run, "mission")

    # -- how the mission reaches the ring and the world (Zenoh; overridden in virtual time) ------
    def open_link(self) -> Any:
        """main's PC link, once it answers."""
        from tokenring.host import open_link

        return open_link(self.launcher.session, self.launcher.ring, wait=60.0)

    def world_info(self) -> dict[str, Any] | None:
        """The simulator's room (``world/info``), or None without one."""
        from modules.pc.mapfiles import live_world

        return live_world(self.launcher.session, self.launcher.ring)

    def end_pose(self, estimate: list[float] | None) -> dict[str, Any] | None:
        """main's pose ``estimate`` against the simulator's truth now (:func:`mapfiles.end_pose`)."""
        from modules.pc.mapfiles import end_pose

        return end_pose(self.launcher.session, self.launcher.ring, estimate)

    def say(self, text: str) -> None:
        self.launcher.say(text, name="explore")

    def failure(self, wait: float = 5.0) -> str | None:
        """Why the mission did not do its job (the run's exit code 1), or None: asked once the
        ring has stopped, it waits a moment for a map being written; a ``--map-out`` that was
        never written is a failure, whatever stopped the ring first."""
        if self.thread is not None:
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
        clock = self.rt.monotonic
        deadline = clock() + 60.0
        if end is not None:
            deadline = min(deadline, self.started + 0.5 * (end - self.started))
        seen_calibrating = False
        while clock() < deadline and not self._stopping():
            state = link.read("compass.data")["state"]
            seen_calibrating = seen_calibrating or state == 3
            if state == 1 and seen_calibrating:
                self.say("compass calibrated")
                return
            self.rt.sleep(0.5)
        self.say("the compass did not finish calibrating: exploring anyway")

    def _mission(self) -> None:
        clock = self.rt.monotonic
        link = self.open_link()
        deadline = clock() + 30.0
        while True:  # main's node answers before its program runs
            try:
                link.request("state")
                break
            except UsageError:
                if clock() > deadline or self._stopping():
                    raise
                self.rt.sleep(0.2)
        end = None
        if self.duration is not None:
            fetch_time = min(15.0, max(3.0, 0.15 * self.duration))
            end = self.started + self.duration - fetch_time
        if self.actions is not None:
            name, text, speed = self.actions
            self._calibrate_compass(link, end)
            state = link.request("actions", text=text, name=name, speed_pct=speed)
            self.say(f"driving {name}")
            while state.get("running") and not self._stopping() and (end is None or clock() < end):
                self.rt.sleep(0.5)
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
            while not self._stopping() and (end is None or clock() < end):
                self.rt.sleep(0.5)
                state = link.request("state")
                if not state.get("running"):
                    finished = state.get("finished") or {}
                    self.say(
                        f"exploration finished: {finished.get('why')}{describe_map(finished.get('map'))}"
                    )
                    break
                if clock() - last_report > 10.0:
                    self.say(describe(state))
                    last_report = clock()
            if self._stopping():
                return
            if state.get("running"):
                link.request("stop")
                self.say("exploration stopped (time is up)")
        if self.fetch_map and not self._stopping():
            self._take_map(link)

    def _take_map(self, link: Any) -> None:
        """Fetch the map through main, score it against the world's walls, keep its text and
        write ``map_out``."""
        import numpy as np

        from modules.pc.mapfiles import map_document, truth_from_info, write_map
        from modules.pc.mapscore import score_map

        got = link.request("get_map", timeout=60.0)
        vectors = self.vectors = np.asarray(got["vectors"], dtype=float).reshape(-1, 4) * 10.0
        info = self.world_info()
        world, truth = truth_from_info(info) if info is not None else (None, None)
        end = self.end_pose(link.request("state").get("pose"))
        if not self.map_out:
            self.score = score_map(vectors, truth) if truth is not None else None
            self.map_text = map_document(vectors, world, self.score, end)
            return
        self.score = write_map(vectors, self.map_out, truth, world, end=end, option="--map-out")
        self.map_text = map_document(vectors, world, self.score, end)
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
