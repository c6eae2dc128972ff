"""The web view's keyboard without a ring or a robot: an extension's :class:`WebKeys` as the
server serves it. One handler for the ring, opened at the first key (and again after it could
not be), keys carried out one at a time in the order they were posted, ``idle`` between keys,
and bad requests refused. The robot's handler: tests/robot/pc/test_web_keys.py; the page in a
browser on a live ring: tests/robot/pc/test_web_keys_browser.py."""

from __future__ import annotations

import asyncio
import json
import threading
import time
from collections.abc import Callable
from typing import Any

import aiohttp

from tests.support.webserve import serve, view_of
from tokenring.errors import TransportError
from tokenring.extensions import WebKey, WebKeys
from tokenring.web.server import WebView


class Handler:
    """Records what it is asked, from which thread and how many at once; the first key waits
    for :attr:`release` (a slow PC link: the keys after it must still come after it)."""

    def __init__(self) -> None:
        self.pressed: list[str] = []
        self.threads: set[str] = set()
        self.idles = 0
        self.busy = 0
        self.most_at_once = 0
        self.started = threading.Event()
        self.release = threading.Event()
        self.unattended_calls = 0

    def press(self, key: str) -> dict[str, Any]:
        self.threads.add(threading.current_thread().name)
        self.busy += 1
        self.most_at_once = max(self.most_at_once, self.busy)
        self.started.set()
        if not self.pressed:
            assert self.release.wait(60)
        self.pressed.append(key)
        self.busy -= 1
        return {"text": f"did {key}", "ok": key != "z"}

    def idle(self) -> None:
        self.idles += 1

    def unattended(self) -> None:
        self.unattended_calls += 1


async def until(condition: Callable[[], bool], timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        await asyncio.sleep(0.01)


def waiting(view: WebView) -> int:
    """Keys the server has handed to its keys' thread that have not started yet."""
    worker = view._key_thread
    return 0 if worker is None else worker._work_queue.qsize()  # type: ignore[attr-defined]


async def post(client: aiohttp.ClientSession, url: str, body: Any, **headers: str) -> tuple[int, dict]:
    data = body if isinstance(body, bytes) else json.dumps(body).encode()
    async with client.post(url, data=data, headers={"Content-Type": "application/json", **headers}) as answer:
        return answer.status, await answer.json()


def test_keys_reach_one_handler_in_order_on_one_thread_and_idle_runs_between() -> None:
    handler = Handler()
    opened: list[tuple[Any, str]] = []

    def open_handler(session: Any, ring: str) -> Handler:
        opened.append((session, ring))
        return handler

    keys = WebKeys([WebKey("↑", "faster", ("ArrowUp",)), WebKey("x/q", "nothing", ("x", "q"))], open_handler,
                   note="b is unbound", idle_s=0.2)  # fmt: skip
    view = view_of(keys)

    async def test(url: str, client: aiohttp.ClientSession) -> None:
        async with client.get(url + "api/config") as answer:
            config = await answer.json()
        assert config["keys"] == {
            "keys": [
                {"label": "↑", "meaning": "faster", "values": ["ArrowUp"]},
                {"label": "x/q", "meaning": "nothing", "values": ["x", "q"]},
            ],
            "note": "b is unbound",
        }
        assert config["enums"]["command_state"]["FREE"] == 0  # protocol.yaml's names for the panels
        sent = ["e", "ArrowUp", "ArrowUp", "ArrowLeft", " ", "z", "s"]
        # the first key is stuck on its way out; the others arrive meanwhile, each once the one
        # before is queued: they are done after it, one at a time, in the order they came
        answers = [asyncio.ensure_future(post(client, url + "api/key", {"key": sent[0]}))]
        await until(handler.started.is_set)
        for n, key in enumerate(sent[1:], start=1):
            answers.append(asyncio.ensure_future(post(client, url + "api/key", {"key": key})))
            await until(lambda n=n: waiting(view) == n)
        handler.release.set()
        results = await asyncio.gather(*answers)
        assert [r[0] for r in results] == [200] * len(sent)
        assert [r[1] for r in results] == [{"key": k, "text": f"did {k}", "ok": k != "z"} for k in sent]
        assert handler.pressed == sent and handler.most_at_once == 1
        before = handler.idles
        await until(lambda: handler.idles > before)  # renewed between keys

    serve(view, test)
    assert len(opened) == 1 and opened[0][1] == "keys"
    assert len(handler.threads) == 1 and next(iter(handler.threads)).startswith("tokenring-web-keys")


def test_a_handler_that_cannot_be_opened_is_the_keys_answer_and_tried_again() -> None:
    attempts: list[int] = []
    handler = Handler()
    handler.release.set()

    def open_handler(session: Any, ring: str) -> Handler:
        attempts.append(1)
        if len(attempts) == 1:
            raise TransportError("main does not answer on its PC link")
        return handler

    async def test(url: str, client: aiohttp.ClientSession) -> None:
        status, answer = await post(client, url + "api/key", {"key": "e"})
        assert status == 200 and answer == {
            "key": "e",
            "ok": False,
            "text": "main does not answer on its PC link",
        }
        status, answer = await post(client, url + "api/key", {"key": "e"})
        assert status == 200 and answer["ok"] and answer["text"] == "did e"

    serve(WebKeys([], open_handler), test)
    assert len(attempts) == 2


def test_bad_key_requests_are_refused_and_a_view_without_keys_says_so() -> None:
    never = Handler()

    async def test(url: str, client: aiohttp.ClientSession) -> None:
        cases: list[tuple[Any, dict[str, str], int, str]] = [
            (b"not json", {}, 400, "not JSON"),
            ([1, 2], {}, 400, '{"key": NAME}'),
            ({"key": ""}, {}, 400, '{"key": NAME}'),
            ({"key": 7}, {}, 400, '{"key": NAME}'),
            ({"key": "x" * 33}, {}, 400, '{"key": NAME}'),
            ({"key": "e"}, {"Origin": "http://evil.example"}, 403, "not from this page"),
        ]
        for body, headers, status, text in cases:
            got, answer = await post(client, url + "api/key", body, **headers)
            assert (got, answer["ok"]) == (status, False) and text in answer["error"], (body, answer)
        async with client.post(url + "api/key", data=b'{"key": "e"}') as answer:
            assert answer.status == 415  # JSON only, as every POST

    serve(WebKeys([], lambda session, ring: never), test)
    assert never.pressed == []

    async def without(url: str, client: aiohttp.ClientSession) -> None:
        async with client.get(url + "api/config") as answer:
            assert (await answer.json())["keys"] is None
        status, answer = await post(client, url + "api/key", {"key": "e"})
        assert status == 404 and "takes no keys" in answer["error"]

    serve(None, without)
