"""Serving control requests: every queryable of tokenring answers the same way.

A request is a Zenoh query on ``.../<verb>`` with an optional msgpack payload; the answer is
msgpack ``{"ok": True, "result": ...}`` or ``{"ok": False, "error": "..."}``. Used by the node's
``ctl/<ID>/*``, main's PC link ``pc/*`` and the launcher's ``ctl/launcher/*``.
"""

from __future__ import annotations

import contextlib
import logging
import threading
from collections.abc import Callable, Mapping
from typing import Any

import msgpack
import zenoh

from tokenring.errors import TokenRingError, UsageError

log = logging.getLogger("tokenring.control")
Handler = Callable[[dict[str, Any]], Any]


class AfterReply:
    """A handler's result plus what to do once the answer is on its way (a fault that stops
    the process must not stop it before its requester heard that it will)."""

    def __init__(self, result: Any, action: Callable[[], None]) -> None:
        self.result = result
        self.action = action


def _jsonable(value: Any) -> Any:
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, set | tuple):
        return list(value)
    return str(value)


def answer_query(
    query: zenoh.Query,
    handlers: Mapping[str, Handler],
    owner: str,
    lock: threading.Lock | None = None,
) -> None:
    """Run the handler of the query's verb and reply. A bad request gets an error answer (never
    a crashed process); a wildcard question (``ctl/*/stats``) about a verb this owner does not
    have gets no answer at all — it was meant for others."""
    key = str(query.key_expr)
    after: Callable[[], None] | None = None
    verb = key.rsplit("/", 1)[-1]
    handler = handlers.get(verb)
    if handler is None and "*" in key:
        return
    try:
        if handler is None:
            raise UsageError(f"{owner} has no verb {verb!r} (has: {', '.join(sorted(handlers))})")
        payload = query.payload
        request = msgpack.unpackb(payload.to_bytes()) if payload is not None else {}
        with lock if lock is not None else contextlib.nullcontext():
            answer = handler(request or {})
        if isinstance(answer, AfterReply):
            after, answer = answer.action, answer.result
        result = {"ok": True, "result": answer}
    except TokenRingError as exc:
        result = {"ok": False, "error": str(exc)}
    except Exception as exc:  # a control request must never take its owner down
        log.exception("%s: verb %s failed", owner, verb)
        result = {"ok": False, "error": f"{type(exc).__name__}: {exc}"}
    query.reply(query.key_expr, msgpack.packb(result, default=_jsonable))
    if after is not None:
        after()
