"""``tokenring dissector``: print a Wireshark Lua dissector for the token, generated from the
protocol.yaml that is loaded (:mod:`tokenring.observe.dissector`)."""

from __future__ import annotations

import argparse
import sys

from tokenring.cli.args import with_examples

HELP = "print a Wireshark Lua dissector for the token, generated from protocol.yaml"

EXAMPLES = """examples:
  tokenring dissector > tokenring.lua
  tokenring sniff --write frames.pcapng --duration 10 && tshark -X lua_script:tokenring.lua -r frames.pcapng
  tokenring dissector > ~/.local/lib/wireshark/plugins/tokenring.lua   # Wireshark loads it at start
  tokenring dissector --protocol my-protocol.yaml > my-ring.lua
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "dissector",
        help=HELP,
        description="Print a Lua dissector for Wireshark and tshark that decodes the token inside "
        "the ARCNET packets of a capture written by 'sniff --write FILE.pcapng' or 'record --pcap': "
        "the header, the system command by name and its window, every inbox's command header and "
        "its command's arguments by name and type, every data channel's fields (enums by name), "
        "and the CRC checked. Everything comes from the protocol.yaml that is loaded; generate it "
        "again when that changes. See docs/wireshark.md.",
        **with_examples(EXAMPLES),
    )
    p.add_argument("--protocol", metavar="FILE", help="protocol.yaml to use (also $TOKENRING_PROTOCOL)")


def run(args: argparse.Namespace) -> int:
    from tokenring._util.files import read_text
    from tokenring.contract.protocol import default_protocol_path, parse_protocol
    from tokenring.errors import ProtocolError
    from tokenring.observe.dissector import lua_dissector

    path = args.protocol or str(default_protocol_path())
    text = read_text(path, "protocol file", lambda where, problem: ProtocolError(where, "", problem))
    protocol = parse_protocol(text, path, cache=True)
    sys.stdout.write(lua_dissector(protocol, source=path, protocol_text=text))
    sys.stdout.flush()
    return 0
