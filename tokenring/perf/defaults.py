"""The benchmarks' defaults that a verb's options show (``tokenring bench --help``), apart from
the measuring code (numpy, the launcher) so that showing them imports nothing else."""

from __future__ import annotations

#: from this ring size on, ``--topology auto`` makes the nodes clients of a Zenoh router: a full
#: mesh of N peers keeps N(N-1)/2 links (bench/RESULTS.md measures both)
ROUTER_FROM = 32
