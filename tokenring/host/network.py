"""Where a launcher sits on the Zenoh network: its hosts' router, the listener on an endpoint of
its own or the default one, or a peer joining a network that already runs."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import zenoh

from tokenring.contract import keys
from tokenring.errors import TransportError, UsageError
from tokenring.transport.zenoh_config import make_config, open_session


@dataclass
class LauncherSession:
    """The launcher's session and what it tells its nodes."""

    session: zenoh.Session
    #: where this launcher listens (the ring's tap endpoint), None when it only joined
    endpoint: str | None
    #: it joined a Zenoh network another process listens on (``--connect``, or the default
    #: port taken)
    joined_existing: bool = False
    note: str | None = None  # a line for the user: how it came to join


def open_launcher_session(
    *,
    router: bool,
    listen: Sequence[str],
    connect: Sequence[str],
    zenoh_config: str | None,
    ring: str,
) -> LauncherSession:
    """Open the launcher's session: the router of ``--router``, a listener on ``--listen``, a
    peer of ``--connect``, or else a listener on the default endpoint — and if another ring
    holds that port, a peer joining its network (rings are namespaces)."""
    if router:
        if not listen:
            raise UsageError(
                "--router needs --listen ENDPOINT (where this host's nodes and other routers reach it)"
            )
        config = make_config(mode="router", listen=listen, connect=connect, config_file=zenoh_config)
        return LauncherSession(open_session(config), listen[0])
    if listen:
        config = make_config(listen=listen, connect=connect, config_file=zenoh_config)
        return LauncherSession(open_session(config), listen[0])
    if connect:
        config = make_config(connect=connect, config_file=zenoh_config)
        return LauncherSession(open_session(config), None, joined_existing=True)
    try:
        config = make_config(listen=[keys.default_endpoint()], config_file=zenoh_config)
        return LauncherSession(open_session(config), keys.default_endpoint())
    except TransportError as exc:
        if "in use" not in str(exc):
            raise
    config = make_config(connect=[keys.default_endpoint()], config_file=zenoh_config)
    return LauncherSession(
        open_session(config),
        None,
        joined_existing=True,
        note=f"{keys.default_endpoint()} is taken: joining that Zenoh network (ring {ring!r})",
    )
