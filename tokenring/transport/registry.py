"""Membership for the socket transports (``udp``, ``zmq``): who is live, and where to reach them.

Zenoh gives the ring liveliness tokens; a plain socket transport has nothing like it, so a small
TCP registry does that job. Every node keeps one TCP connection to it, says where its data socket
listens, and announces or withdraws its liveliness; the registry tells every connected node about
every change. A connection that closes (a crashed process) counts as withdrawn at once — as a
crashed Zenoh process's liveliness token vanishes — while a hung (SIGSTOPped) process keeps its
connection, so catching it is left to the ring's pass acknowledgement, as over Zenoh.

The launcher runs the registry in its own process (``Launcher(transport="udp")``); ``tokenring
node --transport udp --registry HOST:PORT`` reaches it. Messages are msgpack maps behind a 4-byte
big-endian length; they are rare (joins and leaves), never on the token path.
"""

from __future__ import annotations

import contextlib
import logging
import selectors
import socket
import struct
import threading
from collections.abc import Callable
from typing import Any

import msgpack

from tokenring.errors import TransportError, UsageError

log = logging.getLogger("tokenring.registry")
_LENGTH = struct.Struct(">I")
MAX_MESSAGE = 1 << 20


def parse_address(text: str) -> tuple[str, int]:
    """``HOST:PORT`` (or ``tcp/HOST:PORT``) as a socket address; a bad one is a usage error."""
    raw = text.removeprefix("tcp/")
    host, _, port = raw.rpartition(":")
    try:
        number = int(port)
    except ValueError:
        number = -1
    if not host or not 0 < number < 65536:
        raise UsageError(f"registry address {text!r} is not of the form HOST:PORT")
    return host, number


def _pack(message: dict[str, Any]) -> bytes:
    body = msgpack.packb(message)
    return _LENGTH.pack(len(body)) + body


class _Reader:
    """Reassembles length-prefixed messages from a byte stream."""

    def __init__(self) -> None:
        self.buffer = bytearray()

    def feed(self, data: bytes) -> list[dict[str, Any]]:
        self.buffer += data
        out = []
        while len(self.buffer) >= 4:
            (length,) = _LENGTH.unpack_from(self.buffer)
            if length > MAX_MESSAGE:
                raise TransportError(f"registry message of {length} bytes: not a registry peer")
            if len(self.buffer) < 4 + length:
                break
            out.append(msgpack.unpackb(bytes(self.buffer[4 : 4 + length]), strict_map_key=False))
            del self.buffer[: 4 + length]
        return out


def _closed(sock: socket.socket) -> bool:
    """Whether the peer of ``sock`` has closed it (its end is waiting to be read), without
    taking anything from it."""
    try:
        sock.settimeout(0.0)  # a timeout would first wait for it to be readable
        return sock.recv(1, socket.MSG_PEEK) == b""
    except BlockingIOError:
        return False
    except OSError:
        return True


class MembershipRegistry:
    """The registry server: one thread, one TCP connection per node."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0) -> None:
        self._server = socket.create_server((host, port), reuse_port=False)
        self._server.setblocking(False)
        self.address = f"{host}:{self._server.getsockname()[1]}"
        self._selector = selectors.DefaultSelector()
        self._selector.register(self._server, selectors.EVENT_READ, None)
        self._clients: dict[socket.socket, dict[str, Any]] = {}
        self._by_id: dict[int, socket.socket] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="membership-registry", daemon=True)

    def start(self) -> MembershipRegistry:
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2.0)
        for sock in list(self._clients):
            with contextlib.suppress(OSError):
                sock.close()
        self._server.close()
        self._selector.close()

    def live(self) -> list[int]:
        """IDs announced right now (for tests and diagnostics)."""
        return sorted(i for i, s in self._by_id.items() if self._clients.get(s, {}).get("live"))

    def _table(self) -> dict[str, Any]:
        addrs = {i: self._clients[s]["addr"] for i, s in self._by_id.items()}
        live = [i for i, s in self._by_id.items() if self._clients[s]["live"]]
        return {"op": "table", "addrs": addrs, "live": live}

    def _send(self, sock: socket.socket, message: dict[str, Any]) -> None:
        try:
            sock.settimeout(1.0)
            sock.sendall(_pack(message))
        except OSError as exc:
            log.debug("registry: cannot reach a node (%s); dropping it", exc)
            self._drop(sock)

    def _tell_all(self, message: dict[str, Any], but: socket.socket | None = None) -> None:
        for sock in list(self._clients):
            if sock is not but and self._clients.get(sock, {}).get("id") is not None:
                self._send(sock, message)

    def _drop(self, sock: socket.socket) -> None:
        client = self._clients.pop(sock, None)
        with contextlib.suppress(KeyError, ValueError, OSError):
            self._selector.unregister(sock)
        with contextlib.suppress(OSError):
            sock.close()
        if client is None or client.get("id") is None:
            return
        node_id = client["id"]
        if self._by_id.get(node_id) is sock:  # not when a respawned node already replaced it
            del self._by_id[node_id]
            if client["live"]:
                self._tell_all({"op": "live", "id": node_id, "alive": False})

    def _handle(self, sock: socket.socket, message: dict[str, Any]) -> None:
        client = self._clients[sock]
        op = message.get("op")
        if op == "hello":
            node_id = int(message["id"])
            old = self._by_id.get(node_id)
            if old is not None and old is not sock and self._clients.get(old, {}).get("live"):
                if _closed(old):  # a crashed holder whose end is not handled yet: a respawn
                    self._drop(old)
                else:  # two nodes under one ID would both take its token
                    self._send(sock, {"op": "refused", "id": node_id})
                    self._drop(sock)
                    return
            client.update(id=node_id, addr=message["addr"], live=False)
            self._by_id[node_id] = sock
            self._send(sock, self._table())
            self._tell_all({"op": "addr", "id": node_id, "addr": message["addr"]}, but=sock)
        elif op in ("announce", "withdraw") and client.get("id") is not None:
            alive = op == "announce"
            if client["live"] != alive and self._by_id.get(client["id"]) is sock:
                client["live"] = alive
                self._tell_all({"op": "live", "id": client["id"], "alive": alive})

    def _run(self) -> None:
        while not self._stop.is_set():
            for key, _ in self._selector.select(timeout=0.1):
                sock = key.fileobj
                if sock is self._server:
                    with contextlib.suppress(BlockingIOError):
                        conn, _ = self._server.accept()
                        conn.setblocking(False)
                        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                        self._clients[conn] = {"id": None, "live": False, "reader": _Reader()}
                        self._selector.register(conn, selectors.EVENT_READ, None)
                    continue
                assert isinstance(sock, socket.socket)
                try:
                    sock.settimeout(0.0)
                    data = sock.recv(65536)
                except BlockingIOError:
                    continue
                except OSError:
                    data = b""
                if not data:
                    self._drop(sock)
                    continue
                try:
                    for message in self._clients[sock]["reader"].feed(data):
                        self._handle(sock, message)
                except (TransportError, ValueError, KeyError, TypeError, msgpack.UnpackException) as exc:
                    log.warning("registry: bad message from a node (%s); dropping it", exc)
                    self._drop(sock)


AddressHandler = Callable[[int, str], None]
LiveHandler = Callable[[int, bool], None]


class RegistryClient:
    """One node's connection to the registry: address book and liveliness, kept current."""

    def __init__(self, address: str, node_id: int, data_address: str, timeout: float = 5.0) -> None:
        self.address = address
        self.node_id = node_id
        self.data_address = data_address
        self.addrs: dict[int, str] = {}
        self.live: set[int] = set()
        self.on_live: LiveHandler | None = None
        self.on_addr: AddressHandler | None = None
        self._timeout = timeout
        self._sock: socket.socket | None = None
        self._send_lock = threading.Lock()
        self._have_table = threading.Event()
        self._thread: threading.Thread | None = None
        self._closing = False
        self.refused = False  # the registry refused this node's ID: another node holds it live

    def connect(self) -> set[int]:
        """Connect, register the data address; returns the IDs live right now."""
        host, port = parse_address(self.address)
        try:
            sock = socket.create_connection((host, port), timeout=self._timeout)
        except OSError as exc:
            raise TransportError(f"cannot reach the membership registry at {self.address}: {exc}") from exc
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.settimeout(None)
        self._sock = sock
        self._thread = threading.Thread(target=self._read, name=f"registry-{self.node_id}", daemon=True)
        self._thread.start()
        self._send({"op": "hello", "id": self.node_id, "addr": self.data_address})
        if not self._have_table.wait(self._timeout):
            raise TransportError(f"the membership registry at {self.address} did not answer")
        if self.refused:
            self.close()
            raise UsageError(
                f"node ID {self.node_id} is already live at the membership registry {self.address}: "
                "a node must not join under an ID in use (stop that node or pick another --id)"
            )
        return set(self.live) - {self.node_id}

    def announce(self) -> None:
        self._send({"op": "announce"})

    def withdraw(self) -> None:
        self._send({"op": "withdraw"})

    def close(self) -> None:
        self._closing = True
        if self._sock is not None:
            with contextlib.suppress(OSError):
                self._sock.shutdown(socket.SHUT_RDWR)
            self._sock.close()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(1.0)

    def _send(self, message: dict[str, Any]) -> None:
        if self._sock is None:
            raise TransportError("not connected to the membership registry")
        with self._send_lock:
            self._sock.sendall(_pack(message))

    def _read(self) -> None:
        reader = _Reader()
        assert self._sock is not None
        while True:
            try:
                data = self._sock.recv(65536)
            except OSError:
                data = b""
            if not data:
                if not self._closing:
                    log.warning("lost the membership registry at %s", self.address)
                return
            for message in reader.feed(data):
                self._apply(message)

    def _apply(self, message: dict[str, Any]) -> None:
        op = message.get("op")
        if op == "refused":
            self.refused = True
            self._closing = True  # the registry closes the connection: no warning for that
            self._have_table.set()
            return
        if op == "table":
            self.addrs.update({int(k): v for k, v in message["addrs"].items()})
            self.live = {int(i) for i in message["live"]}
            self._have_table.set()
            for node_id, addr in self.addrs.items():
                if self.on_addr is not None:
                    self.on_addr(node_id, addr)
            return
        if op == "addr":
            node_id = int(message["id"])
            self.addrs[node_id] = message["addr"]
            if self.on_addr is not None:
                self.on_addr(node_id, message["addr"])
        elif op == "live":
            node_id, alive = int(message["id"]), bool(message["alive"])
            if alive:
                self.live.add(node_id)
            else:
                self.live.discard(node_id)
            if self.on_live is not None:
                self.on_live(node_id, alive)
