"""tokenring: a ring of OS processes passing one 512-byte token over Zenoh.

This is the face programs, extensions and tools import: the program API, the extension seam,
the wire contract and the errors. Everything else lives in the role folders (``contract/``,
``transport/``, ``node/``, ``host/``, ``observe/``, ``chaos/``, ``perf/``, ``web/``, ``cli/``)
and may move; the names here are loaded on first use, so importing tokenring costs nothing."""

from __future__ import annotations

from typing import TYPE_CHECKING

from tokenring._face import lazy_face

#: the one version: pyproject.toml's ([tool.hatch.version]) and ``tokenring --version``'s
__version__ = "0.1.0"

if TYPE_CHECKING:
    from tokenring._util.files import (
        check_input,
        check_output,
        message_error,
        option_error,
        read_bytes,
        read_text,
        replacing,
        write_atomically,
        write_failed,
    )
    from tokenring._util.strict_yaml import NumberLoader, YAMLStructureError, one_line, yaml_problem
    from tokenring.contract import keys
    from tokenring.contract.frame import frame_problem
    from tokenring.contract.protocol import CommandChannel, Protocol, default_protocol, load_protocol
    from tokenring.contract.ring import hop_time, parse_bitrate
    from tokenring.errors import (
        ChannelError,
        FrameError,
        ProgramError,
        ProtocolError,
        TokenRingError,
        TransportClosed,
        TransportError,
        UsageError,
    )
    from tokenring.extensions import Extension, SimPlan, UpPlan, WebAction, WebKey, WebKeys, WebPanel
    from tokenring.node.node_os import NodeOS
    from tokenring.node.program import UserProgram
    from tokenring.node.resident import ResidentProgram
else:  # each name is imported on first use
    __getattr__, __dir__ = lazy_face(
        __name__,
        {
            "ChannelError": "tokenring.errors",
            "check_input": "tokenring._util.files",
            "check_output": "tokenring._util.files",
            "CommandChannel": "tokenring.contract.protocol",
            "default_protocol": "tokenring.contract.protocol",
            "Extension": "tokenring.extensions",
            "frame_problem": "tokenring.contract.frame",
            "FrameError": "tokenring.errors",
            "hop_time": "tokenring.contract.ring",
            "keys": "tokenring.contract.keys",
            "load_protocol": "tokenring.contract.protocol",
            "message_error": "tokenring._util.files",
            "NodeOS": "tokenring.node.node_os",
            "NumberLoader": "tokenring._util.strict_yaml",
            "one_line": "tokenring._util.strict_yaml",
            "option_error": "tokenring._util.files",
            "parse_bitrate": "tokenring.contract.ring",
            "ProgramError": "tokenring.errors",
            "Protocol": "tokenring.contract.protocol",
            "ProtocolError": "tokenring.errors",
            "read_bytes": "tokenring._util.files",
            "read_text": "tokenring._util.files",
            "replacing": "tokenring._util.files",
            "ResidentProgram": "tokenring.node.resident",
            "SimPlan": "tokenring.extensions",
            "TokenRingError": "tokenring.errors",
            "TransportClosed": "tokenring.errors",
            "TransportError": "tokenring.errors",
            "UpPlan": "tokenring.extensions",
            "UsageError": "tokenring.errors",
            "UserProgram": "tokenring.node.program",
            "WebAction": "tokenring.extensions",
            "WebKey": "tokenring.extensions",
            "WebKeys": "tokenring.extensions",
            "WebPanel": "tokenring.extensions",
            "write_atomically": "tokenring._util.files",
            "write_failed": "tokenring._util.files",
            "YAMLStructureError": "tokenring._util.strict_yaml",
            "yaml_problem": "tokenring._util.strict_yaml",
        },
    )

__all__ = [
    "ChannelError",
    "CommandChannel",
    "Extension",
    "FrameError",
    "NodeOS",
    "NumberLoader",
    "ProgramError",
    "Protocol",
    "ProtocolError",
    "ResidentProgram",
    "SimPlan",
    "TokenRingError",
    "TransportClosed",
    "TransportError",
    "UpPlan",
    "UsageError",
    "UserProgram",
    "WebAction",
    "WebKey",
    "WebKeys",
    "WebPanel",
    "YAMLStructureError",
    "check_input",
    "check_output",
    "default_protocol",
    "frame_problem",
    "hop_time",
    "keys",
    "load_protocol",
    "message_error",
    "one_line",
    "option_error",
    "parse_bitrate",
    "read_bytes",
    "read_text",
    "replacing",
    "write_atomically",
    "write_failed",
    "yaml_problem",
]
