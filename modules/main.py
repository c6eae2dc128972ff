"""ROBMAIN, the main computer (seed §4.3.6): navigator and pilot, cooperative, two pairs.

Pair 1 runs Explore 1 (avoid, turn 90° toward the side with more room), pair 2 Explore 2
(left-wall following); the calibration run uses pair 1's pilot. Navigator and pilot alternate
once per token visit: while the pilot has a sequence it is stepped with the sensors decoded from
the token; when it finished (done or aborted) the navigator plans the next sequence.

Started and stopped by commands (EXPLORE mode, STOP_EXPLORE, CALIBRATE, CLEAR_MAP — from the
LCD keypad; CALIBRATE_COMPASS — from the compass, asked to calibrate) or over the PC link
(``on_pc_request``: ``explore``, ``stop``, ``calibrate``, ``calibrate_compass``, ``clear_map``,
``get_map``, ``actions`` (an action file's text; ``append``: queued behind a file under way, the
seed's queueing actions), ``state`` (with ``queue``, the actions not yet done)). ``main.data`` carries the navigator state, the mode,
the pilot's last abort reason, the ALERT lock and the number of planned steps.

The compass's calibration turn is pair 1's (seed 001 §4.3): :class:`CompassCalibration` tells the
compass to listen and has the pilot turn the robot once round in eight 45° stops, waiting at each
for the compass's samples (the compass never commands the motor).

A job of main's own (Explore 1 and 2, the calibration runs: the Hamburg robot's, whose drive
has no switch) on a drive that is off (``up --sensors darmstadt`` boots it off, as the Darmstadt
Pioneer's) gets one MOTORS_ON from main, logged, before its first move; an action file switches
the drive on itself with its ``e`` (seed 000 §6.7), as the seed's did, and gets none.

``--algorithms main=seed`` (read once in :meth:`Program.setup`) runs the seed's strategies and
pilot instead (:func:`explore_navigator`, :func:`make_pilots`): ALERT on any sonar, Explore 1's
turn stopped at the CLOSE area, Explore 2 the calibration run then plain left-wall following.
"""

from __future__ import annotations

import logging
import queue
from typing import Any

from modules.localization.pose_correction import CorrectionSettings, PoseCorrector
from modules.mapping.map_request import MapCollector
from modules.mapping.vectorgen import SonarLayout, default_layout
from modules.navigation.compass_turn import CompassCalibration
from modules.navigation.navigator import (
    NAV,
    Calibrate,
    ExploreAvoid,
    ExploreLeftWall,
    Navigator,
    SeedCalibrated,
    SeedExploreAvoid,
    SeedLeftWall,
)
from modules.navigation.pilot import (
    MOTOR_STATE,
    REASON,
    REASON_NAMES,
    STOPPED,
    Outcome,
    Pilot,
    PilotSettings,
    SeedPilot,
    Send,
    Sensors,
)
from modules.units import pose_from_wire
from modules.variants import algorithm
from tokenring import UsageError, UserProgram, default_protocol
from tokenring.runtime import current as current_runtime

log = logging.getLogger("tokenring.main")
NAV_NAMES = {v: k for k, v in NAV.items()}
COMPASS_CALIBRATING = default_protocol().enums["compass_state"]["CALIBRATING"]
#: motor.data samples (distinct stamps) still showing OFF after main's MOTORS_ON that mean the
#: motor did not take it (up to three can predate it: see PilotSettings.off_samples); the job
#: then plans, and its first move ends MOTORS_OFF
POWER_SAMPLES = 4


def explore_navigator(mode: int, layout: SonarLayout, seed: bool) -> tuple[Navigator, int] | None:
    """The navigator for EXPLORE ``mode`` and the pair that runs it (None: no such mode). The
    seed's (seed §4.3.6, §4.4): Explore 1's turn stops at the CLOSE area; Explore 2 is the
    calibration run and then plain left-wall following. Ours: :class:`ExploreAvoid`,
    :class:`ExploreLeftWall`."""
    if mode == 1:
        return (SeedExploreAvoid(layout) if seed else ExploreAvoid(layout)), 1
    if mode == 2:
        return (SeedCalibrated(layout, SeedLeftWall(layout)) if seed else ExploreLeftWall(layout)), 2
    return None


def make_pilots(layout: SonarLayout, send: Send, seed: bool) -> dict[int, Pilot]:
    """The two navigator/pilot pairs' pilots; the seed's watch every sonar for ALERT on every move."""
    pilot = SeedPilot if seed else Pilot
    return {1: pilot(layout, send), 2: pilot(layout, send, PilotSettings())}


class Program(UserProgram):
    module = "main"

    def setup(self) -> None:
        os = self.os
        self.out = os.publish()
        os.set_own_input_id()
        self.sonar = os.subscribe("sonar.data")
        self.motor = os.subscribe("motor.data")
        self.copro = os.subscribe("copro.data")
        self.compass = os.subscribe("compass.data")
        self.layout = default_layout(algorithm("body"))
        self.seed = algorithm("main") == "seed"  # the seed's strategies and pilot (issue 20)
        # two navigator/pilot pairs so that two strategies can be compared (the seed's design)
        self.pilots = make_pilots(self.layout, self._send, self.seed)
        self.navigator: Navigator | None = None
        self.pilot: Pilot | None = None
        self.pair = 0
        self.last_outcome: Outcome | None = None
        self.last_outcome_logged = "start"
        self.abort_reason = REASON["NONE"]
        self.rt = current_runtime()  # the clock and queues: the process's, or a simulation's
        self.requests: queue.Queue[tuple[str, dict[str, Any], queue.Queue[Any]]] = self.rt.queue()
        self.collector = MapCollector()
        self.history: list[dict[str, Any]] = []
        self.finished: dict[str, Any] | None = None
        self.started = self.rt.monotonic()
        self.sensors = Sensors()
        #: the fused heading at rest before the compass's calibration turn: where an action file
        #: run after it should start from (the turn ends a few degrees off, up to 11° seen)
        self.rest_heading: float | None = None
        self.rest_filtered = False  # rest_heading is the fused heading (not the motor's)
        self.calibration_heading: float | None = None
        self.compass_calibrating = False  # compass.data says CALIBRATING (read with the sensors)
        # self-localisation (seed §4.3 item 5): the filtered pose corrects the motor between moves
        self.corrector = PoseCorrector(CorrectionSettings.from_env())
        #: main's MOTORS_ON for its own job: None (none sent for this job), the stamps of the
        #: motor.data samples seen OFF since it was sent, or "on" once motor.data showed it
        self.job_power: set[int] | str | None = None
        self.motors_on_sent = 0  # MOTORS_ON main sent for its own jobs
        self._publish()

    # -- sending ------------------------------------------------------------------------------------
    def _send(self, target: str, command: str, **args: Any) -> None:
        """The pilot's and navigator's commands: delivered (resent until acknowledged)."""
        if not self.os.deliver(target, command, timeout=3.0, **args):
            log.warning("%s did not take %s %s", target, command, args)

    # -- the loop -------------------------------------------------------------------------------------
    def run(self) -> None:
        while self.running:
            self.os.wait_visit(0.2)
            self._take_commands()
            self._take_requests()
            self.sensors = self._read_sensors()
            self._note_calibration_turn()
            self._observe_poses()
            try:
                self._cooperate()
            except Exception as exc:  # a strategy's bug stops the exploration, not main
                log.exception("navigator/pilot failed")
                self.stop_explore(f"failed: {type(exc).__name__}: {exc}")
            self._publish()

    def _take_commands(self) -> None:
        while (command := self.os.receive_command(timeout=0)) is not None:
            self.handle_command(command.name, command.args)

    def handle_command(self, name: str, args: dict[str, Any]) -> None:
        if self.collector.feed(name, args):
            return
        if name == "POSITION_REACHED":
            if self.pilot is not None:
                self.pilot.note_position_reached(args["status"], args["move_seq"])
        elif name == "EXPLORE":
            self.start_explore(int(args.get("mode", 2)))
        elif name == "STOP_EXPLORE":
            self.stop_explore("stopped")
        elif name == "CALIBRATE":
            self.start(Calibrate(self.layout), 1)
        elif name == "CALIBRATE_COMPASS":
            self.start(CompassCalibration(self.layout), 1)
        elif name == "CLEAR_MAP":
            self._send("map", "CLEAR_MAP")
        elif name == "ERROR":
            log.warning("error reported to main: %s", args)
            if self.pilot is not None:
                self.pilot.note_error(args["error"], args["about"])

    def _read_sensors(self) -> Sensors:
        sonar, motor, copro, compass = (
            self.sonar.read(),
            self.motor.read(),
            self.copro.read(),
            self.compass.read(),
        )
        pose, pose_ms = None, None
        if copro["pose_source"]:
            pose = pose_from_wire(copro["pose_x_mm"], copro["pose_y_mm"], copro["pose_angle_cdeg"])
            pose_ms = copro["pose_stamp_ms"]
        elif self.motor.published:
            pose = pose_from_wire(motor["x_mm"], motor["y_mm"], motor["angle_cdeg"])
            pose_ms = motor["stamp_ms"]
        self.compass_calibrating = bool(self.compass.visits) and compass["state"] == COMPASS_CALIBRATING
        heading = compass["heading_cdeg"] if self.compass.visits and not self.compass_calibrating else None
        return Sensors(
            distances=list(sonar["distances"]) if self.sonar.visits else [255] * 8,
            sweep=sonar["sweep"],
            left_contact=copro["left_contact"],
            right_contact=copro["right_contact"],
            motor_state=motor["state"],
            motor_direction=motor["direction"],
            move_seq=motor["move_seq"],
            distance_mm=motor["distance_mm"],
            stamp_ms=motor["stamp_ms"]
            if self.motor.visits
            else int((self.rt.monotonic() - self.started) * 1000),
            sweep_ms=sonar["stamp_ms"] if self.sonar.visits else None,
            pose=pose,
            pose_ms=pose_ms,
            heading_cdeg=heading,
            pose_filtered=copro["pose_source"] == 2,
            ready=bool(self.sonar.visits and sonar["sweep"] and self.motor.visits and motor["stamp_ms"]),
        )

    def _note_calibration_turn(self) -> None:
        """Keep the heading at rest; while the compass calibrates, hold the one from before. The
        fused heading's once copro has one; before that the motor's (where the robot was put
        down): a calibration turn started before copro's filter published (a slow start with
        --sensors darmstadt) left none, and the next action file ran 16° off into a wall."""
        sensors = self.sensors
        if self.compass_calibrating:
            if self.calibration_heading is None:
                self.calibration_heading = self.rest_heading
        elif (
            self.navigator is None
            and self.calibration_heading is None
            and sensors.pose is not None
            and (sensors.pose_filtered or not self.rest_filtered)
            and sensors.motor_state in (MOTOR_STATE["IDLE"], MOTOR_STATE["OFF"])  # (OFF: it stands)
        ):
            self.rest_heading = sensors.pose[2]
            self.rest_filtered = sensors.pose_filtered

    def _cooperate(self) -> None:
        """One turn of the seed's cooperative multitasking: pilot step, then navigator if free."""
        nav, pilot = self.navigator, self.pilot
        if nav is None or pilot is None:
            return
        outcome = pilot.step(self.sensors)
        if outcome is not None:
            self.last_outcome = outcome
            self.abort_reason = outcome.reason
            self.last_outcome_logged = (
                f"{outcome.reason_name}{'/' + outcome.trigger if outcome.trigger else ''}"
            )
            if outcome.reason == REASON["MOTORS_OFF"]:  # nothing moves until MOTORS_ON: no replanning
                self.stop_explore(f"failed: {outcome.trigger}")
                self.abort_reason = outcome.reason
                return
        if pilot.busy or not self.sensors.ready:  # no plan before sonar and motor have spoken
            return
        if self._power_drive(nav):  # main's own job on a drive that is off: MOTORS_ON first
            return
        if self._correct_motor():  # a correction under way: no move until motor and filter show it
            return
        if isinstance(nav, CompassCalibration):  # it waits on the compass's samples
            nav.observe_compass(self.compass.read() if self.compass.visits else None)
        moves = nav.plan(self.last_outcome, self.sensors, pilot.alert_lock)
        for target, command, args in nav.commands:
            self._send(target, command, **args)
        nav.commands.clear()
        self.last_outcome = None
        ended = self.last_outcome_logged
        if moves is None:
            self.stop_explore(nav.note or "done", aborted=False)
            return
        if moves:  # (an empty plan: the navigator waits at rest, e.g. for a turn to be judged)
            log.info(
                "%s after %s: %s",
                NAV_NAMES.get(nav.state, nav.state),
                ended,
                ", ".join(f"{m.label or m.direction} {m.amount}" for m in moves),
            )
        pilot.start(moves, self.sensors, keep_clear=nav.keeps_clear)

    def _power_drive(self, nav: Navigator) -> bool:
        """Before a move of main's own job (not an action file's: its ``e`` switches the drive on)
        with motor.data saying OFF at the job's first plan: MOTORS_ON, once per job, and no plan
        until motor.data shows the drive on (or :data:`POWER_SAMPLES` samples still show it
        off). Switched off later (the operator's ``d``), the drive stays off: the pilot's next
        move ends MOTORS_OFF and the job stops. True: wait."""
        if not nav.powers_the_drive or self.job_power == "on":
            return False
        off = self.sensors.motor_state == MOTOR_STATE["OFF"]
        if not off:  # on at the job's first plan, or after main's MOTORS_ON: never sent again
            self.job_power = "on"
            return False
        if self.job_power is None:
            log.info(
                "the drive is off: MOTORS_ON for %s (main's own job; an action file says e itself)",
                type(nav).__name__,
            )
            self._send("motor", "MOTORS_ON")
            self.motors_on_sent += 1
            self.job_power = set()
            return True
        assert isinstance(self.job_power, set)
        self.job_power.add(self.sensors.stamp_ms)
        return len(self.job_power) < POWER_SAMPLES

    def _observe_poses(self) -> None:
        """Feed motor.data and copro.data to the self-localisation (once both have spoken)."""
        if self.motor.visits and self.copro.visits:
            self.corrector.observe(self.motor.read(), self.copro.read())

    def _correct_motor(self) -> bool:
        """Between two pilot sequences: SET_GLOBAL_POSITION with the filtered pose when the
        corrector asks for it (seed §4.3 item 5, §4.3.3). True while a correction holds."""
        if not (self.motor.visits and self.copro.visits) or self.compass_calibrating:
            return self.corrector.holding  # (the calibration turn: the filter does not trust the compass)
        correction = self.corrector.correction(self.motor.read(), self.copro.read())
        if correction is not None:
            self._send("motor", "SET_GLOBAL_POSITION", **correction)
        return self.corrector.holding

    # -- exploration control ---------------------------------------------------------------------
    def start_explore(self, mode: int) -> None:
        chosen = explore_navigator(mode, self.layout, self.seed)
        if chosen is None:
            log.warning("EXPLORE mode %d unknown (1 = avoid, 2 = left wall)", mode)
            return
        self.start(*chosen)

    def start(self, navigator: Navigator, pair: int) -> None:
        if self.pilot is not None and self.pilot.busy:
            self.pilot.abort("USER")
            self._drain_pilot()
        self._leave_compass_calibration()
        self.navigator, self.pair, self.pilot = navigator, pair, self.pilots[pair]
        self.job_power = None
        self.last_outcome = None
        self.finished = None
        log.info("navigator %s started (pair %d)", type(navigator).__name__, pair)

    def stop_explore(self, why: str, aborted: bool = True) -> None:
        nav, pilot = self.navigator, self.pilot
        if nav is None:
            return
        if pilot is not None and pilot.busy:
            pilot.abort("USER")
            self._drain_pilot()
        self._leave_compass_calibration()
        from modules.navigation.actions import ActionNavigator

        if isinstance(nav, ActionNavigator) and nav.plan_steps.holding is not None:
            self._send("motor", "STOP")  # the seed's non-queueing v/c runs until stopped (§6.7)
        self._send("copro", "FLUSH")  # vectors held back for merging go to the map now
        self.finished = {
            "navigator": type(nav).__name__,
            "why": why,
            "steps": nav.steps,
            "state": NAV_NAMES.get(nav.state, nav.state),
        }
        if isinstance(nav, Calibrate | SeedCalibrated | CompassCalibration):
            self.finished["calibration"] = nav.result
        if isinstance(nav, ExploreLeftWall):
            self.finished["map"] = nav.completeness()
        self.history.append(self.finished)
        self.abort_reason = REASON["USER"] if aborted else REASON["DONE"]
        self.navigator = None
        log.info("navigator stopped: %s", why)

    def _leave_compass_calibration(self) -> None:
        """A compass calibration ended early (another navigator, STOP_EXPLORE): the compass stops
        listening, or it would take the next moves for its turn."""
        if isinstance(self.navigator, CompassCalibration):
            for target, command, args in self.navigator.cancel():
                self._send(target, command, **args)

    def _drain_pilot(self, timeout: float = 5.0) -> None:
        """Step the pilot until its abort finished (the motor stands still)."""
        assert self.pilot is not None
        deadline = self.rt.monotonic() + timeout
        while self.pilot.busy and self.rt.monotonic() < deadline and not self.os.stopping:
            self.os.wait_visit(0.2)
            self._take_commands()
            self.pilot.step(self._read_sensors())

    # -- PC link ------------------------------------------------------------------------------------
    def on_pc_request(self, verb: str, payload: dict[str, Any]) -> Any:
        """Called on the PC link's thread: hand the request to the program's loop and wait."""
        if verb == "state":
            return self.state()
        verbs = ("explore", "stop", "calibrate", "calibrate_compass", "clear_map", "get_map", "actions")
        if verb not in verbs:
            raise UsageError(f"main takes {', '.join(verbs)}, state — not {verb!r}")
        answer: queue.Queue[Any] = self.rt.queue()
        self.requests.put((verb, payload, answer))
        timeout = float(payload.get("timeout", 60.0))
        try:
            result = answer.get(timeout=timeout)
        except queue.Empty:
            raise UsageError(f"main did not finish {verb!r} within {timeout:.0f} s") from None
        if isinstance(result, Exception):
            raise result
        return result

    def _take_requests(self) -> None:
        while True:
            try:
                verb, payload, answer = self.requests.get_nowait()
            except queue.Empty:
                return
            try:
                answer.put(self._serve(verb, payload))
            except Exception as exc:
                answer.put(exc)

    def _serve(self, verb: str, payload: dict[str, Any]) -> Any:
        if verb == "explore":
            mode = int(payload.get("mode", 2))
            if mode not in (1, 2):
                raise UsageError(f"explore mode must be 1 or 2, not {mode}")
            self.start_explore(mode)
            return self.state()
        if verb == "stop":
            self.stop_explore("stopped from the PC")
            return self.state()
        if verb == "calibrate":
            self.start(Calibrate(self.layout), 1)
            return self.state()
        if verb == "calibrate_compass":  # the compass's calibration turn, by pair 1's pilot
            self.start(CompassCalibration(self.layout), 1)
            return self.state()
        if verb == "actions":  # an action file (seed 000 §6.7), run by pair 1's pilot
            from modules.navigation.actions import ActionNavigator, parse_actions

            name = str(payload.get("name", "<actions>"))
            actions = parse_actions(str(payload.get("text", "")), name, seed=self.seed)
            speed = int(payload.get("speed_pct", 50))
            running = self.navigator
            if payload.get("append") and isinstance(running, ActionNavigator):
                running.plan_steps.append(actions)  # the seed's queueing actions (§6.7)
                return self.state()
            start_heading, self.calibration_heading = self.calibration_heading, None
            navigator = ActionNavigator(
                self.layout, actions, speed_pct=speed, start_heading=start_heading, seed=self.seed
            )
            self.start(navigator, 1)
            return self.state()
        if verb == "clear_map":
            self._send("map", "CLEAR_MAP")
            return {"cleared": True}
        return {"vectors": self._get_map(float(payload.get("timeout", 30.0)))}

    def _get_map(self, timeout: float) -> list[list[int]]:
        """GET_MAP to the map module; the answer arrives through this loop's inbox."""
        self._flush_copro(timeout)
        self.collector.begin()
        self._send("map", "GET_MAP")
        deadline = self.rt.monotonic() + timeout
        last = -1
        while not self.collector.done.is_set():
            self.os.wait_visit(0.2)
            self._take_commands()
            received, _ = self.collector.progress()
            if received != last:
                last, deadline = received, self.rt.monotonic() + timeout
            if self.rt.monotonic() > deadline or self.os.stopping:
                raise UsageError(f"the map module did not answer GET_MAP within {timeout:.0f} s")
        vectors = self.collector.wait(0) or []
        return [list(v) for v in vectors]

    def _flush_copro(self, timeout: float) -> None:
        """FLUSH copro and wait until the vectors it still held are in the map's hands (its
        ``flushes_done`` moves on): a GET_MAP sent at once would overtake them. A FLUSH that
        copro does not acknowledge (no copro on the ring) is not waited for."""
        before = self.copro.read()["flushes_done"]
        if not self.os.deliver("copro", "FLUSH", timeout=3.0):
            log.warning("copro did not take FLUSH: asking the map without it")
            return
        deadline = self.rt.monotonic() + timeout
        while self.copro.read()["flushes_done"] == before:
            if self.rt.monotonic() > deadline or self.os.stopping:
                log.warning("copro did not report its flush within %.0f s", timeout)
                return
            self.os.wait_visit(0.2)
            self._take_commands()

    # -- outputs ------------------------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        nav = self.navigator
        pilot = self.pilot
        from modules.navigation.actions import ActionNavigator

        return {
            "queue": nav.plan_steps.queue() if isinstance(nav, ActionNavigator) else [],
            "navigator": NAV_NAMES.get(nav.state if nav else NAV["IDLE"]),
            "mode": nav.mode if nav else 0,
            "running": nav is not None,
            "steps": nav.steps if nav else 0,
            "abort_reason": REASON_NAMES.get(self.abort_reason),
            "alert_lock": pilot.alert_lock if pilot else STOPPED,
            "finished": self.finished,
            "pose": list(self.sensors.pose) if self.sensors.pose else None,
        }

    def _publish(self) -> None:
        nav, pilot = self.navigator, self.pilot
        self.out.write(
            navigator=nav.state if nav else NAV["IDLE"],
            explore_mode=nav.mode if nav else 0,
            abort_reason=self.abort_reason,
            alert_lock=pilot.alert_lock if pilot else STOPPED,
            steps_done=(nav.steps if nav else 0) & 0xFFFF,
            stamp_ms=int((self.rt.monotonic() - self.started) * 1000) & 0xFFFFFFFF,
        )

    def report(self) -> dict[str, Any]:
        return {**self.state(), "history": self.history, "motors_on_sent": self.motors_on_sent}
