"""The robot's side of LOPS: its WLAN receiver (the seed's LOPS module on the onboard PC, §6.2.5).

Packets arrive on ``tokenring/<ring>/robot/lops/packets`` as the LOPS PC sent them (tables 6.1
and 6.2, raw bytes); a :class:`~modules.lops.packets.PacketReader` takes them apart, resyncing
past a lost byte as the seed's did. Each packet is stamped with the robot's clock when it arrives
(the seed stamped LOPS's data on reception: LOPS carries a counter, no time). A data packet is
handed on as the values of one ``lops`` sample; a message packet as lopscpp's message, for the
error log. :class:`CoproHardware` is copro's hardware with it: the world's truth and this receiver.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable
from typing import Any, Protocol

from modules.description import keys as robot_keys
from modules.lops.packets import DataPacket, MessagePacket, PacketReader
from modules.world.clients import HardwareClient, TruthFeed

log = logging.getLogger("modules.lops")


class Clock(Protocol):
    def now_ms(self) -> float: ...


def sample_values(packet: DataPacket) -> dict[str, Any]:
    """A data packet as a sample's values: the counter, three distances (mm, None: nothing
    heard) and the position (mm, None: LOPS gave none this time)."""
    d1, d2, d3 = (None if v is None or not math.isfinite(v) else float(v) for v in packet.distances)
    position = packet.position
    return {
        "counter": int(packet.counter),
        "d1": d1,
        "d2": d2,
        "d3": d3,
        "x": None if position is None else float(position[0]),
        "y": None if position is None else float(position[1]),
    }


def message_record(packet: MessagePacket) -> tuple[str, str]:
    """lopscpp's message as an error-log record: its class letter (the message's first letter
    when it is one of the seed's I W E F D, else I) and the text."""
    text = packet.text.strip()
    if len(text) >= 2 and text[0] in "IWEFD" and text[1] == " ":
        return text[0], f"LOPS: {text[2:]}"
    return "I", f"LOPS: {text}"


class LopsReceiver:
    """Subscribes to LOPS's packets on one ring; ``on_data(stamp_ms, values)`` per data packet,
    ``on_message(stamp_ms, class_letter, text)`` per message (both on Zenoh's thread)."""

    def __init__(self, session: Any, ring: str, clock: Clock) -> None:
        self.session = session
        self.ring = ring
        self.clock = clock
        self.reader = PacketReader()
        self.received = 0
        self._lock = threading.Lock()
        self._sub: Any = None

    def subscribe(
        self,
        on_data: Callable[[int, dict[str, Any]], None],
        on_message: Callable[[int, str, str], None] | None = None,
    ) -> Any:
        """Start receiving; returns the subscription (``undeclare()`` ends it)."""

        def on_sample(sample: Any) -> None:
            try:
                raw = bytes(sample.payload.to_bytes())
                stamp = int(self.clock.now_ms())
                with self._lock:  # one stream: a packet may span two puts on a real link
                    packets = self.reader.feed(raw)
                    self.received += len(packets)
                for packet in packets:
                    if isinstance(packet, DataPacket):
                        on_data(stamp, sample_values(packet))
                    elif on_message is not None:
                        on_message(stamp, *message_record(packet))
            except Exception:  # a bad packet must not kill the subscriber thread
                log.exception("LOPS: a packet could not be taken")

        self._sub = self.session.declare_subscriber(robot_keys.lops(self.ring, "packets"), on_sample)
        return self._sub


class CoproHardware(TruthFeed):
    """Copro's hardware: the world's truth for the logs, and the onboard PC's WLAN receiver for
    LOPS's packets (:class:`LopsReceiver`), stamped with the robot's clock on arrival."""

    def __init__(self, session: Any, ring: str) -> None:
        super().__init__(session, ring)
        self._clock_client: HardwareClient | None = None

    def subscribe_lops(self, on_data: Any, on_message: Any = None) -> Any:
        """LOPS's data packets as ``on_data(stamp_ms, values)``, its messages as
        ``on_message(stamp_ms, class_letter, text)``; returns the subscription."""
        if self._clock_client is None:
            self._clock_client = HardwareClient(self.session, self.ring)
        return LopsReceiver(self.session, self.ring, self._clock_client.clock).subscribe(on_data, on_message)
