"""A peer that joins sees the whole ring before it is in it.

On a peer-to-peer Zenoh network a liveliness query is answered by the peers already linked to
the asker, each with its own token: a joiner whose gossip links are still coming up would see part
of the ring, pick the wrong successor and lose the token. The transport asks the ring's nodes
(or its launcher) which IDs they pass among and waits for their liveliness.

The ring's side here is written by the test itself, on raw Zenoh sessions and the documented keys
(``tokenring/<ring>/node/<ID>``, ``tokenring/<ring>/view/<ID>``), not with tokenring's code. Gossip
is off so that the test alone decides who links to whom.
"""

from __future__ import annotations

import json
import logging
import threading
from collections.abc import Iterator

import pytest
import zenoh

from tests.support.ringutil import wait_until
from tokenring.transport.session import free_port
from tokenring.transport.zenoh import RingViewServer, ZenohTransport
from tokenring.transport.zenoh_config import make_config, open_session


def peer(listen: int | None = None, connect: int | None = None) -> zenoh.Session:
    """A peer on loopback that links only where it is told (no gossip, no multicast)."""
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("scouting/gossip/enabled", "false")
    config.insert_json5("listen/endpoints", json.dumps([f"tcp/127.0.0.1:{listen}"] if listen else []))
    if connect:
        config.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{connect}"]))
    return zenoh.open(config)


@pytest.fixture
def sessions() -> Iterator[list[zenoh.Session]]:
    opened: list[zenoh.Session] = []
    yield opened
    for session in reversed(opened):
        session.close()


def ring_node(
    sessions, ring: str, node_id: int, view: list[int], asked: threading.Event, **links: int
) -> tuple[zenoh.Session, zenoh.LivelinessToken, zenoh.Queryable]:
    """A node of the ring as the wire contract has it: its liveliness token and its view (both
    undeclared when the caller drops what this returns)."""
    session = peer(**links)
    sessions.append(session)
    token = session.liveliness().declare_token(f"tokenring/{ring}/node/{node_id}")
    key = f"tokenring/{ring}/view/{node_id}"

    def answer(query: zenoh.Query) -> None:
        asked.set()
        query.reply(key, bytes(view))

    queryable = session.declare_queryable(key, answer)
    return session, token, queryable


def joiner(sessions, ring: str, node_id: int, connect: int, listen: int) -> ZenohTransport:
    session = open_session(
        make_config(connect=[f"tcp/127.0.0.1:{connect}"], listen=[f"tcp/127.0.0.1:{listen}"], gossip=False)
    )
    sessions.append(session)
    return ZenohTransport(session, ring, node_id)


def open_in_background(transport: ZenohTransport) -> tuple[threading.Thread, dict[str, set[int]]]:
    result: dict[str, set[int]] = {}

    def run() -> None:
        result["members"] = transport.open(lambda frame: None, lambda payload: None, lambda i, live: None)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread, result


def test_a_joiner_linked_to_part_of_the_ring_waits_for_the_rest(sessions, ring_name):
    port_10 = free_port()
    port_40 = free_port(avoid=[port_10])
    asked = threading.Event()
    node_10 = ring_node(sessions, ring_name, 10, [10, 30], asked, listen=port_10)
    transport = joiner(sessions, ring_name, 40, connect=port_10, listen=port_40)
    transport.join_wait_s = 120.0  # only the link to 30 may end the wait, never the clock
    thread, result = open_in_background(transport)
    assert asked.wait(60), "the joiner never asked node 10 for its view"
    # node 10 lists 30, whose liveliness the joiner cannot see: it is not linked to 30 yet
    assert "members" not in result
    node_30 = ring_node(sessions, ring_name, 30, [10, 30], threading.Event(), connect=port_40)
    thread.join(60)
    assert not thread.is_alive(), "the joiner went on waiting after 30's liveliness arrived"
    assert result["members"] == {10, 30}
    transport.close()
    del node_10, node_30  # their tokens and queryables lived until here


def test_a_joiner_that_never_sees_a_listed_node_joins_after_its_wait_and_says_so(sessions, ring_name, caplog):
    port_10 = free_port()
    port_40 = free_port(avoid=[port_10])
    asked = threading.Event()
    node_10 = ring_node(sessions, ring_name, 10, [10, 20, 30], asked, listen=port_10)
    transport = joiner(sessions, ring_name, 40, connect=port_10, listen=port_40)
    transport.join_wait_s = 0.5
    with caplog.at_level(logging.WARNING, logger="tokenring.transport"):
        members = transport.open(lambda frame: None, lambda payload: None, lambda i, live: None)
    assert asked.is_set()
    assert members == {10}
    assert "[20, 30]" in caplog.text and "node 40" in caplog.text
    transport.close()
    del node_10


def view_answers(asker: zenoh.Session, ring: str) -> dict[str, set[int]]:
    """Who answers ``view/*`` for this session, and with which IDs."""
    found = {}
    for reply in asker.get(f"tokenring/{ring}/view/*", timeout=5.0):
        if reply.ok is not None:
            found[str(reply.ok.key_expr).rsplit("/", 1)[-1]] = set(reply.ok.payload.to_bytes())
    return found


def test_the_launchers_view_follows_the_liveliness_it_sees(sessions, ring_name):
    port_launcher = free_port()
    launcher = peer(listen=port_launcher)
    sessions.append(launcher)
    server = RingViewServer(launcher, ring_name)
    node_sessions = [peer(connect=port_launcher) for _ in (10, 30)]
    sessions.extend(node_sessions)
    tokens = [
        s.liveliness().declare_token(f"tokenring/{ring_name}/node/{i}")
        for s, i in zip(node_sessions, (10, 30), strict=True)
    ]
    asker = peer(connect=port_launcher)
    sessions.append(asker)
    wait_until(
        lambda: view_answers(asker, ring_name) == {"launcher": {10, 30}}, 30, "the launcher to list 10 and 30"
    )
    tokens[1].undeclare()
    wait_until(lambda: view_answers(asker, ring_name) == {"launcher": {10}}, 30, "the launcher to drop 30")
    server.close()
    tokens[0].undeclare()


def test_a_nodes_view_outweighs_the_launchers(sessions, ring_name):
    """30 is live (the launcher sees it) but out of the ring (node 10 does not list it, as for a
    hung node): the joiner must not wait for 30, which it can never see."""
    port_launcher = free_port()
    port_10 = free_port(avoid=[port_launcher])
    port_40 = free_port(avoid=[port_launcher, port_10])
    transport = joiner(sessions, ring_name, 40, connect=port_10, listen=port_40)
    launcher = peer(listen=port_launcher, connect=port_40)
    sessions.append(launcher)
    server = RingViewServer(launcher, ring_name)
    asked = threading.Event()
    node_10 = ring_node(sessions, ring_name, 10, [10], asked, listen=port_10, connect=port_launcher)
    node_30 = peer(connect=port_launcher)
    sessions.append(node_30)
    token_30 = node_30.liveliness().declare_token(f"tokenring/{ring_name}/node/30")
    asker = peer(connect=port_launcher)
    sessions.append(asker)
    wait_until(
        lambda: view_answers(asker, ring_name).get("launcher") == {10, 30},
        30,
        "the launcher to list 10 and 30",
    )
    transport.join_wait_s = 120.0  # the clock must not end the wait: node 10's answer must
    thread, result = open_in_background(transport)
    thread.join(60)
    assert not thread.is_alive(), "the joiner waited for 30, which only the launcher lists"
    assert asked.is_set() and result["members"] == {10}
    transport.close()
    server.close()
    token_30.undeclare()
    del node_10
