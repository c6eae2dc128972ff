"""``tokenring bench``: token round trips against a bare Zenoh ring, measured in one run."""

from tokenring.bench import add_parser, run

__all__ = ["add_parser", "run"]
