"""The motor module (seed §4.3.3): runs the drive commands on the two stepper motors.

Commands (protocol.yaml, ``motor``): MOVE_FORWARD / MOVE_REVERSE (mm, speed %), TURN_LEFT /
TURN_RIGHT (degrees, speed %), STOP, SET_GLOBAL_POSITION (x, y, angle), RECALC_GLIDE_FACTOR
(target angle, error), SET_WHEEL_SPEEDS (left %, right %, ms), MOTORS_OFF / MOTORS_ON. A
finished move sends POSITION_REACHED (status DONE, or COLLISION when the bumper hit, STALLED,
ABORTED when a new motion command or STOP replaced it) with ``move_seq`` = the sequence number of the command that
started it, to the module that sent that command. A SET_WHEEL_SPEEDS of the wheel speeds already
driven renews that move instead (the operator's held speed, renewed every second): it then ends
``duration_ms`` after the renewal, and the tracks step on without a pause or a reply.
SET_GLOBAL_POSITION and RECALC_GLIDE_FACTOR do not interrupt a move (the seed aborted on them,
which made corrections while driving impossible). Bad arguments (speed 0 or above 100 %, an
implausible glide correction) are refused with ERROR BAD_ARGUMENT to the sender: nothing moves.

The drive's power (the Darmstadt operator's keys ``d``/``e``, seed 000 §6.7, table 8.2): on at
boot, as the Hamburg drive has no switch, so nothing changes for a robot nobody switches off.
With ``TOKENRING_MOTOR_POWER=off`` (set by ``up --sensors darmstadt``) it boots off, as the
Darmstadt Pioneer did: it answered drive commands only after "Motoren an" (§6.7; §8.2: "first
switch the motors on, key e"), so an action file starts with ``e`` and the operator presses it.
MOTORS_OFF ends a move under way (POSITION_REACHED ABORTED, as for STOP), switches the drive
off in the world (``hw/motor/power``) and motor.data's ``state`` reads OFF until MOTORS_ON
powers it again (state IDLE; on already, MOTORS_ON leaves a move alone). While off, a move
command (MOVE_*, TURN_*, SET_WHEEL_SPEEDS) is refused with ERROR MOTORS_OFF to its sender and
one log line: nothing steps. STOP, SET_GLOBAL_POSITION and RECALC_GLIDE_FACTOR are taken as
always (no move to stop; the pose and the glide factor need no power).

Steps are issued on the simulation clock in small batches through the hardware client; the
dead-reckoned pose is computed from the steps issued (no encoders) and starts where the robot
was put down. The data channel carries the pose, direction, speed, distance driven since the last
move command, the cumulative left/right half-step counters and the time stamp of that sample.

The SIP stream (``TOKENRING_MOTOR_SIP_MS``, set by ``up --sensors darmstadt``; issue 53): the
Darmstadt robot's Pioneer sent its encoder counts in a SIP every 100 ms of its own clock. With
the setting, motor.data changes only at the grid times k·period of the motor's clock: each sample
is stamped with its grid time (a multiple of the period: the stamp is the SIP's number) and holds
the counters, pose and state as of that time; the loop wakes at each grid time and first issues
the steps due by then, so the counters are exactly the steps due at the grid time. Stepping,
move completion, replies and collision checks are unchanged: a move ending between grid times
replies at its end, and its last steps appear in the next grid sample. Off (default): a sample
on every loop tick, as before.

Seed mode (``--algorithms motor=seed``, issue 20) keeps the 2001 command semantics of seed
§4.3.3 (``move_forward``'s loop and the main loop's ``switch``): a command of the move's own kind
during a move is ignored ("Befehl falsch"); any other command, SET_GLOBAL_POSITION and
RECALC_GLIDE_FACTOR included, aborts it and is then carried out; POSITION_REACHED (always DONE)
follows a completed move only and is sent once, lost if the commander's inbox does not take it;
the motor never hears of a wall, a stall or lost power (no feedback: it issues every step and
reports DONE); SET_WHEEL_SPEEDS, not a seed command, only aborts a move (both tracks always step
together: straight moves and turns on the spot). The 2001 drive had no power switch either:
MOTORS_OFF is no seed command and only aborts a move (the drive stays on, the state never reads
OFF; a boot setting of off is ignored, the drive boots on), MOTORS_ON aborts a move and is
counted. Not the seed's: speed 0 and an undefined or implausible glide correction are still
refused with ERROR (the seed text says nothing of them; a 0 % move would never end), and speeds
above 100 % are accepted, as the seed had no check (the motor then stalls and loses its steps).
"""

from __future__ import annotations

import logging
import math
import os
from collections import deque

from modules.description.robot import (
    DEFAULT_MOTOR_CURRENT_MA,
    MAX_SPEED_MM_S,
    MOTOR_POWER_ENV,
    MOTOR_SIP_ENV,
    MOTOR_TICK_MS,
    STEP_MM,
)
from modules.sensors.odometry import (
    DeadReckoning,
    Move,
    recalc_glide_factor,
    step_rate_hz,
    steps_for_angle,
    steps_for_distance,
)
from modules.units import cdeg_to_rad, pose_to_wire
from modules.variants import algorithm
from tokenring import ChannelError, UserProgram
from tokenring.runtime import current as current_runtime

log = logging.getLogger("tokenring.motor")

STOPPED, FORWARD, REVERSE, TURN_LEFT, TURN_RIGHT = range(5)  # enum direction
IDLE, MOVING, STALLED_STATE, COLLISION_STATE, OFF = range(5)  # enum motor_state
DONE, ABORTED, STALLED, COLLISION = range(4)  # enum move_status
BAD_ARGUMENT, MOTORS_OFF = 2, 5  # enum error_code
#: what a move command is refused with while the drive is off (ERROR MOTORS_OFF, and the log)
OFF_PROBLEM = "motors are off: MOTORS_ON first"
TICK_SIM_S = MOTOR_TICK_MS / 1000.0  # a batch of steps every 20 simulated ms ...
TICK_MIN_REAL_S = 0.004  # ... but not more often than every 4 real ms
IDLE_PUBLISH_SIM_S = 0.05  # the counters' sample rate while standing
NOTICE_PATIENCE_S = 5.0  # real seconds a reply is offered to a target that does not take it
#: the seed's move commands by the direction they drive (seed §4.3.3: a move ignores its own kind)
SEED_MOVE_COMMANDS = {
    FORWARD: "MOVE_FORWARD",
    REVERSE: "MOVE_REVERSE",
    TURN_LEFT: "TURN_LEFT",
    TURN_RIGHT: "TURN_RIGHT",
}
#: the commands that drive the tracks: refused while the drive is off
MOVE_COMMANDS = (*SEED_MOVE_COMMANDS.values(), "SET_WHEEL_SPEEDS")


def sip_period_ms(environ: dict[str, str] | None = None) -> int:
    """The SIP stream's period from :data:`MOTOR_SIP_ENV` (ms; 0: off, a sample every tick)."""
    text = (os.environ if environ is None else environ).get(MOTOR_SIP_ENV, "").strip()
    if not text:
        return 0
    try:
        period = int(text)
    except ValueError:
        raise ValueError(f"{MOTOR_SIP_ENV}={text!r}: a whole number of ms expected") from None
    if period < 0:
        raise ValueError(f"{MOTOR_SIP_ENV}={text!r}: must not be negative")
    return period


def powered_at_boot(environ: dict[str, str] | None = None) -> bool:
    """The drive's power at boot from :data:`MOTOR_POWER_ENV`: on (unset, ``on``) or off (``off``)."""
    text = (os.environ if environ is None else environ).get(MOTOR_POWER_ENV, "")
    if text.strip().lower() in ("", "on"):
        return True
    if text.strip().lower() == "off":
        return False
    raise ValueError(f"{MOTOR_POWER_ENV}={text!r}: on or off expected")


class Program(UserProgram):
    module = "motor"

    def setup(self) -> None:
        self.seed = algorithm("motor") == "seed"
        self.out = self.os.publish()
        self.os.set_own_input_id()
        self.clock = self.hw.clock
        x, y, theta = self.hw.start_pose()
        self.odometry = DeadReckoning(x, y, theta)
        self.move: Move | None = None
        self.wheels: tuple[int, int] | None = None  # the wheel move under way's speeds (left, right %)
        self.renewals = 0  # SET_WHEEL_SPEEDS that renewed the wheel move under way
        self.move_seq = 0
        self.state = IDLE
        self.direction = STOPPED
        self.speed_pct = 0
        self.distance_mm = 0.0
        self.steps = [0, 0]
        self.current_ma = DEFAULT_MOTOR_CURRENT_MA
        self.notices: deque[tuple[str, str, dict]] = deque()
        self.notice_deadlines: dict[int, float] = {}
        self.in_flight: dict[str, tuple] = {}
        self.stamp_ms = self.clock.now_ms()
        self.moves = {"done": 0, "aborted": 0, "stalled": 0, "collision": 0}
        self.refused = 0
        self.powered = self._boot_power()
        self.hw.power(self.powered)
        if not self.powered:
            self.state = OFF
        self.motors_on = 0  # MOTORS_ON commands taken
        self.motors_off = 0  # MOTORS_OFF commands taken (seed mode: and ignored)
        self.ignored = 0  # seed mode: commands the seed dropped ("Befehl falsch", unknown ones)
        self.notices_lost = 0  # seed mode: replies the target did not take (sent once)
        self.last_move_ms = (0.0, 0.0)
        self.tick_real = max(TICK_MIN_REAL_S, self.clock.to_real(TICK_SIM_S))
        self.sip_ms = sip_period_ms()
        self.sips = 0  # SIP samples published
        self.sip_last_ms: int | None = None  # the grid time of the newest SIP sample
        self.sip_record: dict | None = None  # a SIP sample not yet written to motor.data
        if self.sip_ms:
            self._take_sip(self._sip_due(self.clock.now_ms()) or 0)
        self._publish()

    def _boot_power(self) -> bool:
        """On, as the Hamburg drive (no switch); off with the setting, as the Darmstadt Pioneer."""
        powered = powered_at_boot()
        if not powered and self.seed:
            log.info(
                "motor (seed): the 2001 drive has no switch: on at boot, %s=off ignored", MOTOR_POWER_ENV
            )
            return True
        if not powered:
            log.info("motor: the drive is off at boot (%s=off): MOTORS_ON (key e) powers it", MOTOR_POWER_ENV)
        return powered

    # -- the loop -------------------------------------------------------------------------------
    def run(self) -> None:
        idle_real = max(TICK_MIN_REAL_S, self.clock.to_real(IDLE_PUBLISH_SIM_S))
        while self.running:
            timeout = self.tick_real if self.move else idle_real
            if self.sip_ms:
                timeout = min(timeout, self._until_next_sip())
            command = self.os.receive_command(timeout=timeout)
            if self.sip_ms:
                self._sip_tick()
            if command is not None:
                self._handle(command)
            if self.move is not None:
                self._step()
            else:
                self.stamp_ms = self.clock.now_ms()
            self._publish()
            self._flush_notices()

    def _publish(self) -> None:
        """Write motor.data: the sample of now, or with the SIP stream the newest grid sample
        (once; between grid times motor.data keeps the last one)."""
        if not self.sip_ms:
            self.out.write(**self._record(self.stamp_ms))
        elif self.sip_record is not None:
            self.out.write(**self.sip_record)
            self.sip_record = None

    def _record(self, stamp_ms: float) -> dict:
        """motor.data's fields as they stand now, stamped ``stamp_ms``."""
        return dict(
            **pose_to_wire(self.odometry.x, self.odometry.y, self.odometry.theta),
            direction=self.direction,
            speed_pct=self.speed_pct,
            distance_mm=round(self.distance_mm),
            steps_left=self.steps[0],
            steps_right=self.steps[1],
            stamp_ms=int(stamp_ms) & 0xFFFFFFFF,
            move_seq=self.move_seq,
            state=self.state,
            glide_cfactor=min(0xFFFF, round(self.odometry.glide * 100)),
        )

    # -- the SIP stream ---------------------------------------------------------------------------
    def _sip_due(self, now_ms: float) -> int | None:
        """The newest grid time at or before ``now_ms`` not sampled yet (None: none)."""
        grid = int(now_ms // self.sip_ms) * self.sip_ms
        return grid if self.sip_last_ms is None or grid > self.sip_last_ms else None

    def _until_next_sip(self) -> float:
        """Real seconds until the next grid time (a little past it, so the loop wakes after it)."""
        last = self.sip_last_ms if self.sip_last_ms is not None else 0
        ahead_ms = last + self.sip_ms - self.clock.now_ms()
        return max(TICK_MIN_REAL_S / 4, self.clock.to_real(max(0.0, ahead_ms) / 1000.0) + 0.0005)

    def _sip_tick(self) -> None:
        """At a grid time passed since the last sample: issue the steps due by then, then take
        the sample (before a command that arrived after it is carried out)."""
        grid = self._sip_due(self.clock.now_ms())
        if grid is None:
            return
        if self.move is not None:
            self._step(grid)
        self._take_sip(grid)

    def _take_sip(self, grid: int) -> None:
        self.sip_last_ms = grid
        self.sip_record = self._record(grid)
        self.sips += 1

    # -- commands -------------------------------------------------------------------------------
    def _handle(self, cmd) -> None:
        name, args = cmd.name, cmd.args
        if self.seed and not self._seed_admit(cmd):
            return
        if name in MOVE_COMMANDS and not self.powered:
            self._refuse(cmd, OFF_PROBLEM, MOTORS_OFF)
        elif name in (*MOVE_COMMANDS, "STOP"):
            problem = self._check(name, args)
            if problem:
                self._refuse(cmd, problem)
                return
            if self.move is not None and self._renewal(name, args):
                self._extend(args["duration_ms"])
                return
            if self.move is not None:
                self._finish(ABORTED)
            if name != "STOP":
                self._start(cmd)
            elif self.powered:
                self.state, self.direction, self.speed_pct = IDLE, STOPPED, 0
        elif name == "SET_GLOBAL_POSITION":
            self.odometry.set(
                float(args["x_mm"]), float(args["y_mm"]), cdeg_to_rad(int(args["angle_cdeg"]) % 36000)
            )
        elif name == "RECALC_GLIDE_FACTOR":
            try:
                self.odometry.glide = recalc_glide_factor(
                    self.odometry.glide, float(args["target_deg"]), float(args["error_cdeg"]) / 100.0
                )
                log.info("glide factor now %.3f half-steps per degree", self.odometry.glide)
            except ValueError as exc:
                self._refuse(cmd, str(exc))
        elif name == "MOTORS_ON":
            self._motors_on()
        elif name == "MOTORS_OFF":
            self._motors_off()
        else:
            log.info("motor: ignoring %s from node %d", name, cmd.sender)

    def _motors_on(self) -> None:
        self.motors_on += 1
        if self.powered:
            log.info("motor: motors on (they are)")
            return
        self.hw.power(True)
        self.powered = True
        self.state = IDLE
        log.info("motor: motors on")

    def _motors_off(self) -> None:
        """Unpower the drive: a move under way ends ABORTED, the state reads OFF. Seed mode: ignored
        (the 2001 drive had no switch; :meth:`_seed_admit` aborted a move, as for any command)."""
        self.motors_off += 1
        if self.seed:
            self.ignored += 1
            log.info("motor (seed): MOTORS_OFF is not a seed command, ignored (the drive stays on)")
            return
        if self.move is not None:
            self._finish(ABORTED)
        self.hw.power(False)
        self.powered = False
        self.state, self.direction, self.speed_pct = OFF, STOPPED, 0
        log.info("motor: motors off (MOTORS_ON powers the drive again)")

    def _seed_admit(self, cmd) -> bool:
        """Seed §4.3.3: during a move, a command of the move's own kind is dropped and any other
        aborts the move (silently) before the main loop carries it out; SET_WHEEL_SPEEDS is no
        seed command (the main loop's ``default``). True: carry the command out."""
        if self.move is not None:
            if cmd.name == SEED_MOVE_COMMANDS.get(self.move.direction):
                self.ignored += 1
                log.info("motor (seed): %s during the same move ignored", cmd.name)
                return False
            self._finish(ABORTED)
        if cmd.name == "SET_WHEEL_SPEEDS":
            self.ignored += 1
            log.info("motor (seed): %s is not a seed command, ignored", cmd.name)
            return False
        return True

    def _check(self, name: str, args: dict) -> str:
        if name in ("MOVE_FORWARD", "MOVE_REVERSE", "TURN_LEFT", "TURN_RIGHT") and (
            args["speed_pct"] < 1 or (args["speed_pct"] > 100 and not self.seed)
        ):
            return f"speed {args['speed_pct']} % is outside 1..100 % (start-stop mode, no ramps)"
        if name == "SET_WHEEL_SPEEDS" and not (
            -100 <= args["left_pct"] <= 100 and -100 <= args["right_pct"] <= 100
        ):
            return "wheel speeds must be within -100..100 %"
        return ""

    def _renewal(self, name: str, args: dict) -> bool:
        """SET_WHEEL_SPEEDS of the speeds the wheel move under way drives."""
        return name == "SET_WHEEL_SPEEDS" and self.wheels == (int(args["left_pct"]), int(args["right_pct"]))

    def _extend(self, duration_ms: int) -> None:
        """The wheel move under way now ends ``duration_ms`` from now, as if it had been
        commanded that long in the first place: the steps due go on at the same rates."""
        move = self.move
        assert move is not None
        elapsed = max(0.0, (self.clock.now_ms() - move.start_ms) / 1000.0)
        seconds = elapsed + duration_ms / 1000.0
        move.total = (math.floor(move.rate_hz[0] * seconds), math.floor(move.rate_hz[1] * seconds))
        self.renewals += 1

    def _refuse(self, cmd, problem: str, error: int = BAD_ARGUMENT) -> None:
        self.refused += 1
        log.warning("motor: refused %s %s from node %d: %s", cmd.name, cmd.args, cmd.sender, problem)
        sender = self.os.protocol.by_id.get(cmd.sender)
        if sender is not None:
            self.notices.append((sender.name, "ERROR", {"error": error, "about": cmd.code}))

    def _start(self, cmd) -> None:
        name, args = cmd.name, cmd.args
        now = self.clock.now_ms()
        if name == "SET_WHEEL_SPEEDS":
            left, right = int(args["left_pct"]), int(args["right_pct"])
            seconds = args["duration_ms"] / 1000.0
            rates = (step_rate_hz(abs(left)), step_rate_hz(abs(right)))
            totals = (math.floor(rates[0] * seconds), math.floor(rates[1] * seconds))
            signs = (1 if left >= 0 else -1, 1 if right >= 0 else -1)
            if left + right != 0:
                direction = FORWARD if left + right > 0 else REVERSE
            else:
                direction = TURN_LEFT if right > left else TURN_RIGHT if left > right else STOPPED
            speed = max(abs(left), abs(right))
            self.wheels = (left, right)
        else:
            self.wheels = None
            speed = int(args["speed_pct"])
            if name in ("MOVE_FORWARD", "MOVE_REVERSE"):
                n = steps_for_distance(args["distance_mm"])
                signs = (1, 1) if name == "MOVE_FORWARD" else (-1, -1)
                direction = FORWARD if name == "MOVE_FORWARD" else REVERSE
            else:
                n = steps_for_angle(args["angle_deg"], self.odometry.glide)
                signs = (-1, 1) if name == "TURN_LEFT" else (1, -1)
                direction = TURN_LEFT if name == "TURN_LEFT" else TURN_RIGHT
            totals = (n, n)
            rates = (step_rate_hz(speed), step_rate_hz(speed))
        self.move_seq = cmd.seq & 0xFF  # the motor publishes its move number as a u8
        self.distance_mm = 0.0
        self.move = Move(self.move_seq, cmd.sender, direction, speed, totals, signs, rates, now)
        self.state, self.direction, self.speed_pct = MOVING, direction, speed
        if totals == (0, 0):
            self._finish(DONE)

    # -- stepping -------------------------------------------------------------------------------
    def _step(self, at_ms: float | None = None) -> None:
        """Issue the steps due by ``at_ms`` (default: now); finish the move when all are."""
        move = self.move
        assert move is not None
        now = self.clock.now_ms() if at_ms is None else at_ms
        elapsed = max(0.0, (now - move.start_ms) / 1000.0)
        due = (
            min(move.total[0], math.floor(elapsed * move.rate_hz[0])),
            min(move.total[1], math.floor(elapsed * move.rate_hz[1])),
        )
        new = (due[0] - move.issued[0], due[1] - move.issued[1])
        if new != (0, 0):
            left, right = new[0] * move.sign[0], new[1] * move.sign[1]
            result = self.hw.steps(left, right, max(move.rate_hz), move.seq, self.current_ma)
            move.issued = due
            self.steps[0] += left
            self.steps[1] += right
            self.odometry.apply(left, right)
            self.distance_mm += (abs(left) + abs(right)) / 2 * STEP_MM
            self.stamp_ms = min(
                now,
                move.start_ms
                + 1000.0 * max(t / r for t, r in zip(move.total, move.rate_hz, strict=True) if r > 0),
            )
            # seed §4.3.3: no feedback from the motors, every step counts as made
            status = None if self.seed else self._trouble(result)
            if status is not None:
                self._finish(status)
                return
        else:
            self.stamp_ms = now
        if move.issued == move.total:
            self._finish(DONE)

    @staticmethod
    def _trouble(result: dict) -> int | None:
        """What the power stage reported that ends a move: no power, a wall, a stall."""
        if not result["power"]:
            return ABORTED
        if result["blocked"]:
            return COLLISION
        if result["stalled"]:
            return STALLED
        return None

    def _finish(self, status: int) -> None:
        move = self.move
        assert move is not None
        self.move = None
        self.hw.steps(0, 0, max(move.rate_hz) or 1.0, move.seq, self.current_ma, energised=False)
        self.last_move_ms = (move.start_ms, self.stamp_ms)
        self.state = {DONE: IDLE, ABORTED: IDLE, STALLED: STALLED_STATE, COLLISION: COLLISION_STATE}[status]
        self.direction, self.speed_pct = STOPPED, 0
        self.moves[("done", "aborted", "stalled", "collision")[status]] += 1
        commander = self.os.protocol.by_id.get(move.commander)
        if self.seed and status != DONE:
            return  # seed §4.3.3: POSITION_REACHED only after a completed move
        if commander is not None and commander.name != self.os.name:
            self.notices.append(
                (commander.name, "POSITION_REACHED", {"status": status, "move_seq": move.seq})
            )

    def _flush_notices(self) -> None:
        """Send queued replies, one in flight per target (one inbox slot each). A reply the target
        did not take (its inbox was locked) is sent again, for up to ``NOTICE_PATIENCE_S``: the
        seed sent POSITION_REACHED once and lost it whenever the commander was not listening (seed
        mode does the same: no patience)."""
        now = current_runtime().monotonic()
        patience = 0.0 if self.seed else NOTICE_PATIENCE_S
        for target in list(self.in_flight):
            outbox, entry, deadline = self.in_flight[target]
            if not outbox.done.is_set():
                continue
            del self.in_flight[target]
            if not outbox.acknowledged and now < deadline:
                self.notices.appendleft(entry)
                self.notice_deadlines[id(entry)] = deadline
            elif not outbox.acknowledged and self.seed:
                self.notices_lost += 1
                log.info("motor: %s to %s not taken, given up", entry[1], entry[0])
        waiting = []
        while self.notices:
            entry = self.notices.popleft()
            target, name, args = entry
            deadline = self.notice_deadlines.pop(id(entry), now + patience)
            if target in self.in_flight:
                waiting.append(entry)
                self.notice_deadlines[id(entry)] = deadline
                continue
            try:
                self.in_flight[target] = (self.os.send_command(target, name, **args), entry, deadline)
            except ChannelError:
                waiting.append(entry)
                self.notice_deadlines[id(entry)] = deadline
        self.notices.extend(waiting)

    def report(self) -> dict:
        report = {
            "pose": [self.odometry.x, self.odometry.y, self.odometry.theta],
            "glide_factor": self.odometry.glide,
            "state": self.state,
            "moves": dict(self.moves),
            "refused": self.refused,
            "powered": self.powered,
            "motors_on": self.motors_on,
            "motors_off": self.motors_off,
            "renewals": self.renewals,
            "steps": list(self.steps),
            "last_move_ms": list(self.last_move_ms),
            "max_speed_mm_s": MAX_SPEED_MM_S,
        }
        if self.sip_ms:
            report.update(sip_period_ms=self.sip_ms, sips=self.sips)
        if self.seed:
            report.update(algorithm="seed", ignored=self.ignored, notices_lost=self.notices_lost)
        return report
