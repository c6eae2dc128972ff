"""A listen endpoint another process holds is refused in one line a user can read: no Zenoh
source paths, the endpoint named, exit 2 (the user's choice of endpoint)."""

from __future__ import annotations

import socket
from collections.abc import Iterator

import pytest

from tests.support.refusal import refusal_line, run_refused
from tokenring.transport.session import free_port
from tokenring.transport.zenoh_config import zenoh_message

#: Zenoh's own text for a port in use, as it raised it
ZENOH_TEXT = (
    "Can not create a new TCP listener bound to tcp/127.0.0.1:25391: [127.0.0.1:25391: Address already "
    "in use (os error 98) at /root/.cargo/git/checkouts/zenoh-9c599d5ef3e0480e/cc83980/io/"
    "zenoh-link-commons/src/tcp.rs:61.] at /root/.cargo/git/checkouts/zenoh-9c599d5ef3e0480e/cc83980/"
    "io/zenoh-links/zenoh-link-tcp/src/unicast.rs:338."
)


@pytest.fixture
def held() -> Iterator[str]:
    """An endpoint a plain TCP listener (not Zenoh) holds while the test runs."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(("127.0.0.1", free_port()))
        sock.listen()
        yield f"tcp/127.0.0.1:{sock.getsockname()[1]}"


def test_zenohs_text_loses_its_source_paths():
    assert zenoh_message(Exception(ZENOH_TEXT)) == (
        "cannot listen on tcp/127.0.0.1:25391: the address is in use by another process "
        "(give another --listen endpoint, or stop that process)"
    )
    assert zenoh_message(Exception("Timeout at /a/b/src/x.rs:12. retry")) == "Timeout retry"


@pytest.mark.parametrize(
    "verb",
    [["node", "--id", "9", "--duration", "1"], ["up", "--no-world", "--no-programs", "--nodes", "main"]],
)
def test_a_held_listen_endpoint_is_one_clean_line_and_exit_2(held, verb):
    line = refusal_line(run_refused(*verb, "--listen", held), f"cannot listen on {held}", "in use")
    assert ".rs:" not in line and "/root/" not in line and "cargo" not in line
