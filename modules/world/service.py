"""The world simulator on Zenoh: the hardware queryables, ground truth, and the ready token.

Keys (all under ``tokenring/<ring>/``; requests and answers are msgpack, answers are
``{"ok": true, "result": ...}`` or ``{"ok": false, "error": "..."}``):

==============================  =================================================================
key                             request → result
==============================  =================================================================
``hw/clock``                    ``{}`` → ``{sim_ms, speed, seed, world}``: the simulation clock
``hw/motor/steps``              ``{left, right, rate_hz, move, current_ma, energised}`` half-steps
                                both motors made since the last batch (signed, + = that track
                                forward); ``energised`` false switches the driver off (end of a
                                move: no current, no running field) →
                                ``{moved_mm, turned_rad, blocked, stalled, power, drive,
                                stamp_ms}``; without power (the relays, a flat battery, the
                                drive switched off: ``drive`` false) no step is made
``hw/motor/power``              ``{on: bool}`` → ``{drive}``: the drive's power switch (the
                                motor's MOTORS_OFF/ON); on at power-on
``hw/motor/start``              ``{}`` → ``{x_mm, y_mm, theta_rad}``: where the robot was put down at
                                power-on (the world's start pose; the motor's dead reckoning starts there)
``hw/sonar/ping``               ``{sensors: [i...], ping_samples, slot_ms}`` → ``{envelopes:
                                [510 bytes...], stamps_ms: [...], sample_us: 20}``
``hw/compass/measure``          ``{settings: [{flip: ±1, comp_ut: [c0, c1]}...], samples}`` →
                                ``{adc: [[bridge 0 counts], [bridge 1 counts]] per setting,
                                stamp_ms, sample_ms}`` (12-bit, mid-scale 2048)
``hw/charger/adc``              ``{}`` → ``{electronics, motors, current}`` 10-bit counts,
                                ``full_scale``, ``relay``, ``stamp_ms``
``hw/charger/relay``            ``{on: bool, reason}`` → ``{relay}``; off cuts all hardware
``hw/gyro/read``                ``{}`` → ``{raw: [counts...], stamps_ms, temperature_c, lost,
                                period_ms, power}``: every 20.48 ms sample since the last read
                                (:mod:`modules.world.gyroscope`; the devices of
                                :mod:`modules.world.devices`)
``hw/correlator/read``          ``{}`` → ``{increments_um: [...], stamps_ms, lost, power,
                                defective}``: every floor-correlator sample (40-60 ms apart)
                                since the last read (:mod:`modules.world.correlator`)
``world/truth``                 published ~10× per simulated second (at most 50 Hz real):
                                ground truth for logs and scoring only — ``stamp_ms`` (simulated
                                ms, int), ``t_ms`` (float), ``x_mm``, ``y_mm``, ``theta_rad`` (CCW
                                from +X; also as ``x``, ``y``, ``theta``), ``heading_rad`` (from
                                north, clockwise), ``moving``, ``collisions``, ``stalls``, ``steps``
                                [left, right] taken with power, ``drive`` (its switch),
                                ``steps_unpowered`` [left, right] that arrived without power and
                                were not made, ``glide_factor`` (this turn's true one),
                                ``relay``, ``electronics`` and ``motors`` ``{v, soc, a}``,
                                ``deep_discharge``, ``world``
``world/state``                 queryable: the same truth, now
``world/info``                  queryable: the room (:meth:`World.to_dict`), seed and speed
``world/control/pose``          ``{x_mm, y_mm, theta_rad}`` put the robot there (tests, tools)
``world/control/batteries``     ``{electronics, motors}`` set states of charge (tests, tools)
``world/alive``                 liveliness token: the simulator is up (the launcher waits for it)
==============================  =================================================================
"""

from __future__ import annotations

import contextlib
import logging
from typing import Any

import msgpack
import zenoh

from modules.description import keys as robot_keys
from modules.world.sim import HardwareRequestError, Simulator
from tokenring import keys
from tokenring.runtime import current as current_runtime

log = logging.getLogger("modules.world")
TRUTH_PERIOD_SIM_S = 0.1
TRUTH_MIN_REAL_S = 0.02


def hw_key(ring: str, what: str) -> str:
    """``tokenring/<ring>/hw/<what>``."""
    return f"{keys.PREFIX}/{ring}/hw/{what}"


def ready_key(ring: str) -> str:
    """The liveliness key the world holds while it serves (the launcher's ``ready_key``)."""
    return robot_keys.world(ring, "alive")


class WorldService:
    """Serves one :class:`Simulator` on a Zenoh session."""

    def __init__(self, sim: Simulator, session: zenoh.Session, ring: str) -> None:
        from modules.world.devices import attach_devices  # (they import the clients, which import us)

        self.sim = sim
        self.devices = attach_devices(sim)
        self.session = session
        self.ring = ring
        self.rt = current_runtime()
        self.stop = self.rt.event()
        self._declared: list[Any] = []
        self._publisher: Any = None
        self._thread: Any = None
        self.requests = 0

    def start(self) -> None:
        prefix = hw_key(self.ring, "")
        self._declared.append(
            self.session.declare_queryable(
                hw_key(self.ring, "**"), lambda q: self._answer(q, prefix, self._hardware)
            )
        )
        world_prefix = robot_keys.world(self.ring, "")
        self._declared.append(
            self.session.declare_queryable(
                robot_keys.world(self.ring, "**"), lambda q: self._answer(q, world_prefix, self._world)
            )
        )
        self._publisher = self.session.declare_publisher(robot_keys.world(self.ring, "truth"))
        self._thread = self.rt.spawn(self._publish_truth, "world-truth")
        self._declared.append(self.session.liveliness().declare_token(ready_key(self.ring)))

    def close(self) -> None:
        self.stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
        for item in reversed(self._declared):
            with contextlib.suppress(zenoh.ZError):
                item.undeclare()
        if self._publisher is not None:
            with contextlib.suppress(zenoh.ZError):
                self._publisher.undeclare()
        self._declared.clear()

    def _hardware(self, what: str, request: dict[str, Any]) -> Any:
        self.requests += 1
        device = self.devices.get(what.split("/", 1)[0])
        if device is not None:
            return device.handle(what, request)
        return self.sim.handle(what, request)

    def _world(self, what: str, request: dict[str, Any]) -> Any:
        if what in ("state", "truth"):
            return self.sim.truth()
        if what == "info":
            return self.sim.info()
        if what == "control/pose":
            return self.sim.set_pose(request)
        if what == "control/batteries":
            return self.sim.set_batteries(request)
        raise HardwareRequestError(
            f"no world verb {what!r} (have: state, info, control/pose, control/batteries)"
        )

    def _answer(self, query: zenoh.Query, prefix: str, handler: Any) -> None:
        what = str(query.key_expr)[len(prefix) :]
        try:
            payload = query.payload
            request = msgpack.unpackb(payload.to_bytes()) if payload is not None else {}
            if not isinstance(request, dict):
                raise HardwareRequestError("a request must be a msgpack map")
            result = {"ok": True, "result": handler(what, request)}
        except HardwareRequestError as exc:
            result = {"ok": False, "error": str(exc)}
        except Exception as exc:  # the world must survive any request
            log.exception("request %s failed", what)
            result = {"ok": False, "error": f"{type(exc).__name__}: {exc}"}
        query.reply(query.key_expr, msgpack.packb(result, default=_plain))

    def _publish_truth(self) -> None:
        period = max(TRUTH_MIN_REAL_S, self.sim.clock.to_real(TRUTH_PERIOD_SIM_S))
        clock = self.rt.monotonic
        next_at = clock()
        while not self.stop.is_set():
            try:
                self._publisher.put(msgpack.packb(self.sim.truth(), default=_plain))
            except zenoh.ZError:
                if self.stop.is_set():
                    return
                raise
            next_at += period
            self.stop.wait(max(0.0, next_at - clock()))


def _plain(value: Any) -> Any:
    if hasattr(value, "tolist"):
        return value.tolist()
    if hasattr(value, "item"):
        return value.item()
    return str(value)
