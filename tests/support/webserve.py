"""A web view served on a free port for one test, without a ring (its feed never starts)."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable

import aiohttp

from tokenring.contract.protocol import default_protocol
from tokenring.extensions import WebKeys
from tokenring.observe.feed import Feed
from tokenring.web.server import WebView


def view_of(keys: WebKeys | None) -> WebView:
    """A ring's web view with ``keys`` and nothing else."""
    return WebView(None, "keys", default_protocol(), [], keys=keys, feed=Feed(None, "keys", []))


def serve(
    keys: WebKeys | WebView | None, test: Callable[[str, aiohttp.ClientSession], Awaitable[None]]
) -> None:
    """Serve a web view (or one with ``keys``) on a free port and run ``test(url, client)`` on it."""
    view = keys if isinstance(keys, WebView) else view_of(keys)

    async def main() -> None:
        stop, ready = asyncio.Event(), asyncio.Event()
        url: list[str] = []

        def served(at: str) -> None:
            url.append(at)
            ready.set()

        server = asyncio.create_task(view.serve("127.0.0.1", 0, served, stop))
        await asyncio.wait_for(ready.wait(), 30)
        try:
            async with aiohttp.ClientSession() as client:
                await test(url[0], client)
        finally:
            stop.set()
            await server

    asyncio.run(main())
