"""``tokenring sniff``: decode every frame on the wire (read-only)."""

from tokenring.sniff import add_parser, run

__all__ = ["add_parser", "run"]
