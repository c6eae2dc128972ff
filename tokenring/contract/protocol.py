"""Load, validate and compile ``protocol.yaml`` into numpy structured dtypes over the token.

The file is checked completely before anything starts: overlapping channels, channels in the
header or past the token, fields that do not fit their channel, duplicate IDs, names, seed names
or addresses, unknown types and typos in keys are each refused with a :class:`ProtocolError`
naming the entry. After compilation every channel offers a zero-copy view over a token buffer.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import struct
import zlib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from functools import cache, cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tokenring.errors import ChannelError, ProtocolError

if TYPE_CHECKING:
    import numpy as np

SCALAR_TYPES: dict[str, str] = {
    "u8": "<u1",
    "i8": "<i1",
    "u16": "<u2",
    "i16": "<i2",
    "u32": "<u4",
    "i32": "<i4",
    "u64": "<u8",
    "i64": "<i8",
    "f32": "<f4",
    "f64": "<f8",
}
_TYPE_RE = re.compile(r"^(?P<base>[a-z]+[0-9]*)(?:\[(?P<count>[0-9]+)\])?$")
HEADER_FIELDS = (
    "sid",
    "did",
    "long_marker",
    "size_marker",
    "counter",
    "syscmd_issuer",
    "syscmd_target",
    "syscmd_code",
    "syscmd_length",
    "syscmd_ack",
    "epoch",
    "epoch_origin",
)
COMMAND_HEADER_FIELDS = ("sender", "state", "code", "seq", "incarnation")
_TOP_KEYS = {"version", "token", "system", "command_channel", "common_commands", "enums", "nodes"}
_FIELD_KEYS = {"type", "unit", "enum", "doc", "offset", "const"}


# --------------------------------------------------------------------------------------------
# compiled objects


@dataclass(frozen=True)
class Field:
    """One typed field inside a channel, at ``offset`` bytes from the channel's start."""

    name: str
    type_name: str
    size: int
    offset: int
    unit: str = ""
    enum: str = ""
    doc: str = ""

    @cached_property
    def dtype(self) -> np.dtype:
        """The field's numpy dtype, built on first use: a node that only passes the token on
        never imports numpy (what a node process imports is what it needs)."""
        return type_dtype(self.type_name)

    @property
    def is_text(self) -> bool:
        return self.type_name.startswith("str[")

    def to_python(self, value: Any) -> Any:
        """Turn a numpy value of this field into plain Python (int, float, list or str)."""
        if self.is_text:
            return bytes(value).rstrip(b"\0").decode("ascii", "replace")
        return value.tolist() if hasattr(value, "tolist") else value  # numpy arrays and scalars


@dataclass(frozen=True)
class Channel:
    """A command or data channel: a named byte range of the token with typed fields."""

    name: str
    seed_name: str
    node: str
    kind: str
    address: int
    size: int
    fields: tuple[Field, ...]

    @cached_property
    def dtype(self) -> np.dtype:
        """The channel's structured dtype (its fields over ``size`` bytes), built on first use."""
        return struct_dtype(self.fields, self.size)

    @property
    def end(self) -> int:
        return self.address + self.size

    def view(self, buffer: bytearray | memoryview | bytes) -> np.ndarray:
        """A zero-copy 0-d structured view of this channel inside a token (or frame) buffer."""
        import numpy as np

        return np.ndarray((), dtype=self.dtype, buffer=buffer, offset=self.address)

    def decode(self, buffer: bytes | bytearray | memoryview) -> dict[str, Any]:
        """The channel's fields as plain Python values."""
        view = self.view(buffer)
        return {f.name: f.to_python(view[f.name]) for f in self.fields}


@dataclass(frozen=True)
class Command:
    """A command code accepted by an inbox, with its argument fields (after the header)."""

    name: str
    code: int
    args: tuple[Field, ...]
    #: the inbox's command header and the arguments, over the inbox's ``size`` bytes
    layout: tuple[Field, ...]
    size: int
    doc: str = ""
    common: bool = False

    @cached_property
    def dtype(self) -> np.dtype:
        """Header and arguments as one structured dtype over the inbox, built on first use."""
        return struct_dtype(self.layout, self.size)

    def arg_names(self) -> tuple[str, ...]:
        return tuple(a.name for a in self.args)


@dataclass(frozen=True)
class CommandChannel(Channel):
    """A module's inbox: the common command header followed by per-command arguments."""

    commands: Mapping[str, Command] = field(default_factory=dict)
    by_code: Mapping[int, Command] = field(default_factory=dict)

    def command(self, name_or_code: str | int) -> Command:
        """Look up a command by name or code; :class:`ChannelError` names the inbox if unknown."""
        found = (
            self.by_code.get(name_or_code)
            if isinstance(name_or_code, int)
            else self.commands.get(name_or_code)
        )
        if found is None:
            known = ", ".join(sorted(self.commands))
            raise ChannelError(f"{self.name}: unknown command {name_or_code!r} (known: {known})")
        return found

    def decode_command(self, buffer: bytes | bytearray | memoryview) -> dict[str, Any]:
        """Header plus, if the code is known, the command's name and arguments."""
        head = self.view(buffer)
        out: dict[str, Any] = {f.name: f.to_python(head[f.name]) for f in self.fields}
        cmd = self.by_code.get(out["code"])
        if cmd is not None and out["state"] != 0:
            import numpy as np

            view = np.ndarray((), dtype=cmd.dtype, buffer=buffer, offset=self.address)
            out["command"] = cmd.name
            out["args"] = {a.name: a.to_python(view[a.name]) for a in cmd.args}
        return out


@dataclass(frozen=True)
class NodeSpec:
    """A module of the ring: ID, names and its two channels."""

    name: str
    id: int
    seed_name: str
    command: CommandChannel
    data: Channel
    #: a station ``up`` starts only when asked for (``--nodes``, or an application's option):
    #: its place in the token is reserved, the ring forms without it
    optional: bool = False


@dataclass(frozen=True)
class Header:
    """Byte offsets of the token header fields and the constant marker values."""

    offsets: Mapping[str, int]
    consts: Mapping[str, int]
    fields: tuple[Field, ...]

    def __getattr__(self, name: str) -> int:
        try:
            return self.offsets[name]
        except KeyError:
            raise AttributeError(name) from None


@dataclass(frozen=True)
class Protocol:
    """The compiled ``protocol.yaml``."""

    source: str
    token_size: int
    header: Header
    header_size: int
    system_data_offset: int
    system_data_size: int
    user_area_offset: int
    user_area_size: int
    all_nodes: int
    system_commands: Mapping[str, int]
    system_window: Mapping[str, Mapping[str, tuple[Field, ...]]]
    command_header: tuple[Field, ...]
    command_states: Mapping[str, int]
    common_commands: Mapping[str, Command]
    enums: Mapping[str, Mapping[str, int]]
    nodes: Mapping[str, NodeSpec]
    by_id: Mapping[int, NodeSpec]
    channels: Mapping[str, Channel]

    @property
    def frame_size(self) -> int:
        return self.token_size + 2

    @property
    def default_nodes(self) -> tuple[NodeSpec, ...]:
        """The nodes a ring starts with when none are named: all but the optional ones."""
        return tuple(n for n in self.nodes.values() if not n.optional)

    def node(self, name_or_id: str | int) -> NodeSpec:
        """A node by short name, seed name or ID; :class:`ChannelError` lists the known ones."""
        if isinstance(name_or_id, int):
            spec = self.by_id.get(name_or_id)
        else:
            spec = self.nodes.get(name_or_id)
            if spec is None:
                for candidate in self.nodes.values():
                    if candidate.seed_name == name_or_id:
                        spec = candidate
                if spec is None and name_or_id.isdigit():
                    spec = self.by_id.get(int(name_or_id))
        if spec is None:
            known = ", ".join(f"{n.name}={n.id}" for n in self.nodes.values())
            raise ChannelError(f"unknown node {name_or_id!r} (known: {known})")
        return spec

    def channel(self, name: str) -> Channel:
        """A channel by ``node.kind`` (``sonar.data``) or seed name (``ROBSONAR_DATA``)."""
        found = self.channels.get(name)
        if found is None:
            for ch in self.channels.values():
                if ch.seed_name == name:
                    return ch
            known = ", ".join(sorted(self.channels))
            raise ChannelError(f"unknown channel {name!r} (known: {known})")
        return found

    def enum_name(self, enum: str, value: int) -> str:
        """The symbolic name of ``value`` in ``enum``, or the number as text if it has none."""
        for name, number in self.enums.get(enum, {}).items():
            if number == value:
                return name
        return str(value)

    def system_command_name(self, code: int) -> str:
        """``ARCNET_SCAN`` for 1, ``NONE`` for 0, the number as text if unknown."""
        for name, number in self.system_commands.items():
            if number == code:
                return name
        return "NONE" if code == 0 else str(code)


# --------------------------------------------------------------------------------------------
# loading


_STRUCT_CODES = {
    "u1": "B",
    "i1": "b",
    "u2": "H",
    "i2": "h",
    "u4": "I",
    "i4": "i",
    "u8": "Q",
    "i8": "q",
    "f4": "f",
    "f8": "d",
}


def fields_struct(fields: Iterable[Field]) -> struct.Struct:
    """The :mod:`struct` equivalent of packed fields (``u8[N]`` and ``str[N]`` become bytes)."""
    codes = []
    offset = 0
    for f in fields:
        if f.offset != offset:
            raise ProtocolError("<protocol>", f.name, "fields of a struct must be packed without gaps")
        base, count = split_type(f.type_name)
        if f.is_text or (base == "u8" and count is not None):
            codes.append(f"{f.size}s")
        else:
            n = count or 1
            codes.append((str(n) if n > 1 else "") + _STRUCT_CODES[SCALAR_TYPES[base][1:]])
        offset += f.size
    return struct.Struct("<" + "".join(codes))


def split_type(type_name: str) -> tuple[str, int | None]:
    """``("i16", 4)`` for ``i16[4]``, ``("u8", None)`` for ``u8``: a checked field type's parts."""
    match = _TYPE_RE.match(type_name.strip())
    assert match is not None, type_name  # the compiler checked it
    count = match.group("count")
    return match.group("base"), int(count) if count is not None else None


def type_size(type_name: str) -> int:
    """Bytes of a checked field type (``str[12]``: 12, ``i16[4]``: 8), without numpy."""
    base, count = split_type(type_name)
    one = 1 if base == "str" else int(SCALAR_TYPES[base][2:])
    return one * (count or 1)


def type_dtype(type_name: str) -> np.dtype:
    """The numpy dtype of a checked field type."""
    import numpy as np

    base, count = split_type(type_name)
    if base == "str":
        return np.dtype(f"S{count}")
    if count is None:
        return np.dtype(SCALAR_TYPES[base])
    return np.dtype((SCALAR_TYPES[base], (count,)))


def struct_dtype(fields: Iterable[Field], itemsize: int) -> np.dtype:
    """Packed (or placed) fields as one numpy structured dtype of ``itemsize`` bytes."""
    import numpy as np

    fields = list(fields)
    return np.dtype(
        {
            "names": [f.name for f in fields],
            "formats": [f.dtype for f in fields],
            "offsets": [f.offset for f in fields],
            "itemsize": itemsize,
        }
    )


def default_protocol_path() -> Path:
    """``$TOKENRING_PROTOCOL``, else the repository's ``protocol.yaml``, else the packaged copy."""
    env = os.environ.get("TOKENRING_PROTOCOL")
    if env:
        return Path(env)
    package = Path(__file__).resolve().parents[1]  # tokenring/
    repo_copy = package.parent / "protocol.yaml"
    if repo_copy.exists():
        return repo_copy
    return package / "_data" / "protocol.yaml"


def load_protocol(path: str | os.PathLike[str] | None = None) -> Protocol:
    """Read and compile a protocol file; raises :class:`ProtocolError` naming what is wrong."""
    file = Path(path) if path is not None else default_protocol_path()
    from tokenring._util.files import read_text

    source = str(file)
    text = read_text(file, "protocol file", lambda where, problem: ProtocolError(where, "", problem))
    return parse_protocol(text, source, cache=True)


@cache
def default_protocol() -> Protocol:
    """The protocol at :func:`default_protocol_path`, loaded once per process."""
    return load_protocol()


def parse_protocol(text: str, source: str = "<protocol>", *, cache: bool = False) -> Protocol:
    """Compile protocol text (YAML); raises :class:`ProtocolError`. ``cache``: read the text's
    document from, and keep a valid one in, :func:`document_cache_dir` (protocol files)."""
    if not cache:
        return _Compiler(source).compile(_read_yaml(text, source))
    path = cached_document_path(text)
    try:
        kept = json.loads(path.read_text())
        if kept["text"] == text:  # (the name is a 32-bit checksum: another text may share it)
            return _Compiler(source).compile(kept["document"])
    except (OSError, ValueError, TypeError, KeyError, ProtocolError):
        pass  # none yet, damaged, or not what this compiler accepts: read the YAML
    doc = _read_yaml(text, source)
    protocol = _Compiler(source).compile(doc)
    keep_document(doc, text, path)
    return protocol


#: bump when the YAML reading changes what a text means (tokenring._util.strict_yaml's loader)
DOCUMENT_CACHE_VERSION = 2
#: parsed documents kept (the newest; one per protocol text in use)
DOCUMENT_CACHE_SIZE = 16


def document_cache_dir() -> Path:
    """Where parsed protocol documents are kept: ``$XDG_CACHE_HOME/tokenring`` (``~/.cache``)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "tokenring"


def cached_document_path(text: str) -> Path:
    """Where the parsed document of protocol ``text`` is kept (named by the text's CRC-32).

    A protocol file's YAML is read once; later readings of the same text (every node of a ring
    booting) take its document from this JSON copy and import no YAML parser: 1-2 MB of each
    node process's memory. A text JSON cannot hold exactly, or a cache that cannot be written,
    is simply read as YAML each time. The name is a CRC, not a cryptographic hash: hashlib
    would load OpenSSL into every node (3-4 MB of RSS); the copy holds its text, compared on
    reading, so two texts with one name only cost a YAML reading."""
    data = text.encode()
    return document_cache_dir() / f"protocol-{DOCUMENT_CACHE_VERSION}-{zlib.crc32(data):08x}-{len(data)}.json"


def keep_document(doc: Any, text: str, path: Path) -> None:
    """Write ``doc`` of protocol ``text`` (both) to ``path`` if JSON gives the document back as
    it was; keep the newest few."""
    partial = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    try:
        copy = json.dumps({"text": text, "document": doc})
        if json.loads(copy)["document"] != doc:  # e.g. keys that are numbers
            return
        path.parent.mkdir(parents=True, exist_ok=True)
        partial.write_text(copy)
        os.replace(partial, path)  # whole or not at all, for nodes booting together
        kept = sorted(path.parent.glob("protocol-*.json"), key=lambda p: p.stat().st_mtime, reverse=True)
        for old in kept[DOCUMENT_CACHE_SIZE:]:
            old.unlink(missing_ok=True)
    except (OSError, TypeError, ValueError):
        with contextlib.suppress(OSError):
            partial.unlink(missing_ok=True)


def _read_yaml(text: str, source: str) -> Any:
    import yaml

    from tokenring._util.strict_yaml import one_line, strict_loader, yaml_problem

    try:
        return yaml.load(text, Loader=strict_loader(ProtocolError, source))
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise ProtocolError(source, where, yaml_problem(exc)) from None
    except yaml.YAMLError as exc:
        raise ProtocolError(source, "", f"not YAML text: {one_line(exc)}") from None


class _Compiler:
    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, entry: str, problem: str) -> ProtocolError:
        return ProtocolError(self.source, entry, problem)

    # -- small checked getters -----------------------------------------------------------------
    def mapping(self, value: Any, entry: str) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise self.fail(entry, f"expected a mapping, found {type(value).__name__}")
        return value

    def integer(self, value: Any, entry: str, lo: int, hi: int) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(entry, f"expected an integer, found {value!r}")
        if not lo <= value <= hi:
            raise self.fail(entry, f"{value} is outside {lo}..{hi}")
        return value

    def get(self, mapping: dict[str, Any], key: str, entry: str) -> Any:
        if key not in mapping:
            raise self.fail(entry, f"missing key {key!r}")
        return mapping[key]

    def only_keys(self, mapping: dict[str, Any], allowed: Iterable[str], entry: str) -> None:
        extra = set(mapping) - set(allowed)
        if extra:
            raise self.fail(
                entry,
                f"unknown key(s) {', '.join(sorted(map(str, extra)))} "
                f"(allowed: {', '.join(sorted(allowed))})",
            )

    # -- types and fields ----------------------------------------------------------------------
    def field_size(self, type_name: Any, entry: str) -> int:
        """Check a field's type; its size in bytes."""
        if not isinstance(type_name, str):
            raise self.fail(entry, f"type must be text such as 'u8' or 'i16[4]', got {type_name!r}")
        match = _TYPE_RE.match(type_name.strip())
        if not match:
            raise self.fail(entry, f"cannot read type {type_name!r}")
        base, count = match.group("base"), match.group("count")
        if base == "str":
            if count is None or int(count) < 1:
                raise self.fail(entry, f"text type needs a length, e.g. 'str[12]', got {type_name!r}")
            return type_size(type_name)
        if base not in SCALAR_TYPES:
            known = ", ".join([*SCALAR_TYPES, "str[N]"])
            raise self.fail(entry, f"unknown type {base!r} (known: {known})")
        if count is not None and int(count) < 1:
            raise self.fail(entry, f"array length must be at least 1 in {type_name!r}")
        return type_size(type_name)

    def fields(self, spec: Any, entry: str, start: int, limit: int, enums: Mapping[str, Any]) -> list[Field]:
        """Fields packed from ``start``; each must end at or before ``limit`` (channel size)."""
        if spec is None:
            return []
        spec = self.mapping(spec, entry)
        out: list[Field] = []
        offset = start
        for name, raw in spec.items():
            where = f"{entry}.{name}"
            if not isinstance(name, str) or not name.isidentifier():
                raise self.fail(where, f"field name {name!r} is not a valid identifier")
            unit = doc = enum = ""
            if isinstance(raw, dict):
                self.only_keys(raw, _FIELD_KEYS - {"const"}, where)
                type_name = self.get(raw, "type", where)
                unit = str(raw.get("unit", ""))
                doc = str(raw.get("doc", ""))
                enum = str(raw.get("enum", ""))
                if enum and enum not in enums:
                    raise self.fail(where, f"unknown enum {enum!r}")
                if "offset" in raw:
                    offset = self.integer(raw["offset"], f"{where}.offset", 0, limit)
            else:
                type_name = raw
            size = self.field_size(type_name, where)
            if offset + size > limit:
                raise self.fail(
                    where,
                    f"field {name!r} ({type_name}, {size} bytes at offset {offset}) "
                    f"overflows the {limit}-byte channel by {offset + size - limit} bytes",
                )
            for other in out:
                if offset < other.offset + other.size and other.offset < offset + size:
                    raise self.fail(where, f"field {name!r} overlaps field {other.name!r}")
            out.append(Field(name, str(type_name), size, offset, unit, enum, doc))
            offset += size
        return out

    # -- sections ------------------------------------------------------------------------------
    def compile(self, doc: Any) -> Protocol:
        if doc is None:
            raise self.fail("", "the file is empty")
        doc = self.mapping(doc, "(top level)")
        self.only_keys(doc, _TOP_KEYS, "(top level)")
        self.integer(self.get(doc, "version", "(top level)"), "version", 1, 1)
        enums = self.enums(doc.get("enums") or {})
        token = self.mapping(self.get(doc, "token", "(top level)"), "token")
        self.only_keys(token, {"size", "crc", "header", "system_data", "user_area"}, "token")
        token_size = self.integer(self.get(token, "size", "token"), "token.size", 512, 512)
        crc = token.get("crc", "crc16-arc")
        if crc != "crc16-arc":
            raise self.fail("token.crc", f"only crc16-arc is supported, got {crc!r}")
        header, header_size = self.header(self.get(token, "header", "token"), enums)
        sys_off, sys_size = self.area(token, "system_data", header_size, token_size)
        user_off, user_size = self.area(token, "user_area", header_size, token_size)
        if not (user_off <= sys_off and sys_off + sys_size <= user_off + user_size):
            raise self.fail("token.system_data", "must lie inside token.user_area")

        system = self.mapping(self.get(doc, "system", "(top level)"), "system")
        self.only_keys(system, {"all_nodes", "commands", "window"}, "system")
        all_nodes = self.integer(self.get(system, "all_nodes", "system"), "system.all_nodes", 0, 255)
        system_commands = self.codes(self.get(system, "commands", "system"), "system.commands")
        system_window = self.window(system.get("window") or {}, system_commands, sys_size, enums)

        cc = self.mapping(self.get(doc, "command_channel", "(top level)"), "command_channel")
        self.only_keys(cc, {"header"}, "command_channel")
        cmd_header = self.fields(
            self.get(cc, "header", "command_channel"), "command_channel.header", 0, 255, enums
        )
        names = tuple(f.name for f in cmd_header)
        missing = [n for n in COMMAND_HEADER_FIELDS if n not in names]
        if missing:
            raise self.fail("command_channel.header", f"missing field(s): {', '.join(missing)}")
        head_size = max(f.offset + f.size for f in cmd_header)
        states = enums.get("command_state")
        if not states or {"FREE", "OCCUPIED", "ACKNOWLEDGED"} - set(states):
            raise self.fail("enums.command_state", "needs FREE, OCCUPIED and ACKNOWLEDGED")
        if states["FREE"] != 0:
            raise self.fail("enums.command_state.FREE", "must be 0 (a zeroed token is all free)")

        common_raw = self.mapping(doc.get("common_commands") or {}, "common_commands")
        common_specs = self.command_specs(common_raw, "common_commands", enums)

        nodes, by_id, channels = self.nodes(
            self.get(doc, "nodes", "(top level)"),
            enums,
            cmd_header,
            head_size,
            common_specs,
            (user_off, user_off + user_size),
        )
        # a common command compiled against the smallest inbox, for decoding without a node
        common_commands = {}
        if nodes:
            first_inbox = next(iter(nodes.values())).command
            common_commands = {n: c for n, c in first_inbox.commands.items() if c.common}
        return Protocol(
            source=self.source,
            token_size=token_size,
            header=header,
            header_size=header_size,
            system_data_offset=sys_off,
            system_data_size=sys_size,
            user_area_offset=user_off,
            user_area_size=user_size,
            all_nodes=all_nodes,
            system_commands=system_commands,
            system_window=system_window,
            command_header=tuple(cmd_header),
            command_states=dict(states),
            common_commands=common_commands,
            enums=enums,
            nodes=nodes,
            by_id=by_id,
            channels=channels,
        )

    def enums(self, raw: Any) -> dict[str, dict[str, int]]:
        raw = self.mapping(raw, "enums")
        out: dict[str, dict[str, int]] = {}
        for name, values in raw.items():
            values = self.mapping(values, f"enums.{name}")
            seen: dict[int, str] = {}
            for key, number in values.items():
                if not isinstance(key, str):  # YAML 1.1 reads a bare OFF, ON, YES or NO as a bool
                    raise self.fail(f"enums.{name}.{key}", f"the name {key!r} is not text: quote it")
                number = self.integer(number, f"enums.{name}.{key}", 0, 2**32 - 1)
                if number in seen:
                    raise self.fail(
                        f"enums.{name}.{key}", f"value {number} is already used by {seen[number]!r}"
                    )
                seen[number] = key
            out[str(name)] = dict(values)
        return out

    def codes(self, raw: Any, entry: str) -> dict[str, int]:
        raw = self.mapping(raw, entry)
        seen: dict[int, str] = {}
        for name, code in raw.items():
            code = self.integer(code, f"{entry}.{name}", 1, 255)
            if code in seen:
                raise self.fail(f"{entry}.{name}", f"code {code} is already used by {seen[code]!r}")
            seen[code] = name
        return dict(raw)

    def window(
        self, raw: Any, commands: Mapping[str, int], size: int, enums: Mapping[str, Any]
    ) -> dict[str, dict[str, tuple[Field, ...]]]:
        """The request/answer layout of each system command inside the system data window."""
        raw = self.mapping(raw, "system.window")
        out: dict[str, dict[str, tuple[Field, ...]]] = {}
        for name, spec in raw.items():
            where = f"system.window.{name}"
            if name not in commands:
                raise self.fail(where, f"{name!r} is not a system command (known: {', '.join(commands)})")
            spec = self.mapping(spec, where)
            self.only_keys(spec, {"request", "answer"}, where)
            out[str(name)] = {
                part: tuple(self.fields(spec[part], f"{where}.{part}", 0, size, enums)) for part in spec
            }
        return out

    def header(self, raw: Any, enums: Mapping[str, Any]) -> tuple[Header, int]:
        raw = self.mapping(raw, "token.header")
        missing = [n for n in HEADER_FIELDS if n not in raw]
        if missing:
            raise self.fail("token.header", f"missing field(s): {', '.join(missing)}")
        fields: list[Field] = []
        consts: dict[str, int] = {}
        for name, spec in raw.items():
            where = f"token.header.{name}"
            spec = self.mapping(spec, where)
            self.only_keys(spec, _FIELD_KEYS, where)
            offset = self.integer(self.get(spec, "offset", where), f"{where}.offset", 0, 511)
            size = self.field_size(self.get(spec, "type", where), where)
            for other in fields:
                if offset < other.offset + other.size and other.offset < offset + size:
                    raise self.fail(where, f"overlaps header field {other.name!r}")
            if "const" in spec:
                consts[name] = self.integer(spec["const"], f"{where}.const", 0, 255)
            fields.append(Field(name, str(spec["type"]), size, offset, "", str(spec.get("enum", ""))))
        if any(f.size != 1 for f in fields if f.name in HEADER_FIELDS):
            bad = next(f for f in fields if f.name in HEADER_FIELDS and f.size != 1)
            raise self.fail(f"token.header.{bad.name}", "the seed's header fields are one byte")
        size = max(f.offset + f.size for f in fields)
        return Header({f.name: f.offset for f in fields}, consts, tuple(fields)), size

    def area(self, token: dict[str, Any], key: str, header_size: int, token_size: int) -> tuple[int, int]:
        where = f"token.{key}"
        spec = self.mapping(self.get(token, key, "token"), where)
        self.only_keys(spec, {"offset", "size"}, where)
        offset = self.integer(self.get(spec, "offset", where), f"{where}.offset", 0, token_size)
        size = self.integer(self.get(spec, "size", where), f"{where}.size", 1, token_size)
        if offset < header_size:
            raise self.fail(where, f"starts at byte {offset}, inside the {header_size}-byte header")
        if offset + size > token_size:
            raise self.fail(where, f"ends at byte {offset + size - 1}, past byte {token_size - 1}")
        return offset, size

    def command_specs(
        self, raw: dict[str, Any], entry: str, enums: Mapping[str, Any]
    ) -> dict[str, tuple[int, Any, str]]:
        out: dict[str, tuple[int, Any, str]] = {}
        seen: dict[int, str] = {}
        for name, spec in raw.items():
            where = f"{entry}.{name}"
            spec = self.mapping(spec, where)
            self.only_keys(spec, {"code", "args", "doc"}, where)
            code = self.integer(self.get(spec, "code", where), f"{where}.code", 1, 254)
            if code in seen:
                raise self.fail(where, f"code {code} is already used by {seen[code]!r}")
            seen[code] = name
            out[str(name)] = (code, spec.get("args"), str(spec.get("doc", "")))
        return out

    def nodes(
        self,
        raw: Any,
        enums: Mapping[str, Any],
        cmd_header: list[Field],
        head_size: int,
        common: Mapping[str, tuple[int, Any, str]],
        user_area: tuple[int, int],
    ) -> tuple[dict[str, NodeSpec], dict[int, NodeSpec], dict[str, Channel]]:
        raw = self.mapping(raw, "nodes")
        if not raw:
            raise self.fail("nodes", "no nodes defined")
        nodes: dict[str, NodeSpec] = {}
        by_id: dict[int, NodeSpec] = {}
        seed_names: dict[str, str] = {}
        channels: dict[str, Channel] = {}
        for name, spec in raw.items():
            where = f"nodes.{name}"
            if not isinstance(name, str) or not re.fullmatch(r"[a-z][a-z0-9_]*", name):
                raise self.fail(where, "node names are lower-case identifiers")
            spec = self.mapping(spec, where)
            self.only_keys(spec, {"id", "seed_name", "optional", "command", "data"}, where)
            node_id = self.integer(self.get(spec, "id", where), f"{where}.id", 1, 255)
            if node_id in by_id:
                raise self.fail(
                    f"{where}.id", f"ID {node_id} is already used by node {by_id[node_id].name!r}"
                )
            seed = str(spec.get("seed_name", f"ROB{name.upper()}"))
            if seed in seed_names:
                raise self.fail(
                    f"{where}.seed_name",
                    f"seed name {seed!r} is already used by {seed_names[seed]!r}",
                )
            seed_names[seed] = name
            command = self.command_channel(spec, name, seed, enums, cmd_header, head_size, common, user_area)
            data = self.data_channel(spec, name, seed, enums, user_area)
            for ch in (command, data):
                for other in channels.values():
                    if ch.address < other.end and other.address < ch.end:
                        raise self.fail(
                            f"nodes.{name}.{ch.kind}",
                            f"channel {ch.name} (bytes {ch.address}..{ch.end - 1}) overlaps "
                            f"{other.name} (bytes {other.address}..{other.end - 1})",
                        )
                channels[ch.name] = ch
            optional = spec.get("optional", False)
            if not isinstance(optional, bool):
                raise self.fail(f"{where}.optional", f"expected true or false, got {optional!r}")
            node = NodeSpec(name, node_id, seed, command, data, optional)
            nodes[name] = node
            by_id[node_id] = node
        return nodes, by_id, channels

    def placement(self, spec: dict[str, Any], where: str, user_area: tuple[int, int]) -> tuple[int, int]:
        address = self.integer(self.get(spec, "address", where), f"{where}.address", 0, 1 << 16)
        size = self.integer(self.get(spec, "size", where), f"{where}.size", 1, 1 << 16)
        lo, hi = user_area
        if address < lo:
            raise self.fail(where, f"address {address} is inside the token header (user area starts at {lo})")
        if address + size > hi:
            raise self.fail(
                where,
                f"bytes {address}..{address + size - 1} run past the token's last byte {hi - 1}",
            )
        return address, size

    def data_channel(
        self, spec: dict[str, Any], node: str, seed: str, enums: Mapping[str, Any], user_area: tuple[int, int]
    ) -> Channel:
        where = f"nodes.{node}.data"
        raw = self.mapping(self.get(spec, "data", f"nodes.{node}"), where)
        self.only_keys(raw, {"address", "size", "fields"}, where)
        address, size = self.placement(raw, where, user_area)
        fields = self.fields(raw.get("fields"), f"{where}.fields", 0, size, enums)
        return Channel(
            f"{node}.data",
            f"{seed}_DATA",
            node,
            "data",
            address,
            size,
            tuple(fields),
        )

    def command_channel(
        self,
        spec: dict[str, Any],
        node: str,
        seed: str,
        enums: Mapping[str, Any],
        cmd_header: list[Field],
        head_size: int,
        common: Mapping[str, tuple[int, Any, str]],
        user_area: tuple[int, int],
    ) -> CommandChannel:
        where = f"nodes.{node}.command"
        raw = self.mapping(self.get(spec, "command", f"nodes.{node}"), where)
        self.only_keys(raw, {"address", "size", "commands"}, where)
        address, size = self.placement(raw, where, user_area)
        if size < head_size:
            raise self.fail(where, f"size {size} is smaller than the {head_size}-byte command header")
        own = self.command_specs(self.mapping(raw.get("commands") or {}, where), f"{where}.commands", enums)
        commands: dict[str, Command] = {}
        by_code: dict[int, Command] = {}
        merged = [(n, s, False) for n, s in own.items()] + [(n, s, True) for n, s in common.items()]
        for cmd_name, (code, args_raw, doc), is_common in merged:
            entry = f"common_commands.{cmd_name}" if is_common else f"{where}.commands.{cmd_name}"
            if cmd_name in commands:
                raise self.fail(entry, f"command name {cmd_name!r} clashes with a common command")
            if code in by_code:
                raise self.fail(
                    entry,
                    f"code {code} of {cmd_name!r} clashes with {by_code[code].name!r} in {node}'s inbox",
                )
            args = self.fields(args_raw, f"{entry}.args", head_size, size, enums)
            clash = {a.name for a in args} & {f.name for f in cmd_header}
            if clash:
                raise self.fail(
                    entry,
                    f"argument name(s) {', '.join(sorted(clash))} clash with the command header",
                )
            cmd = Command(cmd_name, code, tuple(args), (*cmd_header, *args), size, doc, is_common)
            commands[cmd_name] = cmd
            by_code[code] = cmd
        return CommandChannel(
            f"{node}.command",
            f"{seed}_COMMAND",
            node,
            "command",
            address,
            size,
            tuple(cmd_header),
            commands,
            by_code,
        )
