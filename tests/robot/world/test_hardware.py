"""The hardware registry and clients: which modules have hardware, and clear errors without a world."""

from __future__ import annotations

import threading

import pytest

from modules.description import load_world
from modules.world.clients import (
    ChargerHardware,
    CompassHardware,
    HardwareError,
    MotorHardware,
    SonarHardware,
)
from modules.world.hardware import FACTORIES, open_hardware
from modules.world.sim import Simulator
from tokenring.transport.zenoh_config import make_config, open_session


def test_the_four_hardware_modules_have_clients_the_others_none():
    assert {m: FACTORIES[m] for m in ("motor", "sonar", "compass", "charger")} == {
        "motor": MotorHardware,
        "sonar": SonarHardware,
        "compass": CompassHardware,
        "charger": ChargerHardware,
    }
    assert open_hardware("map", None, "r") is None  # type: ignore[arg-type]
    assert isinstance(open_hardware("sonar", None, "r"), SonarHardware)  # type: ignore[arg-type]


def test_without_a_world_a_request_fails_with_a_clear_message():
    with open_session(make_config()) as session:
        # the client's own timeout is an hour: a request that ends at all, before the hang guard,
        # was ended by the 0.3 s it was given (no stopwatch: a loaded machine runs past those)
        motor = MotorHardware(session, "nobody-here", timeout=3600.0)
        failed: list[BaseException] = []
        done = threading.Event()

        def request() -> None:
            try:
                motor.request("motor/start", timeout=0.3)
            except BaseException as exc:  # handed to the test's thread
                failed.append(exc)
            finally:
                done.set()

        threading.Thread(target=request, daemon=True).start()
        assert done.wait(60), "the request did not end with its 0.3 s timeout"
        (error,) = failed
        assert isinstance(error, HardwareError)
        assert "no world simulator answered tokenring/nobody-here/hw/motor/start" in str(error)


def test_local_clients_answer_like_the_service_and_report_refusals():
    sim = Simulator(load_world("square"), seed=1, speed=100.0)
    motor = MotorHardware.local(sim)
    assert motor.start_pose() == (1000.0, 1000.0, 0.0) and motor.clock is sim.clock
    with pytest.raises(HardwareError, match="hw/motor/steps: left must be within"):
        motor.steps(10**6, 0, 100.0, 1, 1000)
    charger = ChargerHardware.local(sim)
    adc = charger.adc()
    assert adc["relay"] and 850 <= adc["electronics"] <= 880  # 12.8 V on a 15 V full scale
    assert charger.relay(False, "test")["relay"] is False and not sim.truth()["relay"]
    envelopes, _ = SonarHardware.local(sim).ping([1])
    assert envelopes[0].max() <= 5  # power cut: no transmitter, no echo
