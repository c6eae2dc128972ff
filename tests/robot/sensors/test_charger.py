"""The charger: ADC arithmetic, the battery model's 45 minutes of driving, and the deep-discharge
cut stopping the ring (in-process ring; the launcher's side is in test_world_ring.py)."""

from __future__ import annotations

from dataclasses import replace

import pytest

from modules.description import Batteries, load_world
from modules.sensors import battery as algo
from modules.world.battery import MOTOR_PACK_A_PER_MOTOR_A, Battery
from modules.world.clients import ChargerHardware, MotorHardware
from modules.world.sim import Simulator
from tests.support.hwprograms import program
from tests.support.memring import MemoryRing, wait_for

ChargerProgram = program("charger")
MotorProgram = program("motor")


def test_adc_and_state_of_charge_arithmetic():
    assert algo.counts_to_value(1023, 15.0) == 15.0
    assert algo.state_of_charge(12.8, 1) == pytest.approx(1.0)
    assert algo.state_of_charge(36.6, 3) == pytest.approx(0.5)
    # under load the terminal voltage sags; the estimate adds the sag back
    assert algo.state_of_charge(36.6 - 3 * 2.67 * algo.BLOCK_RESISTANCE_OHM, 3, 2.67) == pytest.approx(0.5)
    assert algo.remaining_minutes(1.0, 1.0) == pytest.approx(45.0)
    assert algo.remaining_minutes(1.0, 0.1) == pytest.approx(30.0)  # the electronics give out first
    guard = algo.DischargeGuard()
    assert [guard.check(12.0, 31.0), guard.check(12.0, 31.4), guard.check(10.4, 36.0)] == [False, False, True]
    assert not algo.DischargeGuard().check(10.6, 31.6)


def test_a_full_motor_pack_drives_about_45_minutes_at_1_ampere():
    pack = Battery("motors", 3, 72.0, 1.0, current_a=MOTOR_PACK_A_PER_MOTOR_A)
    seconds = 0
    while not pack.deep_discharged():
        pack.drain(pack.current_a, 10.0)
        seconds += 10
    assert 40 <= seconds / 60 <= 46


def test_deep_discharge_stops_the_ring_and_cuts_the_power():
    base = load_world("empty")
    sim = Simulator(replace(base, batteries=Batteries(motors_soc=0.04)), seed=2, speed=40.0)
    ring = MemoryRing([10, 20, 80])
    main = ring.nodes[10]
    data = main.subscribe("charger.data")
    requests: list[str] = []
    charger_os = ring.nodes[80]
    charger_os.request_ring_shutdown = lambda reason: requests.append(reason) or True
    ring.nodes[20].start_program(MotorProgram, MotorHardware.local(sim))
    charger_os.start_program(ChargerProgram, ChargerHardware.local(sim))
    try:
        wait_for(lambda: data.visits and data.read()["stamp_ms"] > 0, 10, "charger data")
        first = data.read()
        assert first["state"] == 1 and first["motors_pct"] <= 6  # LOW
        assert 10_500 < first["motors_mv"] / 3 < 11_000 and first["electronics_mv"] > 12_500
        assert first["remaining_min"] <= 3
        assert main.deliver("motor", "MOVE_FORWARD", distance_mm=2500, speed_pct=100, timeout=5)
        wait_for(lambda: requests, 30, "a ring shutdown request")
        assert "deep discharge: motor battery" in requests[0]
        wait_for(lambda: data.read()["state"] == 2, 5, "SHUTDOWN on the ring")
        wait_for(lambda: not sim.truth()["relay"], 5, "the relays dropped")
        truth = sim.truth()
        assert truth["motors"]["soc"] < 0.034  # cut at the knee of the curve, before the pack is flat
        # with the relays open nothing moves any more
        x = truth["x_mm"]
        assert sim.motor_steps({"left": 100, "right": 100, "rate_hz": 184.5, "move": 99})["power"] is False
        assert sim.truth()["x_mm"] == x
    finally:
        for node_id in (20, 80):
            ring.nodes[node_id].stop_program()
        ring.close()
