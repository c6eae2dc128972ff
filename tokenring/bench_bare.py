"""The bare Zenoh ring baseline: N processes forwarding a 514-byte payload, no OS work at all.

Same Zenoh settings as the real ring (peers on loopback, multicast off, express publishers,
congestion control DROP, real-time priority); process 0 times the rounds and prints them as
one JSON line on stdout.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import threading
import time

import zenoh

from tokenring.zconfig import make_config, open_session


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--index", type=int, required=True)
    p.add_argument("--count", type=int, required=True)
    p.add_argument("--port", type=int, required=True)
    p.add_argument("--rounds", type=int, default=2000)
    p.add_argument("--warmup", type=int, default=200)
    p.add_argument("--ring", default="bare")
    p.add_argument("--timeout", type=float, default=120.0)
    args = p.parse_args(argv)
    i, n = args.index, args.count
    endpoint = f"tcp/127.0.0.1:{args.port}"
    config = make_config(listen=[endpoint]) if i == 0 else make_config(connect=[endpoint])
    prefix = f"tokenring-bare/{args.ring}"
    done = threading.Event()
    stamps: list[float] = []
    total = args.rounds + args.warmup + 1
    with open_session(config) as session:
        publisher = session.declare_publisher(
            f"{prefix}/hop/{(i + 1) % n}",
            express=True,
            congestion_control=zenoh.CongestionControl.DROP,
            priority=zenoh.Priority.REAL_TIME,
        )
        put = publisher.put

        if i == 0:

            def handle(sample: zenoh.Sample) -> None:
                stamps.append(time.perf_counter())
                if len(stamps) >= total:
                    done.set()
                    return
                put(sample.payload.to_bytes())

        else:

            def handle(sample: zenoh.Sample) -> None:
                put(sample.payload.to_bytes())

        subscriber = session.declare_subscriber(f"{prefix}/hop/{i}", handle)
        stop = session.declare_subscriber(f"{prefix}/stop", lambda _s: done.set())
        token = session.liveliness().declare_token(f"{prefix}/live/{i}")
        if i == 0:
            deadline = time.monotonic() + args.timeout
            while time.monotonic() < deadline:
                live = [r for r in session.liveliness().get(f"{prefix}/live/*", timeout=1.0) if r.ok]
                if len(live) >= n:
                    break
                time.sleep(0.05)
            else:
                print(json.dumps({"error": "bare ring did not form"}), flush=True)
                return 1
            time.sleep(0.3)  # let every peer connect to every other
            put(bytes(514))
            if not done.wait(args.timeout):
                print(
                    json.dumps({"error": f"only {len(stamps)} rounds in {args.timeout} s"}),
                    flush=True,
                )
                session.put(f"{prefix}/stop", b"")
                return 1
            rounds = [b - a for a, b in itertools.pairwise(stamps)][args.warmup :]
            print(json.dumps({"rounds_s": rounds}), flush=True)
            session.put(f"{prefix}/stop", b"")
            time.sleep(0.1)
        else:
            done.wait(args.timeout + 30)
        subscriber.undeclare()
        stop.undeclare()
        token.undeclare()
    return 0


if __name__ == "__main__":
    sys.exit(main())
