"""The bare Zenoh ring baseline: N processes forwarding a 514-byte payload, no OS work at all.

Same Zenoh settings as the real ring (peers on loopback, multicast off, express publishers,
congestion control DROP, real-time priority); process 0 times the rounds and prints them as
one JSON line on stdout. ``--mode client``: every process is a client of a router at ``--port``
(the router topology of ``Launcher(router=True)``); ``--mode chain``: each process a peer
listening on its own port of ``--ports`` and linked to its successor's only (gossip off), so each
pass is one link and no process routes for the others (what a ring of direct successor links
would cost; tokenring's nodes do not run that way); ``--mode links``: the chain, plus a second
session in every process, a client of a router at ``--port``, that carries liveliness and the
stop and subscribes the hop key too (a Zenoh router routes for its clients, not between peers:
a node on direct links would need such a session for everything else and for a pass past a dead
successor); otherwise process 0 listens there and the others connect to it, forming a full
mesh of peers.
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import json
import sys
import threading
import time

import zenoh

from tokenring.transport.zenoh_config import hop_callback, make_config, open_session

#: a chained process waits this long after passing the stop on before it closes its session: a
#: session closed at once can drop the frame still queued (a 255-node chain then stopped part way
#: and its other processes waited out their timeout)
CHAIN_LINGER_S = 0.5


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--index", type=int, required=True)
    p.add_argument("--count", type=int, required=True)
    p.add_argument("--port", type=int, required=True)
    p.add_argument("--rounds", type=int, default=2000)
    p.add_argument("--warmup", type=int, default=200)
    p.add_argument("--ring", default="bare")
    p.add_argument("--timeout", type=float, default=120.0)
    p.add_argument("--mode", default="peer", choices=("peer", "client", "chain", "links"))
    p.add_argument("--ports", help="--mode chain: every process's port, comma-separated, in ring order")
    p.add_argument(
        "--stamps", action="store_true", help="also print each round's arrival time (CLOCK_MONOTONIC, s)"
    )
    args = p.parse_args(argv)
    i, n = args.index, args.count
    endpoint = f"tcp/127.0.0.1:{args.port}"
    chained = args.mode in ("chain", "links")
    if chained:
        ports = [int(port) for port in (args.ports or "").split(",") if port]
        if len(ports) != n:
            p.error(f"--mode {args.mode} needs {n} --ports, got {len(ports)}")
        config = make_config(  # no links beyond the successor's
            listen=[f"tcp/127.0.0.1:{ports[i]}"],
            connect=[f"tcp/127.0.0.1:{ports[(i + 1) % n]}"],
            gossip=False,
        )
    elif args.mode == "client":
        config = make_config(mode="client", connect=[endpoint])
    elif i == 0:
        config = make_config(listen=[endpoint])
    else:
        config = make_config(connect=[endpoint])
    prefix = f"tokenring-bare/{args.ring}"
    done = threading.Event()
    warm = threading.Event()  # process 0: the warm-up rounds have gone round
    stamps: list[float] = []
    total = args.rounds + args.warmup + 1
    with contextlib.ExitStack() as stack:
        session = stack.enter_context(open_session(config))
        control = (
            stack.enter_context(open_session(make_config(mode="client", connect=[endpoint])))
            if args.mode == "links"
            else session
        )
        publisher = session.declare_publisher(
            f"{prefix}/hop/{(i + 1) % n}",
            express=True,
            congestion_control=zenoh.CongestionControl.DROP,
            priority=zenoh.Priority.REAL_TIME,
        )
        put = publisher.put

        put_times: list[float] = []
        perf = time.perf_counter

        if i == 0:

            def handle(sample: zenoh.Sample) -> None:
                stamps.append(perf())
                if len(stamps) == args.warmup + 1:
                    warm.set()
                if len(stamps) >= total:
                    done.set()
                    return
                payload = sample.payload.to_bytes()
                if len(stamps) & 15:
                    put(payload)
                else:  # every 16th put is timed, as the node OS times its sends
                    t0 = perf()
                    put(payload)
                    put_times.append(perf() - t0)

            if chained:
                plain = handle
                kept: list[int] = []

                def handle(sample: zenoh.Sample) -> None:
                    # a start frame resent before the first came back circulates too: keep the
                    # first to come back (its number), drop the others
                    number = int.from_bytes(sample.payload.to_bytes()[:4], "little")
                    if not kept:
                        kept.append(number)
                    if number == kept[0]:
                        plain(sample)

        elif chained:

            def handle(sample: zenoh.Sample) -> None:
                payload = sample.payload.to_bytes()
                put(payload)
                if len(payload) == 1:  # the stop: nothing else reaches past the successor
                    done.set()

        else:

            def handle(sample: zenoh.Sample) -> None:
                put(sample.payload.to_bytes())

        subscriber = session.declare_subscriber(f"{prefix}/hop/{i}", hop_callback(handle))
        fallback = (
            control.declare_subscriber(f"{prefix}/hop/{i}", hop_callback(handle))
            if control is not session
            else None
        )
        stop = control.declare_subscriber(f"{prefix}/stop", lambda _s: done.set())
        token = control.liveliness().declare_token(f"{prefix}/live/{i}")

        def stop_all() -> None:
            control.put(f"{prefix}/stop", b"")
            if chained:
                put(b"\xff")
                time.sleep(CHAIN_LINGER_S)

        if i == 0 and args.mode != "chain":  # the chain's processes see no one's liveliness
            deadline = time.monotonic() + args.timeout
            while time.monotonic() < deadline:
                live = [r for r in control.liveliness().get(f"{prefix}/live/*", timeout=1.0) if r.ok]
                if len(live) >= n:
                    break
                time.sleep(0.05)
            else:
                print(json.dumps({"error": "bare ring did not form"}), flush=True)
                return 1
        if i == 0 and chained:
            # every process is up, but a successor link may still be forming and a frame put
            # before it is lost: send until a frame has gone round
            deadline, number = time.monotonic() + args.timeout, 0
            while not stamps and time.monotonic() < deadline:
                put(number.to_bytes(4, "little") + bytes(510))
                number += 1
                done.wait(1.0)
        elif i == 0:
            time.sleep(0.3 + 0.01 * n)  # let every peer connect to every other
            put(bytes(514))
        if i == 0:
            if warm.wait(args.timeout):  # for a caller that waits on a ring running for long
                print(json.dumps({"warm": args.warmup}), flush=True)
            if not done.wait(args.timeout):
                print(
                    json.dumps({"error": f"only {len(stamps)} rounds in {args.timeout} s"}),
                    flush=True,
                )
                stop_all()
                return 1
            rounds = [b - a for a, b in itertools.pairwise(stamps)][args.warmup :]
            put_times.sort()
            put_us = put_times[len(put_times) // 2] * 1e6 if put_times else float("nan")
            result = {"rounds_s": rounds, "put_us_median": put_us}
            if args.stamps:  # a profiler counts the rounds inside its own window
                result["stamps_s"] = stamps[args.warmup :]
            print(json.dumps(result), flush=True)
            stop_all()
            time.sleep(0.1)
        else:
            done.wait(args.timeout + 30)
            if chained:
                time.sleep(CHAIN_LINGER_S)
        subscriber.undeclare()
        if fallback is not None:
            fallback.undeclare()
        stop.undeclare()
        token.undeclare()
    return 0


if __name__ == "__main__":
    sys.exit(main())
