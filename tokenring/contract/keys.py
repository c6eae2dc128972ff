"""Every Zenoh key tokenring uses, in one place. ``<ring>`` is the ring's name (default ``default``).

=======================================  ========================================================
key                                      what travels on it
=======================================  ========================================================
``tokenring/<ring>/token/<DID>``         frames only: 512-byte token + CRC-16/ARC (514 bytes)
``tokenring/<ring>/node/<ID>``           liveliness token held by every live node
``tokenring/<ring>/ack/<ID>``            pass acknowledgements and stale-token notices to ``ID``
``tokenring/<ring>/ring/event``          ring events: a node excluded, a node rejoining
``tokenring/<ring>/view/<ID>``           queryable of a node in a peer ring: the IDs it passes among
``tokenring/<ring>/view/launcher``       the same from the launcher: the IDs whose liveliness it sees
``tokenring/<ring>/ctl/<ID>/<verb>``     queryables of node ``ID``: ``stats``, ``fault``, ...
``tokenring/<ring>/ctl/launcher/<verb>`` queryables of the launcher (``status``)
``tokenring/<ring>/pc/<verb>``           the PC link ("serial line") to main
``tokenring/<ring>/tap/<id>``            liveliness token of a tap (``tokenring sniff``)
``tokenring/<ring>/tap/<id>/drained``    its queryable: every sample put before has reached it
``tokenring/<ring>/tap/<id>/left``       its goodbye: it stopped on purpose, nothing was cut
``tokenring/<ring>/...``                 an application's own keys (the robot's: modules.description.keys)
=======================================  ========================================================
"""

from __future__ import annotations

PREFIX = "tokenring"
DEFAULT_RING = "default"
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"


def default_endpoint() -> str:
    """The ring's tap endpoint: ``$TOKENRING_ENDPOINT`` if set, else ``tcp/127.0.0.1:7447``."""
    import os

    return os.environ.get("TOKENRING_ENDPOINT") or DEFAULT_ENDPOINT


def check_name(name: str, what: str = "ring name") -> str:
    """A name that becomes one key chunk and one folder (of the program store): letters,
    digits, ``_ - .``, starting with a letter or digit, at most 64 (so never ``..`` or ``/``)."""
    import re

    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}", name):
        from tokenring.errors import UsageError

        raise UsageError(
            f"{what} {name!r}: letters, digits, _ - . only, starting with a letter or digit, at most 64"
        )
    return name


def check_ring_name(ring: str) -> str:
    """A ring's name: it is a key chunk and a folder of the program store (:func:`check_name`)."""
    return check_name(ring, "ring name")


def check_node_name(name: str) -> str:
    """A node's name: a folder of its ring's program store, like a ring name (:func:`check_name`)."""
    return check_name(name, "node name")


def token(ring: str, did: int | str) -> str:
    return f"{PREFIX}/{ring}/token/{did}"


def node(ring: str, node_id: int | str) -> str:
    return f"{PREFIX}/{ring}/node/{node_id}"


def ack(ring: str, node_id: int | str) -> str:
    return f"{PREFIX}/{ring}/ack/{node_id}"


def ring_event(ring: str) -> str:
    return f"{PREFIX}/{ring}/ring/event"


def ring_view(ring: str, who: int | str = "*") -> str:
    """Where a peer ring's nodes (and its launcher) tell a joiner which IDs they see live: on a
    peer-to-peer Zenoh network a liveliness query reaches only the peers already linked."""
    return f"{PREFIX}/{ring}/view/{who}"


#: what a ``stats`` question may ask a node to add to its answer (``{"with": [...]}``): its
#: active faults (the ``fault`` verb's list) and its system layer's report (``system``)
STATS_EXTRAS = ("faults", "system")


def control(ring: str, node_id: int | str, verb: str = "**") -> str:
    return f"{PREFIX}/{ring}/ctl/{node_id}/{verb}"


def pc_link(ring: str, verb: str) -> str:
    return f"{PREFIX}/{ring}/pc/{verb}"


def watch_ready(ring: str, tag: str) -> str:
    """The liveliness token a watcher (``tokenring watch``) declares once it serves and records."""
    return f"{PREFIX}/{ring}/watch/{tag}"


def tap(ring: str, tap_id: str = "*") -> str:
    """The liveliness token a tap (``tokenring sniff``) holds while it listens: ``play`` tells
    a tap cut off mid-play (its token gone without a goodbye) from one that stopped."""
    return f"{PREFIX}/{ring}/tap/{tap_id}"


def tap_left(ring: str, tap_id: str = "*") -> str:
    """A tap's goodbye, put just before it stops on purpose."""
    return f"{PREFIX}/{ring}/tap/{tap_id}/left"


def tap_drained(ring: str, tap: str = "*") -> str:
    """A tap's (``tokenring sniff``'s) queryable: its reply says every sample put before the
    query on the same link has reached it (``tokenring play`` asks before it closes)."""
    return f"{PREFIX}/{ring}/tap/{tap}/drained"


def id_from_key(key: str) -> int | None:
    """The trailing numeric chunk of a key (``.../node/20`` -> 20), or None."""
    tail = key.rsplit("/", 1)[-1]
    return int(tail) if tail.isdigit() else None


def tap_id_from_key(key: str) -> str | None:
    """The tap's ID in any of its keys (``.../tap/<id>``, ``.../tap/<id>/drained``, ``/left``)."""
    chunks = key.split("/")
    return chunks[3] if len(chunks) >= 4 and chunks[0] == PREFIX and chunks[2] == "tap" else None


def check_ring_name_type(ring: str) -> str:
    """:func:`check_ring_name` as an argparse type (refused while the options are parsed)."""
    import argparse

    from tokenring.errors import UsageError

    try:
        return check_ring_name(ring)
    except UsageError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def check_node_name_type(name: str) -> str:
    """:func:`check_node_name` as an argparse type."""
    import argparse

    from tokenring.errors import UsageError

    try:
        return check_node_name(name)
    except UsageError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
