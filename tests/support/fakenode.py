"""A node OS stand-in for a robot program's ``setup`` and loop, without a ring: channel buffers
the test fills, outputs that keep what was written, deliveries recorded (and always taken)."""

from __future__ import annotations

from typing import Any

from tokenring.contract.protocol import default_protocol


class FakeBuffer:
    """A subscribed channel: ``set`` as if a visit had copied it, ``read`` as the program does."""

    def __init__(self) -> None:
        self.values: dict[str, Any] = {}
        self.visits = 0
        self.published = False

    def set(self, values: dict[str, Any]) -> None:
        self.values, self.visits, self.published = dict(values), self.visits + 1, True

    def read(self) -> dict[str, Any]:
        return dict(self.values)


class FakeOut:
    """The program's own data channel: the last fields written."""

    def write(self, **fields: Any) -> None:
        self.fields = fields


class FakeOS:
    """What the programs' setup and loops use of the node OS."""

    protocol = default_protocol()
    stopping = False

    def __init__(self) -> None:
        self.buffers: dict[str, FakeBuffer] = {}
        self.delivered: list[tuple[str, str, dict[str, Any]]] = []

    def publish(self) -> FakeOut:
        return FakeOut()

    def subscribe(self, name: str) -> FakeBuffer:
        return self.buffers.setdefault(name, FakeBuffer())

    def set_own_input_id(self) -> None:
        pass

    def receive_command(self, timeout: float = 0) -> None:
        return None

    def deliver(self, module: str, command: str, timeout: float = 0, **args: Any) -> bool:
        self.delivered.append((module, command, args))
        return True
