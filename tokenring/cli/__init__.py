"""The command line: ``tokenring`` and its verbs (``commands/``), and the helpers a verb of an
application (the robot's) builds its options and output with."""

from __future__ import annotations

from typing import TYPE_CHECKING

from tokenring._face import lazy_face

if TYPE_CHECKING:
    from tokenring._util.process import StopEvent, stop_on_signals, wait_for_stop
    from tokenring._util.tables import format_table
    from tokenring.cli.args import (
        OneLineParser,
        add_json_option,
        add_ring_options,
        int_within,
        node_id,
        non_negative_seconds,
        number_within,
        positive_int,
        seconds,
        tap_session,
        with_examples,
    )
    from tokenring.cli.output import check_json_target, check_option_output, print_json, write_json
    from tokenring.cli.verbs import verb_modules
else:  # each name is imported on first use
    __getattr__, __dir__ = lazy_face(
        __name__,
        {
            "add_json_option": "tokenring.cli.args",
            "add_ring_options": "tokenring.cli.args",
            "check_json_target": "tokenring.cli.output",
            "check_option_output": "tokenring.cli.output",
            "format_table": "tokenring._util.tables",
            "int_within": "tokenring.cli.args",
            "node_id": "tokenring.cli.args",
            "non_negative_seconds": "tokenring.cli.args",
            "number_within": "tokenring.cli.args",
            "OneLineParser": "tokenring.cli.args",
            "positive_int": "tokenring.cli.args",
            "print_json": "tokenring.cli.output",
            "seconds": "tokenring.cli.args",
            "StopEvent": "tokenring._util.process",
            "stop_on_signals": "tokenring._util.process",
            "tap_session": "tokenring.cli.args",
            "verb_modules": "tokenring.cli.verbs",
            "wait_for_stop": "tokenring._util.process",
            "with_examples": "tokenring.cli.args",
            "write_json": "tokenring.cli.output",
        },
    )

__all__ = [
    "OneLineParser",
    "StopEvent",
    "add_json_option",
    "add_ring_options",
    "check_json_target",
    "check_option_output",
    "format_table",
    "int_within",
    "node_id",
    "non_negative_seconds",
    "number_within",
    "positive_int",
    "print_json",
    "seconds",
    "stop_on_signals",
    "tap_session",
    "verb_modules",
    "wait_for_stop",
    "with_examples",
    "write_json",
]
