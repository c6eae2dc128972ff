"""The web view's server: the page, a WebSocket of coalesced topics, and the buttons' actions.

::

    Zenoh ──► Feed (its thread) ──► Hub (latest value per topic) ──► every 100 ms, what changed
                                                                      ──► each browser's WebSocket
    browser ──► POST /api/fault  ──► tokenring.host.faults.FaultClient (as ``tokenring fault``)
            ──► POST /api/action/<name> ──► an extension's WebAction (e.g. Explore 2)
            ──► POST /api/key ──► an extension's KeyHandler (one per ring; one thread, in order)

A key handler's ``idle`` (renew what its keys hold) is called only while someone is there: a page
connected (its WebSocket open) or a key posted within :data:`KEY_LIFE_S` (a script). When the
last page goes, or a script falls silent, or the view stops, the handler's ``unattended`` is
called if it has one (stop what its keys hold): what the keys hold must not outlive its holder.

It is a tool on the ring like ``monitor``: it subscribes to the token's key expressions and asks
the nodes' control keys, and the token path never waits for it (a slow browser only delays its
own updates; the feed's queue is bounded). aiohttp serves it all from one asyncio loop; Zenoh's
blocking queries run on worker threads.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import json
import logging
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from aiohttp import WSMsgType, web

from tokenring._util.tables import json_default
from tokenring.contract.faults import KINDS, NEEDS_VALUE, parse_partition, validate
from tokenring.contract.protocol import Protocol
from tokenring.errors import TokenRingError, UsageError
from tokenring.extensions import KeyHandler, WebAction, WebKeys, WebPanel
from tokenring.host.faults import FaultClient
from tokenring.observe.feed import Feed, FeedSource
from tokenring.web.hub import Hub

log = logging.getLogger("tokenring.web")

STATIC = Path(__file__).resolve().parent / "static"
#: a browser gets at most this many updates a second
UPDATES_PER_S = 10.0
#: the fault kinds the page offers (``partition`` needs two groups: ``tokenring fault``)
PAGE_KINDS = (
    "delay", "drop", "corrupt", "duplicate", "lose", "partition", "heal", "hang", "resume", "crash", "clear",
)  # fmt: skip
#: the longest key name a page may send (``KeyboardEvent.key`` names are short)
MAX_KEY_CHARS = 32
#: without a page connected, a posted key keeps what the keys hold renewed this long
KEY_LIFE_S = 5.0


def dumps(value: Any) -> str:
    """JSON for the browser (numpy values, bytes and sets included; NaN and infinities null)."""
    try:
        return json.dumps(value, default=json_default, allow_nan=False)
    except ValueError:
        return json.dumps(_scrub(value), default=json_default, allow_nan=False)


def _scrub(value: Any) -> Any:
    """NaN and infinities (a sonar's "no echo") as null: JSON has no word for them."""
    if hasattr(value, "tolist"):
        value = value.tolist()
    if isinstance(value, float):
        return value if value == value and abs(value) != float("inf") else None
    if isinstance(value, dict):
        return {k: _scrub(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_scrub(v) for v in value]
    return value


class WebView:
    """One ring's web view: an aiohttp application over a :class:`Feed` and a :class:`Hub`."""

    def __init__(
        self,
        session: Any,
        ring: str,
        protocol: Protocol,
        sources: list[FeedSource],
        *,
        panels: list[WebPanel] | None = None,
        actions: list[WebAction] | None = None,
        keys: WebKeys | None = None,
        fault_timeout: float = 3.0,
        feed: Feed | None = None,
    ) -> None:
        self.session = session
        self.ring = ring
        self.protocol = protocol
        self.hub = Hub()
        #: a feed shared with other sinks (``tokenring watch``) is started and stopped by its owner
        self._owns_feed = feed is None
        self.feed = Feed(session, ring, sources) if feed is None else feed
        self.feed.add_sink(self.hub.on_message)
        self.panels = list(panels or [])
        self.actions = {action.name: action for action in actions or []}
        #: the keyboard: one handler, opened at the first key, fed by one thread in arrival order
        self.keys = keys
        self._key_handler: KeyHandler | None = None
        self._key_thread: concurrent.futures.ThreadPoolExecutor | None = None
        self._last_key = -math.inf  # when the last key was posted (time.monotonic)
        self.fault_timeout = fault_timeout
        self.nodes = {spec.id: spec.name for spec in protocol.nodes.values()}
        self._sockets: set[web.WebSocketResponse] = set()
        self.app = self._build()

    # -- the application --------------------------------------------------------------------
    def _build(self) -> web.Application:
        app = web.Application(middlewares=[same_origin_posts], client_max_size=64 * 1024)
        app.router.add_get("/", self.index)
        app.router.add_get("/api/config", self.config)
        app.router.add_get("/api/state", self.state)
        app.router.add_post("/api/fault", self.fault)
        app.router.add_post("/api/action/{name}", self.action)
        app.router.add_post("/api/key", self.key)
        app.router.add_get("/ws", self.websocket)
        app.router.add_static("/static/", STATIC)
        for panel in self.panels:
            app.router.add_static(f"/panels/{panel.name}/", panel.directory)
        return app

    async def index(self, request: web.Request) -> web.StreamResponse:
        return web.FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-cache"})

    async def config(self, request: web.Request) -> web.Response:
        """What the page builds itself from: the ring, its nodes, the fault kinds, panels, buttons."""
        return web.json_response(
            {
                "ring": self.ring,
                "nodes": [{"id": i, "name": n} for i, n in sorted(self.nodes.items())],
                "fault_kinds": list(PAGE_KINDS),
                "needs_value": {k: v for k, v in NEEDS_VALUE.items() if k in PAGE_KINDS},
                "panels": [
                    {"name": p.name, "title": p.title or p.name, "url": f"/panels/{p.name}/{p.module}"}
                    for p in self.panels
                ],
                "actions": [{"name": a.name, "label": a.label} for a in self.actions.values()],
                "keys": self._keys_config(),
                "enums": self.protocol.enums,
                "updates_per_s": UPDATES_PER_S,
            }
        )

    async def state(self, request: web.Request) -> web.Response:
        """Every topic's latest value at once (scripts; the page uses the WebSocket)."""
        version, topics = self.hub.changes(0)
        return web.Response(text=dumps({"v": version, "topics": topics}), content_type="application/json")

    async def websocket(self, request: web.Request) -> web.StreamResponse:
        """Everything once, then what changed, at most :data:`UPDATES_PER_S` times a second."""
        ws = web.WebSocketResponse(heartbeat=20.0)
        await ws.prepare(request)
        self._sockets.add(ws)
        reader = asyncio.create_task(_drain(ws))
        since = 0
        try:
            while not ws.closed and not reader.done():
                version, changed = self.hub.changes(since)
                if changed:
                    await ws.send_str(dumps({"v": version, "topics": changed}))
                    since = version
                await asyncio.sleep(1.0 / UPDATES_PER_S)
        except (ConnectionResetError, RuntimeError):
            pass  # the browser went away mid-send
        finally:
            reader.cancel()
            self._sockets.discard(ws)
            await ws.close()
            if not self._sockets:
                self._last_key = -math.inf  # a key the page sent last does not outlive it
                await self._release_keys("the last page closed")
        return ws

    async def fault(self, request: web.Request) -> web.Response:
        """Inject or clear a fault, as ``tokenring fault NODE KIND [VALUE]`` does."""
        try:
            body = await request.json()
        except ValueError:
            return _error("the body is not JSON")
        try:
            targets, fault = self.fault_request(body)
        except UsageError as exc:
            return _error(str(exc))
        loop = asyncio.get_running_loop()
        try:
            results = await loop.run_in_executor(None, self._inject, targets, fault)
        except TokenRingError as exc:
            return _error(str(exc), 502)
        return web.json_response({"ok": True, "request": fault, "results": results})

    def fault_request(self, body: Any) -> tuple[list[int], dict[str, Any]]:
        """The nodes and the validated request of a page's fault (raises :class:`UsageError`)."""
        if not isinstance(body, dict):
            raise UsageError('a fault is a JSON object like {"node": "lcd", "kind": "delay", "value": 20}')
        node, kind = body.get("node"), body.get("kind")
        if kind not in KINDS or kind == "list":
            raise UsageError(f"unknown fault kind {kind!r} (kinds: {', '.join(PAGE_KINDS)})")
        request = {k: body[k] for k in ("kind", "value", "jitter_ms", "count", "soft") if k in body}
        if kind in NEEDS_VALUE and body.get("value") in (None, ""):
            raise UsageError(f"{kind} needs a value: {kind} {NEEDS_VALUE[kind]}")
        if kind == "partition":
            request["groups"] = parse_partition(str(body.get("value")), self.resolve)
        fault = validate(request)
        targets = sorted(self.nodes) if node == "all" else [self.resolve(node)]
        return targets, fault

    def resolve(self, item: Any) -> int:
        """A node's ID from its name or ID (protocol.yaml's nodes only)."""
        for node_id, name in self.nodes.items():
            if item == name or str(item) == str(node_id):
                return node_id
        known = ", ".join(f"{n}={i}" for i, n in sorted(self.nodes.items()))
        raise UsageError(f"unknown node {str(item)[:40]!r} (protocol.yaml: {known})")

    def _inject(self, targets: list[int], fault: dict[str, Any]) -> list[dict[str, Any]]:
        client = FaultClient(self.session, self.ring, self.fault_timeout)
        results = []
        for node_id in targets:
            try:
                results.append(client.inject(node_id, fault))
            except UsageError as exc:  # this node did not answer: say so, try the others
                results.append({"id": node_id, "node": self.nodes[node_id], "error": str(exc)})
        return results

    async def action(self, request: web.Request) -> web.Response:
        """Run an extension's button (e.g. Explore 2) on a worker thread."""
        name = request.match_info["name"]
        action = self.actions.get(name)
        if action is None:
            return _error(f"no action {name[:40]!r} (actions: {', '.join(self.actions) or 'none'})", 404)
        loop = asyncio.get_running_loop()
        try:
            result = await loop.run_in_executor(None, action.run, self.session, self.ring)
        except TokenRingError as exc:
            return _error(f"{action.label}: {exc}", 502)
        return web.Response(text=dumps({"ok": True, "result": result}), content_type="application/json")

    # -- the keyboard ---------------------------------------------------------------------------
    def _keys_config(self) -> dict[str, Any] | None:
        if self.keys is None:
            return None
        listed = [{"label": k.label, "meaning": k.meaning, "values": list(k.values)} for k in self.keys.keys]
        return {"keys": listed, "note": self.keys.note}

    async def key(self, request: web.Request) -> web.Response:
        """Carry out one key the page had focus for (``{"key": KeyboardEvent.key}``), after every
        key posted before it; the answer is the handler's: one line of text, ok or not."""
        if self.keys is None:
            return _error("this web view takes no keys (no extension gives it a keyboard)", 404)
        try:
            body = await request.json()
        except ValueError:
            return _error("the body is not JSON")
        key = body.get("key") if isinstance(body, dict) else None
        if not isinstance(key, str) or not 0 < len(key) <= MAX_KEY_CHARS:
            return _error(f'a key is {{"key": NAME}}, NAME a KeyboardEvent.key of 1..{MAX_KEY_CHARS} chars')
        self._last_key = time.monotonic()
        outcome = await asyncio.get_running_loop().run_in_executor(self._keys_worker(), self._press, key)
        return web.Response(text=dumps({"key": key, **outcome}), content_type="application/json")

    def _keys_worker(self) -> concurrent.futures.ThreadPoolExecutor:
        """The one thread that carries keys out: what is submitted first is done first."""
        if self._key_thread is None:
            self._key_thread = concurrent.futures.ThreadPoolExecutor(
                1, thread_name_prefix="tokenring-web-keys"
            )
        return self._key_thread

    def _press(self, key: str) -> dict[str, Any]:
        """On the keys' thread: the handler's answer, ``{"text", "ok"}``."""
        assert self.keys is not None
        try:
            if self._key_handler is None:
                self._key_handler = self.keys.open(self.session, self.ring)
            answer = self._key_handler.press(key)
        except TokenRingError as exc:  # the handler could not be opened, or refused: say so, go on
            return {"text": str(exc), "ok": False}
        return {"text": str(answer.get("text", "")), "ok": bool(answer.get("ok", True))}

    def _idle(self) -> None:
        """On the keys' thread, between keys: the handler renews what its keys hold."""
        if self._key_handler is not None:
            try:
                self._key_handler.idle()
            except TokenRingError as exc:
                log.warning("keys: %s", exc)

    def _release(self, why: str) -> None:
        """On the keys' thread: the handler stops what its keys hold."""
        if self._key_handler is None:
            return
        try:
            answer = self._key_handler.unattended()
        except TokenRingError as exc:
            log.warning("keys (%s): %s", why, exc)
            return
        if isinstance(answer, dict) and answer.get("text"):
            log.info("keys (%s): %s", why, answer["text"])

    async def _release_keys(self, why: str) -> None:
        if self._key_handler is None or self._key_thread is None:
            return
        with contextlib.suppress(RuntimeError):  # the keys' thread is shut down: the view stopped
            await asyncio.get_running_loop().run_in_executor(self._key_thread, self._release, why)

    def _attended(self) -> bool:
        """A page is connected, or a key was posted a moment ago."""
        return bool(self._sockets) or time.monotonic() - self._last_key < KEY_LIFE_S

    async def _keep_alive(self, every_s: float) -> None:
        """Renew what the keys hold while someone is there; release it once nobody is."""
        loop = asyncio.get_running_loop()
        released = True
        while True:
            await asyncio.sleep(every_s)
            if self._key_handler is None:
                continue
            if self._attended():
                released = False
                await loop.run_in_executor(self._keys_worker(), self._idle)
            elif not released:
                released = True
                await self._release_keys("no page and no key")

    # -- running ------------------------------------------------------------------------------
    async def serve(
        self,
        host: str,
        port: int,
        ready: Callable[[str], None],
        stop: asyncio.Event,
        port_option: str = "--port",
    ) -> None:
        """Listen on ``host:port`` (0: any free port), call ``ready(url)``, serve until ``stop``
        (``port_option`` names the port in the message if it cannot be had)."""
        runner = web.AppRunner(self.app, handle_signals=False, access_log=None)
        await runner.setup()
        site = web.TCPSite(runner, host, port)
        try:
            await site.start()
        except OSError as exc:
            await runner.cleanup()
            why = "in use" if exc.errno == 98 else exc.strerror or str(exc)
            raise UsageError(f"{port_option} {port}: cannot listen on {host}:{port} ({why})") from None
        if self._owns_feed:
            self.feed.start()
        renew = asyncio.create_task(self._keep_alive(self.keys.idle_s)) if self.keys is not None else None
        try:
            bound = runner.addresses[0]
            where = f"[{bound[0]}]" if ":" in str(bound[0]) else str(bound[0])
            ready(f"http://{where}:{bound[1]}/")
            await stop.wait()
        finally:
            if renew is not None:
                renew.cancel()
            for ws in list(self._sockets):
                with contextlib.suppress(Exception):
                    await ws.close()
            await runner.cleanup()
            await self._release_keys("the web view stops")
            if self._key_thread is not None:  # a key under way ends first (a PC-link call: seconds)
                await asyncio.get_running_loop().run_in_executor(None, self._key_thread.shutdown)
            if self._owns_feed:
                await asyncio.get_running_loop().run_in_executor(None, self.feed.stop)


@web.middleware
async def same_origin_posts(request: web.Request, handler: Any) -> web.StreamResponse:
    """A POST (a fault, an action) must come from the page itself: JSON, and from this origin
    (another site open in the same browser cannot crash the ring)."""
    if request.method == "POST":
        origin = request.headers.get("Origin")
        if origin is not None and origin.split("://", 1)[-1] != request.host:
            return _error(f"a request from {origin[:80]} is not from this page", 403)
        if request.content_type != "application/json":
            return _error("send JSON (Content-Type: application/json)", 415)
    response: web.StreamResponse = await handler(request)
    return response


async def _drain(ws: web.WebSocketResponse) -> None:
    """Read what the browser sends (nothing but pings and the close) until it closes."""
    async for message in ws:
        if message.type == WSMsgType.ERROR:
            return


def _error(text: str, status: int = 400) -> web.Response:
    return web.json_response({"ok": False, "error": text}, status=status)
