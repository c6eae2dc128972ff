"""The charger module (seed §3.3.7, "ROBLOAD"): watches both batteries, tells the ring what is left,
and switches everything off before a battery is deep-discharged.

Every 500 simulated ms it reads its ADC (both battery dividers and the current shunt) and
publishes the voltages, state of charge, the total current, an estimate of the driving time left
and its state (OK, LOW below 20 %, SHUTDOWN). When a 12 V block reads below 10.5 V three times
in a row — or on the SHUTDOWN command — it asks the launcher to stop the whole ring cleanly
(every node leaves and saves its data) and then drops the power relays.
"""

from __future__ import annotations

import logging

from modules.sensors.battery import (
    CURRENT_FULL_SCALE_A,
    ELECTRONICS_CURRENT_A,
    ELECTRONICS_FULL_SCALE_V,
    LOW_PERCENT,
    MOTORS_FULL_SCALE_V,
    DischargeGuard,
    Smoother,
    counts_to_value,
    remaining_minutes,
    state_of_charge,
)
from tokenring import UserProgram

log = logging.getLogger("tokenring.charger")

OK, LOW, SHUTDOWN = range(3)  # enum charger_state
SAMPLE_PERIOD_SIM_S = 0.5
MIN_PERIOD_REAL_S = 0.01


class Program(UserProgram):
    module = "charger"

    def setup(self) -> None:
        self.out = self.os.publish()
        self.os.set_own_input_id()
        self.clock = self.hw.clock
        self.guard = DischargeGuard()
        self.electronics_soc = Smoother()
        self.motors_soc = Smoother()
        self.state = OK
        self.reading: dict = {}
        self.shutdown_reason = ""
        self.ring_stop_answered: bool | None = None
        self.period_real = max(MIN_PERIOD_REAL_S, self.clock.to_real(SAMPLE_PERIOD_SIM_S))

    def run(self) -> None:
        while self.running and self.state != SHUTDOWN:
            self.sample()
            command = self.os.receive_command(timeout=self.period_real)
            if command is not None and command.name == "SHUTDOWN":
                self.shutdown(f"SHUTDOWN command from node {command.sender}")
        while self.running:  # after the cut: keep the SHUTDOWN state on the ring until stopped
            self.sleep(0.1)

    def sample(self) -> None:
        adc = self.hw.adc()
        electronics_v = counts_to_value(adc["electronics"], ELECTRONICS_FULL_SCALE_V)
        motors_v = counts_to_value(adc["motors"], MOTORS_FULL_SCALE_V)
        current_a = counts_to_value(adc["current"], CURRENT_FULL_SCALE_A)
        motors_a = max(0.0, current_a - ELECTRONICS_CURRENT_A)
        e_soc = self.electronics_soc.add(
            state_of_charge(electronics_v, 1, min(current_a, ELECTRONICS_CURRENT_A))
        )
        m_soc = self.motors_soc.add(state_of_charge(motors_v, 3, motors_a))
        minutes = remaining_minutes(m_soc, e_soc)
        self.reading = {
            "electronics_v": electronics_v,
            "motors_v": motors_v,
            "current_a": current_a,
            "electronics_soc": e_soc,
            "motors_soc": m_soc,
            "remaining_min": minutes,
            "stamp_ms": adc["stamp_ms"],
        }
        if self.guard.check(electronics_v, motors_v):
            which = "electronics" if electronics_v < 10.5 else "motor"
            volts = electronics_v if which == "electronics" else motors_v / 3
            self.shutdown(f"deep discharge: {which} battery at {volts:.2f} V per 12 V block (< 10.5 V)")
            return
        self.state = LOW if min(e_soc, m_soc) * 100 < LOW_PERCENT else OK
        self.publish()

    def publish(self) -> None:
        r = self.reading
        if not r:
            return
        self.out.write(
            electronics_mv=min(0xFFFF, round(r["electronics_v"] * 1000)),
            motors_mv=min(0xFFFF, round(r["motors_v"] * 1000)),
            electronics_pct=round(r["electronics_soc"] * 100),
            motors_pct=round(r["motors_soc"] * 100),
            remaining_min=min(0xFFFF, round(r["remaining_min"])),
            current_ma=min(0xFFFF, round(r["current_a"] * 1000)),
            state=self.state,
            stamp_ms=int(r["stamp_ms"]) & 0xFFFFFFFF,
        )

    def shutdown(self, reason: str) -> None:
        """Publish SHUTDOWN, have the ring stopped cleanly, then drop the power relays."""
        self.state = SHUTDOWN
        self.shutdown_reason = reason
        self.publish()
        log.warning("charger: %s: stopping the ring", reason)
        for _ in range(3):  # let the SHUTDOWN state travel round the ring
            self.os.wait_visit(0.2)
        self.ring_stop_answered = (
            bool(self.os.request_ring_shutdown(reason)) if self.os.request_ring_shutdown else None
        )
        if not self.ring_stop_answered:
            log.error("charger: no launcher stopped the ring; cutting the power anyway")
        self.hw.relay(False, reason)

    def report(self) -> dict:
        return {
            "state": self.state,
            "reading": dict(self.reading),
            "shutdown_reason": self.shutdown_reason,
            "ring_stop_answered": self.ring_stop_answered,
        }
