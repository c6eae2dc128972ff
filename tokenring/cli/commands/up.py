"""``tokenring up``: launch the whole ring, every node its own process."""

from __future__ import annotations

import argparse
import contextlib
import time
from typing import TYPE_CHECKING

from tokenring.cli.args import int_within, seconds
from tokenring.errors import UsageError

DEFAULT_BITRATE = "2.5M"
EXAMPLES = """examples:
  tokenring up                     boot, download the programs over the ring, start them
  tokenring up --no-start          boot and download; the programs wait for ARCNET_START_SYSTEM
  tokenring load --start           ... which this sends (or the application's own way, said at boot)
  tokenring up --no-download       every node starts its program from its file, no download
  tokenring up --router --links -l tcp/127.0.0.1:7447
                                   the nodes clients of this launcher, the token on direct links
  tokenring up --ring lab2         a second ring beside a running one (a ring runs once per network)
  tokenring up --metrics 9464      Prometheus scrapes the ring at http://127.0.0.1:9464/metrics
  tokenring up --hosts ring.yaml --web
                                   one ring across the hosts of an inventory, started over ssh, a
                                   Zenoh router per host (docs/hosts.md); Ctrl-C stops every host

an inventory (--hosts FILE; the launcher's host is 'ssh: local', its router the hub):
  hosts:
    pc:     {address: 10.0.0.1, ssh: local, nodes: [main, motor]}
    board1: {address: 10.0.0.2, ssh: {user: robot}, nodes: 3, tokenring: /opt/ring/bin/tokenring}

exit codes:
  0  the run was whole; 130 after Ctrl-C
  1  something failed while it ran, each said in one line: a module program that failed (raised
     in setup() or run(), or would not load: a syntax error), a node that died, a service (the
     world simulator, the recorder) that died or did not stop cleanly, a download that failed
  2  bad input, refused before anything started: an option, a file, a ring name that another
     launcher holds on this Zenoh network (named; --connect joins it on purpose, with --nodes
     that are not live there), an inventory's mistake or a host it names that cannot be reached
     or whose share refused to start (FILE:LINE)

supervision: every node and service is its own process group; what a program starts ends with
its node. --respawn starts a dead node again, and a dead service where that is safe (the web
view, Foxglove; not the world simulator or a recording, whose state would be lost).
"""

if TYPE_CHECKING:
    import threading
    from pathlib import Path

    from tokenring.contract.protocol import Protocol
    from tokenring.extensions import UpPlan
    from tokenring.host.hosts import Inventory
    from tokenring.host.launcher import Launcher
    from tokenring.host.services import ServicePlan

HELP = "launch the whole ring (every node its own process)"


def add_parser(sub: argparse._SubParsersAction) -> None:
    from tokenring import extensions  # the extensions' own options (the robot's world, missions)
    from tokenring.cli.args import add_ring_options, with_examples
    from tokenring.cli.commands.watch import add_metrics_options, add_pcap_option

    p = sub.add_parser(
        "up",
        help=HELP,
        description="Launch every node of protocol.yaml as its own OS process on one Zenoh network "
        "and supervise them until Ctrl-C, SIGTERM or --duration.",
        **with_examples(EXAMPLES),
    )
    p.add_argument(
        "--nodes",
        help="comma-separated nodes to start (names or IDs); default protocol.yaml's nodes but the optional ones",
    )
    p.add_argument(
        "--hosts",
        metavar="FILE",
        help="a ring across hosts: the inventory (YAML) says each host's address, how ssh reaches it "
        "and its nodes; each other host runs its share over ssh as its own Zenoh router, connected "
        "to this launcher's (docs/hosts.md)",
    )
    # a host's share of a ring across hosts, started over ssh by `up --hosts` (remote.py): it
    # stops when its standard input closes; TOTAL is the whole ring's size
    p.add_argument("--share", type=int_within(1, 255), metavar="TOTAL", help=argparse.SUPPRESS)
    # ... and stops by itself once it heard nothing from that launcher for S seconds
    p.add_argument("--lost-after", type=seconds, metavar="S", help=argparse.SUPPRESS)
    p.add_argument("--duration", type=seconds, metavar="S", help="stop after S seconds")
    p.add_argument(
        "--bitrate",
        help=f"emulated ARCNET bitrate, e.g. 2.5M, 10M or max (default {DEFAULT_BITRATE})",
    )
    p.add_argument(
        "--ack",
        default="adaptive",
        choices=("adaptive", "always", "never"),
        help="pass acknowledgement policy",
    )
    p.add_argument(
        "--programs",
        metavar="DIR",
        help="directory of user programs, <node>.py each (default: the installed application's)",
    )
    p.add_argument("--no-programs", action="store_true", help="start the nodes with the OS only")
    p.add_argument(
        "--no-download",
        action="store_true",
        help="give each node its program file at start instead of booting bare and loading over the ring",
    )
    p.add_argument(
        "--no-start",
        action="store_true",
        help="boot and download the programs but send no ARCNET_START_SYSTEM: the programs wait "
        "until 'tokenring load --start' (or the application's own start) sends it",
    )
    p.add_argument(
        "--store",
        metavar="DIR",
        help="root of the nodes' program stores (default $TOKENRING_STORE or ~/.local/state/tokenring)",
    )
    p.add_argument("--respawn", action="store_true", help="restart nodes that die, like a supervisor")
    p.add_argument(
        "--profile",
        choices=("arcnet",),
        help="emulate the seed robot's hardware timing on top of the wire: the 8051s' per-visit work and "
        "channel copies, the sonar's interrupt lock (tokenring/node/pacing.py; needs a bitrate, not max)",
    )
    p.add_argument(
        "--router",
        action="store_true",
        help="this launcher is its host's Zenoh router (needs --listen); its nodes are clients of it. "
        "For rings across hosts: only router-to-router links cross between hosts",
    )
    p.add_argument(
        "--links",
        action="store_true",
        help="with --router: each node also passes the token on a direct link to its successor "
        "(a second Zenoh session per node; the router carries everything else)",
    )
    p.add_argument(
        "--boot-wave",
        type=int_within(1, 255),
        metavar="N",
        help="at most N nodes (1..255) booting at a time; a bigger ring starts in waves, a new node as "
        "each booting one comes live (default: 8 per core)",
    )
    web = p.add_argument_group("web view")
    web.add_argument("--web", action="store_true", help="serve the live web view too (as 'tokenring web')")
    web.add_argument(
        "--web-port",
        type=int_within(1, 65535),
        default=8080,
        metavar="N",
        help="its port (default %(default)s)",
    )
    fox = p.add_argument_group("Foxglove")
    fox.add_argument(
        "--foxglove",
        action="store_true",
        help="serve the ring to Foxglove too (as 'tokenring foxglove')",
    )
    fox.add_argument(
        "--foxglove-port",
        type=int_within(1, 65535),
        default=8765,
        metavar="N",
        help="its WebSocket port (default %(default)s)",
    )
    rec = p.add_argument_group("recording")
    rec.add_argument(
        "--record",
        metavar="FILE.mcap",
        help="record the whole run to a new MCAP file (as 'tokenring record'; one watcher process serves"
        " --web, --record and --foxglove together)",
    )
    add_pcap_option(rec)
    add_metrics_options(p)
    p.add_argument(
        "--force",
        action="store_true",
        help="replace existing output files (--record, --pcap, and an application's, e.g. the robot's --map-out)",
    )
    for extension in extensions.loaded():
        extension.add_up_options(p)
    add_ring_options(p)


def node_selection(args: argparse.Namespace, protocol: Protocol) -> list[str] | None:
    """The nodes ``up`` starts as names or IDs: ``--nodes``; without it None (protocol.yaml's
    nodes but the optional ones) unless the extensions' options add optional nodes to those."""
    from tokenring import extensions

    # asked with or without --nodes: an extension checks a given --nodes against its options
    added = [name for extension in extensions.loaded() for name in extension.up_nodes(args, protocol)]
    if args.nodes is not None:
        selection = [s.strip() for s in args.nodes.split(",") if s.strip()]
        if not selection:  # ',,,' or '' once meant every node, silently
            raise UsageError(
                f"--nodes {args.nodes!r} names no node: give names or IDs (e.g. main,sonar), or leave "
                "--nodes out for the default ring"
            )
        return selection
    return [n.name for n in protocol.default_nodes] + added if added else None


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from tokenring import extensions
    from tokenring.contract.protocol import load_protocol
    from tokenring.contract.ring import format_bitrate, parse_bitrate
    from tokenring.host.launcher import (
        BOOT_CONCURRENCY,
        Launcher,
        install_signal_handlers,
        plans_from_protocol,
    )

    protocol = load_protocol(args.protocol)
    bitrate_given = args.bitrate is not None
    args.bitrate = args.bitrate or DEFAULT_BITRATE
    bitrate = parse_bitrate(args.bitrate)  # refuse a bad value before anything starts
    if args.duration is not None and args.duration <= 0:
        raise UsageError("--duration must be positive")
    if args.profile and bitrate is None:
        raise UsageError(
            f"--profile {args.profile} emulates hardware timing: give a bitrate such as 2.5M, not max"
        )
    if args.store:
        from tokenring.node.store import check_store_root

        check_store_root(Path(args.store))  # before any node starts (a node would fail mid-download)
    inventory = load_hosts(args, protocol) if args.hosts else None
    if inventory is not None:
        selection: list[str] | None = inventory.local.nodes
        everyone = plans_from_protocol(protocol, [n for h in inventory.hosts for n in h.nodes], None)
    else:
        selection = node_selection(args, protocol)
    programs = None if args.no_programs else (args.programs or extensions.programs_dir())
    if programs is not None and not Path(programs).is_dir():
        raise UsageError(f"--programs {programs}: no such directory")
    main_id = protocol.nodes["main"].id if "main" in protocol.nodes else None
    download = programs is not None and not args.no_download
    if args.share and not args.no_download:
        programs = None  # a host's share boots bare: the launcher of the whole ring downloads
    plans = (
        [] if selection == [] else plans_from_protocol(protocol, selection, None if download else programs)
    )
    ring_ids = {p.node_id for p in (everyone if inventory is not None else plans)}
    if download and main_id not in ring_ids:
        download = False  # no main, no PC link: the programs start from their files
        plans = [] if selection == [] else plans_from_protocol(protocol, selection, programs)
    if programs is not None:  # a <node>.py that cannot be one (a link loop) is named, not skipped
        from tokenring.host.loader import check_program_dir

        check_program_dir(Path(programs), [p.name for p in (everyone if inventory is not None else plans)])
    if args.no_start and not download:
        why = "main, the PC link, is not among --nodes"
        if programs is None or args.no_download:
            why = "--no-programs" if programs is None else "--no-download"
        raise UsageError(
            f"--no-start holds the programs downloaded over the ring, and there is no download ({why})"
        )
    # every extension checks its options before anything starts (a host's share runs none: its
    # services run beside the launcher of the whole ring, which passes the nodes' environment)
    plans_up = [] if args.share else [extension.plan_up(args, protocol) for extension in extensions.loaded()]
    speedup = 1.0
    node_env: dict[str, str] = {}
    for plan in plans_up:
        speedup *= plan.speedup
        node_env.update(plan.env)
        if plan.profile and not (args.profile or bitrate_given):
            args.profile = plan.profile  # e.g. the seed's algorithms at the seed's pace
    # everything emulated runs K times faster with a speed-up K, the wire included: a round
    # of the ring must stay as short in emulated time as it is on the real hardware
    wire = args.bitrate if bitrate is None or speedup == 1.0 else format_bitrate(bitrate * speedup)
    if wire != args.bitrate:
        try:
            parse_bitrate(wire)  # every node would refuse it, after the boot
        except UsageError:
            raise UsageError(
                f"--bitrate {args.bitrate} with a speed-up of {speedup:g} (--speed) is a wire of {wire} bit/s; "
                "the emulated wire must be within 10k..100G bit/s (give another --bitrate or --speed)"
            ) from None
    services = [service for plan in plans_up for service in plan.services]
    if args.web or args.record or args.foxglove or args.metrics is not None or args.pcap:
        services.append(watch_service(args))
    if inventory is not None:
        args.router = True
        args.listen = hub_endpoints(inventory)
    launcher = Launcher(
        plans,
        ring=args.ring,
        bitrate=wire,
        ack_mode=args.ack,
        connect=args.connect or [],
        listen=args.listen or [],
        zenoh_config=args.zenoh_config,
        protocol_path=args.protocol,
        log_level=args.log_level,
        respawn=args.respawn,
        router=args.router,
        links=args.links,
        profile=args.profile,
        services=services,
        extra_node_args=["--store", args.store] if args.store else [],
        boot_concurrency=BOOT_CONCURRENCY if args.boot_wave is None else args.boot_wave,
        env=node_env,
    )
    if inventory is not None:
        across_hosts(launcher, args, inventory, wire, node_env, download)
    lost = share_of_a_ring(launcher, args.share, args.lost_after) if args.share else None
    install_signal_handlers(launcher)
    # the status says so from its first answer: nodes that are live before the download starts
    # are not yet running their programs
    launcher.booting = download and programs is not None
    launcher.start()
    if launcher.hosts is not None:
        wait_for_hosts(launcher, ring_ids)
    boot_ok = True
    if download and programs is not None:
        boot_ok = boot_load(launcher, Path(programs), ring_ids, start=not args.no_start)
    if args.no_start:
        say_waiting(launcher, plans_up)
    for plan in plans_up:
        if plan.on_started is not None and not args.no_start:
            plan.on_started(launcher)
    limit = args.duration
    grace = max((plan.grace_s for plan in plans_up), default=0.0)
    if limit is not None:
        limit += grace
    code = launcher.run(limit)
    failures = [plan.failure() for plan in plans_up if plan.failure is not None]
    if any(failures) and code == 0:
        code = 1
    if not boot_ok and code == 0:
        code = 1
    why = ""  # a host's share says why its run was not whole: the launcher of the ring names it
    if lost is not None and lost.is_set():
        from tokenring.host.remote import SHARE_LOST

        code, why = SHARE_LOST, f"heard nothing from the launcher for {args.lost_after:g} s"
    elif args.share and code == 1:
        why = "; ".join(launcher.reasons())
    launcher.say(
        "stopped (interrupted)"
        if code == 130
        else f"stopped (exit code {code})" + (f": {why}" if why else "")
    )
    launcher.flush_output()
    return code


def load_hosts(args: argparse.Namespace, protocol: Protocol) -> Inventory:
    """``--hosts FILE``: the inventory, checked; it places the nodes and the routers itself."""
    from tokenring.host.hosts import load_inventory

    if args.share:
        raise UsageError("--hosts starts the shares itself; --share is theirs")
    for option, given in (
        ("--nodes", args.nodes is not None),
        ("--router", args.router),
        ("--listen", bool(args.listen)),
        ("--connect", bool(args.connect)),
        ("--links", args.links),
    ):
        if given:
            raise UsageError(
                f"--hosts places the nodes and the routers from {args.hosts}; leave out {option}"
            )
    return load_inventory(args.hosts, protocol)


def hub_endpoints(inventory: Inventory) -> list[str]:
    """Where the launcher's router, the hub, listens: its host's address, where the other hosts'
    routers connect, and on plain TCP loopback on the same port, where this host's tools find the
    ring without ``-e`` (a secured ring's certificate names the hosts' addresses, not loopback)."""
    local = inventory.local
    endpoints = [local.endpoint(inventory.scheme)]
    if inventory.scheme == "tcp" and local.address not in ("127.0.0.1", "localhost", "0.0.0.0", "::", "::1"):
        endpoints.append(f"tcp/127.0.0.1:{local.zenoh_port}")
    return endpoints


def across_hosts(
    launcher: Launcher,
    args: argparse.Namespace,
    inventory: Inventory,
    wire: str,
    node_env: dict[str, str],
    download: bool,
) -> None:
    """Make ``launcher`` the hub of a ring across the inventory's hosts: each other host's share
    is started over ssh (each checked reachable first) and supervised like its nodes."""
    import os

    from tokenring.host.remote import HostShares, ShareSettings, check_reachable

    env = dict(node_env)
    for name in ("TOKENRING_EXTENSIONS", "TOKENRING_PROTOCOL"):
        if name in os.environ and name not in env:
            env[name] = os.environ[name]
    settings = ShareSettings(
        ring=launcher.ring,
        bitrate=wire,
        ack=args.ack,
        log_level=args.log_level,
        total=inventory.node_count,
        hub=launcher.listen[0],
        scheme=inventory.scheme,
        respawn=args.respawn,
        profile=args.profile,
        protocol=args.protocol,
        zenoh_config=args.zenoh_config,
        no_programs=args.no_programs,
        no_download=not download,  # (no main in the ring: the programs start from their files)
        programs=args.programs,
        env=env,
    )
    launcher.hosts = HostShares(launcher, inventory, settings)
    launcher.label_prefix = f"{inventory.local.name}/"
    launcher.expected_nodes = inventory.node_count
    labels = [*launcher.hosts.labels(), *(f"{inventory.local.name}/{p.name}" for p in launcher.plans)]
    launcher.output.width = max([launcher.output.width, *map(len, labels)])
    check_reachable(inventory)


def wait_for_hosts(launcher: Launcher, ids: set[int], timeout: float = 120.0) -> None:
    """Wait until every host's nodes are live; a host whose share ended first stops the run
    (exit 2, the inventory's line named)."""
    assert launcher.hosts is not None
    started = time.monotonic()
    try:
        whole = launcher.hosts.wait_up(ids, timeout)
    except UsageError:
        launcher.stop()
        raise
    if whole:
        launcher.say(f"every host's nodes are live ({len(ids)} nodes, {time.monotonic() - started:.1f} s)")
    elif not launcher.stopping:
        launcher.say(f"not every node is live after {timeout:.0f} s: going on with those that are")


def share_of_a_ring(launcher: Launcher, total: int, lost_after: float | None) -> threading.Event:
    """``--share TOTAL``: this launcher runs one host's share of a ring of TOTAL nodes for ``up
    --hosts`` (over ssh). It stops when its standard input closes (the launcher stops the ring, or
    the ssh session dropped) or, with ``lost_after``, once nothing came on it for that long (the
    launcher writes a line every second; a cut network closes nothing until sshd notices);
    the event returned is set then. It does not announce the ring's stop (the other hosts go on)."""
    import os
    import select
    import sys
    import threading

    launcher.expected_nodes = total
    launcher.announce_stop = False
    lost = threading.Event()

    def lifeline() -> None:
        with contextlib.suppress(OSError, ValueError):
            fd = sys.stdin.fileno()
            while True:
                if not select.select([fd], [], [], lost_after)[0]:
                    lost.set()
                    break
                if not os.read(fd, 4096):
                    break
        if lost.is_set():
            launcher.say(f"heard nothing from the launcher for {lost_after:g} s: stopping this host's share")
        elif not launcher.stopping:
            launcher.say("the launcher's connection closed: stopping this host's share")
        launcher.request_stop()

    threading.Thread(target=lifeline, name="share-lifeline", daemon=True).start()
    return lost


def boot_load(
    launcher: Launcher, programs: Path, ids: set[int], wait: float = 30.0, start: bool = True
) -> bool:
    """The seed's boot: the nodes run their OS only; scan them, load every program that is newer
    than the node's (``load -i``: a restarted ring finds them in its stores and sends nothing)
    through main's PC link, then ARCNET_START_SYSTEM (unless not ``start``). False if a node
    failed (named in the output)."""
    from tokenring.errors import TokenRingError
    from tokenring.host.loader import Loader, run_load
    from tokenring.host.pclink import open_link

    launcher.booting = True
    try:
        assert launcher.session is not None
        link = open_link(launcher.session, launcher.ring, wait=wait)
        loader = Loader(
            link,
            progress=False,
            say=lambda text: launcher.say(text, name="load"),
            cancelled=lambda: launcher.stopping,
        )
        result = run_load(
            loader, mode="incremental", programs_dir=programs, start=start, expect=ids, wait=wait
        )
        return not result["failed"]
    except TokenRingError as exc:
        launcher.say(f"loading the programs failed: {exc}", name="load")
        return False
    finally:
        launcher.booting = False


def say_waiting(launcher: Launcher, plans_up: list[UpPlan]) -> None:
    """``--no-start``: the programs are loaded and wait; say how to start them."""
    command = " ".join(["tokenring", "load", *launcher.tool_options(), "--start"])
    launcher.say(f"--no-start: the programs wait for ARCNET_START_SYSTEM; start them with: {command}")
    for plan in plans_up:
        hint = plan.start_hint(launcher) if plan.start_hint is not None else None
        if hint:
            launcher.say(hint)


def check_port(option: str, port: int, host: str = "127.0.0.1") -> None:
    """Refuse ``option``'s port on ``host`` if it cannot be had, before anything starts."""
    import socket

    try:
        family, _, _, _, address = socket.getaddrinfo(
            host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE
        )[0]
        with socket.socket(family, socket.SOCK_STREAM) as probe:
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the servers will
            probe.bind(address)
    except OSError as exc:
        raise UsageError(f"{option} {port}: cannot listen on {host}:{port} ({exc.strerror or exc})") from None


def watch_service(args: argparse.Namespace) -> ServicePlan:
    """``--web``, ``--record``, ``--foxglove`` and ``--metrics`` as one launcher service,
    ``tokenring watch``: one process, one Zenoh session and one feed for all of them (three tools would each decode
    every frame again, on the cores the nodes need). Ports and the file are checked here, before
    anything starts; the launcher waits until it serves and records, so the file holds the boot,
    and stops it (SIGTERM: the recording is finalised) after the nodes."""
    import os

    from tokenring.cli.output import check_option_output
    from tokenring.contract import keys
    from tokenring.host.services import ServicePlan

    argv = ["tokenring", "watch", "--ring", "{ring}", "--connect", "{connect}"]
    if args.web:
        check_port("--web-port", args.web_port)
        argv += ["--web", "--web-port", str(args.web_port)]
    if args.foxglove:
        check_port("--foxglove-port", args.foxglove_port)
        argv += ["--foxglove", "--foxglove-port", str(args.foxglove_port)]
    if args.metrics is not None:
        check_port("--metrics", args.metrics, args.metrics_host)
        argv += ["--metrics", str(args.metrics), "--metrics-host", args.metrics_host]
    if args.record:
        check_option_output("--record", args.record, force=args.force)
        argv += ["--record", args.record]
    if args.pcap:
        from tokenring.cli.pcapcapture import check_pcap_output

        check_pcap_output("--pcap", args.pcap, args.force, other=args.record)
        argv += ["--pcap", args.pcap]
    if args.force and (args.record or args.pcap):
        argv += ["--force"]
    tag = f"up{os.getpid()}"
    argv += ["--ready-token", tag]
    if args.zenoh_config:
        argv += ["--zenoh-config", args.zenoh_config]
    if args.protocol:
        argv += ["--protocol", args.protocol]
    # a recording or capture is not started again after a death: it would need a new file
    written = args.record or args.pcap
    return ServicePlan("watch", argv, ready_key=keys.watch_ready(args.ring, tag), restart=not written)
