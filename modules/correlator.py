"""The correlator module (Darmstadt seed 000 §3.3, table 3.1): the floor correlator's translation on the ring.

Every 100 simulated ms it reads the sensor's serial line (the samples since the last read, one
every 40 ms or more) and adds their translation increments to a running sum. The data channel
always holds the newest: the sum (µm, wrapping i32: a reader takes differences between visits,
which is the seed's synchronisation, the sum of the increments), the newest increment, the
sample counter and the newest sample's stamp at the sensor. RESET starts the sum from 0.

The increments are the sensor's as they came: too large in a turn, bogus on the spot, now and
then in the wrong direction (§3.3); sorting that out takes another sensor (the Localizer's).
On the seed's body the sensor is defective, as seed 000's was: state DEFECTIVE, no samples.
"""

from __future__ import annotations

import logging

from modules.sensors.correlator import TranslationSum
from tokenring import UserProgram

log = logging.getLogger("tokenring.correlator")

STARTING, RUNNING, NO_DATA, DEFECTIVE = range(4)  # enum correlator_state
READ_PERIOD_SIM_S = 0.1  # the serial line is read this often; each read brings ~2 samples
MIN_PERIOD_REAL_S = 0.005
NO_DATA_READS = 10  # reads in a row without a sample (1 simulated s): state NO_DATA


class Program(UserProgram):
    module = "correlator"

    def setup(self) -> None:
        self.out = self.os.publish()
        self.os.set_own_input_id()
        self.clock = self.hw.clock
        self.state = STARTING
        self.sum = TranslationSum()
        self.empty_reads = 0
        self.resets = 0
        self.period_real = max(MIN_PERIOD_REAL_S, self.clock.to_real(READ_PERIOD_SIM_S))

    def take(self, increments: list[int], stamps: list[float], lost: int, defective: bool) -> None:
        """One read of the serial line: its samples, oldest first."""
        if defective:
            if self.state != DEFECTIVE:
                log.warning("correlator: the sensor is defective (the seed's body): no translation")
            self.state = DEFECTIVE
            return
        if lost and self.state == RUNNING:
            log.warning("correlator: %d samples lost (the serial line was not read in time)", lost)
        if increments:
            self.sum.add(increments, stamps, lost)
            self.state = RUNNING
            self.empty_reads = 0
            return
        self.empty_reads += 1
        if self.empty_reads == NO_DATA_READS:  # the sensor is silent (no power)
            log.warning("correlator: no samples in %d reads", NO_DATA_READS)
            self.state = NO_DATA

    def publish(self) -> None:
        self.out.write(
            forward_um=self.sum.total_um,
            increment_um=max(-(2**31), min(2**31 - 1, self.sum.newest_um)),
            sample=self.sum.samples & 0xFFFF,
            state=self.state,
            stamp_ms=int(self.sum.stamp_ms) & 0xFFFFFFFF,
        )

    def run(self) -> None:
        while self.running:
            self.take(*self.hw.read())
            self.publish()
            command = self.os.receive_command(timeout=self.period_real)
            if command is None:
                continue
            if command.name == "RESET":
                self.sum.reset()
                self.resets += 1
                log.info("correlator: the sum starts from 0 again")
            else:
                log.info("correlator: ignoring %s from node %d", command.name, command.sender)

    def report(self) -> dict:
        return {
            "state": self.state,
            "forward_um": self.sum.total_um,
            "samples": self.sum.samples,
            "backward": self.sum.backward,
            "backward_um": self.sum.backward_um,
            "lost": self.sum.lost,
            "resets": self.resets,
        }
