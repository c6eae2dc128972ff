"""What users would otherwise pick: the ring over plain UDP sockets or over ZeroMQ.

Both carry the same three things as the Zenoh backend — frames to a successor, small unicast
messages (pass acknowledgements) and ring-wide broadcasts — with a one-byte kind in front
(``F`` frame, ``M`` message); membership and addresses come from the TCP
:mod:`~tokenring.transport.registry`. Each node has one receive thread that calls the node OS's
handlers, as Zenoh's subscriber thread does. They exist to be compared with Zenoh in the
benchmark (``bench/RESULTS.md``): what a hand-made transport costs and what it lacks (no
routing across hosts, no discovery, no key space for tools to tap — the control plane of a node
process stays on Zenoh).

* ``udp``: one datagram per frame (``sendmsg`` gathers the kind byte and the frame without a
  copy). Loopback UDP does not lose datagrams in practice; where it does, the ring's own
  retries and regeneration recover, as they do over ARCNET.
* ``zmq``: a PULL socket per node, a PUSH socket per destination (``zmq.IMMEDIATE``, a small
  high-water mark, no linger, non-blocking sends: a stalled receiver drops frames rather than
  blocking the token handler), one message part per frame. ZeroMQ sockets are not
  thread-safe, so sends share one lock.
"""

from __future__ import annotations

import contextlib
import socket
import threading
from typing import Any

from tokenring.errors import TransportError
from tokenring.transport.base import FrameHandler, FrameSender, MembershipHandler, MessageHandler, Transport
from tokenring.transport.registry import RegistryClient

FRAME = b"F"
MESSAGE = b"M"


class SocketTransport(Transport):
    """Registry membership shared by the socket backends; subclasses move the bytes."""

    kind = "socket"

    def __init__(
        self, ring: str, node_id: int, registry: str, host: str = "127.0.0.1", frame_size: int = 514
    ):
        super().__init__(ring, node_id, frame_size)
        self.registry_address = registry
        self.host = host
        self.registry: RegistryClient | None = None
        self._thread: threading.Thread | None = None
        self._running = False

    # -- subclass hooks -------------------------------------------------------------------------
    def _bind(self) -> str:
        """Open the receiving socket; returns its address for the registry."""
        raise NotImplementedError

    def _receive_loop(self, on_frame: FrameHandler, on_message: MessageHandler) -> None:
        raise NotImplementedError

    def _send_to(self, did: int, kind: bytes, payload: bytes | bytearray) -> None:
        raise NotImplementedError

    def _address_changed(self, node_id: int, addr: str) -> None:
        pass

    def _close_sockets(self) -> None:
        raise NotImplementedError

    # -- Transport ------------------------------------------------------------------------------
    def _open(
        self, on_frame: FrameHandler, on_message: MessageHandler, on_membership: MembershipHandler
    ) -> set[int]:
        addr = self._bind()
        self._running = True
        self._thread = threading.Thread(
            target=self._receive_loop,
            args=(on_frame, on_message),
            name=f"{self.kind}-rx-{self.node_id}",
            daemon=True,
        )
        self._thread.start()
        client = RegistryClient(self.registry_address, self.node_id, addr)
        client.on_live = on_membership
        client.on_addr = self._address_changed
        self.registry = client
        return client.connect()

    def _sender(self, did: int) -> FrameSender:
        send = self._send_to
        return lambda frame: send(did, FRAME, frame)

    def _send_frame(self, did: int, frame: bytes | bytearray) -> None:
        self._send_to(did, FRAME, frame)

    def _send_message(self, did: int, payload: bytes) -> None:
        self._send_to(did, MESSAGE, payload)

    def _broadcast(self, payload: bytes) -> None:
        assert self.registry is not None
        for node_id in list(self.registry.addrs):
            with contextlib.suppress(OSError, TransportError, KeyError):
                self._send_to(node_id, MESSAGE, payload)

    def _announce(self) -> None:
        assert self.registry is not None
        self.registry.announce()

    def _withdraw(self) -> None:
        if self.registry is not None:
            with contextlib.suppress(OSError):
                self.registry.withdraw()

    def _close(self) -> None:
        self._running = False
        if self.registry is not None:
            self.registry.close()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(1.0)
        self._close_sockets()


class UdpTransport(SocketTransport):
    """One UDP socket per node; a datagram per frame or message."""

    kind = "udp"

    def _bind(self) -> str:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        sock.bind((self.host, 0))
        sock.settimeout(0.1)
        self._sock = sock
        self._addrs: dict[int, tuple[str, int]] = {}
        return f"{self.host}:{sock.getsockname()[1]}"

    def _address_changed(self, node_id: int, addr: str) -> None:
        host, _, port = addr.rpartition(":")
        self._addrs[node_id] = (host, int(port))

    def _sender(self, did: int) -> FrameSender:
        sendmsg, addrs = self._sock.sendmsg, self._addrs

        def send(frame: bytes | bytearray) -> None:
            sendmsg((FRAME, frame), (), 0, addrs[did])

        return send

    def _send_to(self, did: int, kind: bytes, payload: bytes | bytearray) -> None:
        self._sock.sendmsg((kind, payload), (), 0, self._addrs[did])

    def _receive_loop(self, on_frame: FrameHandler, on_message: MessageHandler) -> None:
        recv = self._sock.recv
        while self._running:
            try:
                data = recv(2048)
            except TimeoutError:
                continue
            except OSError:
                return
            if data[:1] == FRAME:
                on_frame(data[1:])
            elif data[:1] == MESSAGE:
                on_message(data[1:])

    def _close_sockets(self) -> None:
        self._sock.close()


#: frames and messages a PUSH socket may hold for one node (ZeroMQ's SNDHWM)
ZMQ_SEND_QUEUE = 1000


class ZmqTransport(SocketTransport):
    """A ZeroMQ PULL socket per node, PUSH sockets towards the others."""

    kind = "zmq"

    def _bind(self) -> str:
        import zmq

        self._zmq = zmq
        self._context = zmq.Context(io_threads=1)
        pull = self._context.socket(zmq.PULL)
        pull.setsockopt(zmq.RCVTIMEO, 100)
        pull.setsockopt(zmq.LINGER, 0)
        port = pull.bind_to_random_port(f"tcp://{self.host}")
        self._pull = pull
        self._push: dict[int, Any] = {}
        self._push_addr: dict[int, str] = {}
        self._lock = threading.Lock()
        return f"{self.host}:{port}"

    def _address_changed(self, node_id: int, addr: str) -> None:
        with self._lock:
            if self._push_addr.get(node_id) == addr:
                return
            old = self._push.pop(node_id, None)
            if old is not None:
                old.close(linger=0)
            zmq = self._zmq
            push = self._context.socket(zmq.PUSH)
            push.setsockopt(zmq.LINGER, 0)
            # a full pipe fails the token's send (EAGAIN). ZeroMQ tells the sender what left the
            # pipe only every SNDHWM/2 messages, and the sending thread reads that news at most
            # once a millisecond: with 16, a ring passing more than ~8 frames a millisecond to one
            # node (4 nodes in one process do) met a "full" pipe now and then, and lost the token
            push.setsockopt(zmq.SNDHWM, ZMQ_SEND_QUEUE)
            push.setsockopt(zmq.IMMEDIATE, 1)
            push.connect(f"tcp://{addr}")
            self._push[node_id] = push
            self._push_addr[node_id] = addr

    def _sender(self, did: int) -> FrameSender:
        lock, push, noblock = self._lock, self._push, self._zmq.NOBLOCK

        def send(frame: bytes | bytearray) -> None:
            message = FRAME + frame  # one part: cheaper than two sends, and copied before return
            with lock:
                push[did].send(message, noblock)

        return send

    def _send_to(self, did: int, kind: bytes, payload: bytes | bytearray) -> None:
        message = kind + payload
        with self._lock:
            self._push[did].send(message, self._zmq.NOBLOCK)

    def _receive_loop(self, on_frame: FrameHandler, on_message: MessageHandler) -> None:
        zmq = self._zmq
        recv = self._pull.recv
        while self._running:
            try:
                data = recv()
            except zmq.Again:
                continue
            except zmq.ZMQError:
                return
            if data[:1] == FRAME:
                on_frame(data[1:])
            elif data[:1] == MESSAGE:
                on_message(data[1:])

    def _close_sockets(self) -> None:
        with self._lock:
            for sock in self._push.values():
                sock.close(linger=0)
            self._push.clear()
        self._pull.close(linger=0)
        self._context.term()


BACKENDS: dict[str, type[SocketTransport]] = {"udp": UdpTransport, "zmq": ZmqTransport}
