"""``tokenring dissector``: a Wireshark Lua dissector for the token, generated from the
protocol.yaml that is loaded (the ring knows nothing of what its channels mean beyond it).

The script registers the protocol ``tokenring`` in Wireshark's ``arcnet.protocol_id`` dissector
table under :data:`tokenring.observe.pcapng.ARCNET_PROTOCOL_ID`: Wireshark's ARCNET dissector
(link type ``DLT_ARCNET_LINUX``, 129) reads the ARCNET header of a packet of a capture written by
``sniff --write FILE.pcapng`` or ``record --pcap`` and hands the frame after it over. It shows:

* ``tokenring.length``, ``tokenring.ok``, ``tokenring.crc_ok`` and, for a frame a receiver drops,
  ``tokenring.problem`` (``length``, ``crc``, ``marker``: the checks of
  :func:`tokenring.contract.frame.frame_problem`, in its order, the CRC-16/ARC computed anew);
* every header field as ``tokenring.<name>`` (``tokenring.sid``, ``tokenring.counter``, ...), the
  system command's name as ``tokenring.syscmd_code_name``, the CRC as ``tokenring.crc``;
* while a system command is in the token, its window: the request, or once a target has
  acknowledged it (``syscmd_ack`` set) the answer where the command has one, as
  ``tokenring.system.<COMMAND>.<request|answer>.<field>``;
* every channel in address order: a data channel's fields as ``tokenring.<node>.data.<field>``, an
  inbox's command header as ``tokenring.<node>.command.<field>`` (its ``code`` with the inbox's
  command names) and, when the inbox holds a command (its state not FREE) of a code it knows,
  the command's name as ``tokenring.<node>.command.command`` and its arguments as
  ``tokenring.<node>.command.<COMMAND>.<argument>``.

The header, the window and each channel are fields of their own (``tokenring.header``,
``tokenring.system``, ``tokenring.motor.data``) holding theirs, so a display filter can name them.

Values are what ``sniff --json`` prints, as Wireshark shows them: integers in decimal (an enum's
name beside its number), arrays as one field per element, floats to 6 (f32) or 15 (f64)
significant digits, text up to its first NUL (sniff keeps a NUL inside the text; a Wireshark
string ends there) with a byte that is not ASCII as U+FFFD. Multi-byte fields are little-endian;
an enum on a 64-bit field is shown as the number only (Wireshark's value strings are 32-bit).
Header fields are read by their declared type (sniff reads each header field's first byte;
protocol.yaml's seed header fields are all one byte).
"""

from __future__ import annotations

from collections.abc import Iterable

from tokenring.contract.protocol import CommandChannel, Field, Protocol, split_type
from tokenring.errors import UsageError
from tokenring.observe.pcapng import ARCNET_PROTOCOL_ID, protocol_sha256

#: the dissector's own fields beside protocol.yaml's header fields
OWN_FIELDS = ("length", "ok", "crc_ok", "problem", "crc", "syscmd_code_name", "header", "system")
_ENUM_TYPES = {"u8", "u16", "u32", "i8", "i16", "i32"}


def lua_string(text: str) -> str:
    """``text`` as a Lua string literal (UTF-8, anything but printable ASCII as ``\\ddd``)."""
    out = []
    for byte in text.encode("utf-8"):
        if byte in (0x5C, 0x22):  # backslash, quote
            out.append("\\" + chr(byte))
        elif 32 <= byte < 127:
            out.append(chr(byte))
        else:
            out.append(f"\\{byte:03d}")
    return '"' + "".join(out) + '"'


def crc16_arc_table() -> list[int]:
    """The 256 entries of CRC-16/ARC's (reflected 0x8005) byte table."""
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
        table.append(crc)
    return table


class _Generator:
    def __init__(self, protocol: Protocol) -> None:
        self.protocol = protocol
        self.abbrevs: dict[str, str] = {}  # abbreviation -> what it is (for clashes)

    def claim(self, abbrev: str, what: str) -> str:
        if abbrev in self.abbrevs:
            raise UsageError(
                f"{self.protocol.source}: {what} and {self.abbrevs[abbrev]} would both be the "
                f"Wireshark field {abbrev}: rename one"
            )
        self.abbrevs[abbrev] = what
        return abbrev

    def field(self, spec: Field, abbrev: str, what: str, enum: str | None = None) -> str:
        """One field's Lua table (its offset relative to the block it is in)."""
        base, count = split_type(spec.type_name)
        parts = [f"abbrev = {lua_string(self.claim(abbrev, what))}", f"name = {lua_string(spec.name)}"]
        if base == "str":
            parts += [f"offset = {spec.offset}", 'type = "str"', f"size = {spec.size}"]
        else:
            parts += [f"offset = {spec.offset}", f'type = "{base}"', f"size = {spec.size // (count or 1)}"]
            if count is not None:
                parts.append(f"count = {count}")
            if base in _ENUM_TYPES:
                if enum is not None:
                    parts.append(f"enum = {enum}")
                elif spec.enum:
                    parts.append(f"enum = ENUMS[{lua_string(spec.enum)}]")
        if spec.unit:
            parts.append(f"unit = {lua_string(spec.unit)}")
        if spec.doc:
            parts.append(f"doc = {lua_string(spec.doc)}")
        return "{ " + ", ".join(parts) + " }"

    def fields(self, specs: Iterable[Field], prefix: str, what: str, indent: str) -> str:
        rows = [f"{indent}  {self.field(f, f'{prefix}.{f.name}', f'{what} {f.name}')}," for f in specs]
        return "{\n" + "\n".join(rows) + f"\n{indent}}}"

    def generate(self) -> str:
        p = self.protocol
        for name in OWN_FIELDS:
            self.claim(f"tokenring.{name}", f"the dissector's own field {name!r}")
        out: list[str] = []
        enums = [
            f"  [{lua_string(name)}] = {{ "
            + ", ".join(f"[{value}] = {lua_string(key)}" for key, value in values.items())
            + " },"
            for name, values in p.enums.items()
        ]
        out.append("local ENUMS = {\n" + "\n".join(enums) + "\n}")
        names = ", ".join(f"[{code}] = {lua_string(name)}" for name, code in p.system_commands.items())
        header = self.fields(p.header.fields, "tokenring", "token.header field", "  ")
        consts = ", ".join(
            f"{{ offset = {p.header.offsets[name]}, value = {value} }}"
            for name, value in p.header.consts.items()
        )
        offsets = ", ".join(f"{name} = {offset}" for name, offset in p.header.offsets.items())
        windows = []
        for command, parts in p.system_window.items():
            code = p.system_commands[command]
            layouts = [
                f"{part} = "
                + self.fields(
                    specs,
                    f"tokenring.system.{command}.{part}",
                    f"system.window.{command}.{part} field",
                    "    ",
                )
                for part, specs in parts.items()
            ]
            windows.append(f"  [{code}] = {{\n    " + ",\n    ".join(layouts) + ",\n  },")
        channels = []
        for channel in sorted(p.channels.values(), key=lambda c: c.address):
            prefix = f"tokenring.{channel.name}"
            what = f"nodes.{channel.node}.{channel.kind}"
            rows = [
                f"name = {lua_string(channel.name)}",
                f"abbrev = {lua_string(self.claim(prefix, f'the channel {channel.name}'))}",
                f'kind = "{channel.kind}"',
                f"address = {channel.address}",
                f"size = {channel.size}",
            ]
            if isinstance(channel, CommandChannel):
                codes = (
                    "{ "
                    + ", ".join(f"[{c.code}] = {lua_string(c.name)}" for c in channel.by_code.values())
                    + " }"
                )
                head = []
                for spec in channel.fields:
                    enum = codes if spec.name == "code" and not spec.enum else None
                    head.append(
                        f"      {self.field(spec, f'{prefix}.{spec.name}', f'{what} header {spec.name}', enum)},"
                    )
                state_field = next(f for f in channel.fields if f.name == "state")
                code_field = next(f for f in channel.fields if f.name == "code")
                commands = []
                for cmd in channel.by_code.values():
                    args = self.fields(
                        cmd.args, f"{prefix}.{cmd.name}", f"{what} {cmd.name} argument", "        "
                    )
                    commands.append(
                        f"      [{cmd.code}] = {{ name = {lua_string(cmd.name)}, args = {args} }},"
                    )
                rows += [
                    "fields = {\n" + "\n".join(head) + "\n    }",
                    f"state = {{ offset = {state_field.offset}, size = {state_field.size} }}",
                    f"code = {{ offset = {code_field.offset}, size = {code_field.size} }}",
                    f"command = {{ abbrev = {lua_string(self.claim(f'{prefix}.command', f'{what} command name'))}, "
                    f'name = "command", type = "name" }}',
                    "commands = {\n" + "\n".join(commands) + "\n    }",
                ]
            else:
                rows.append("fields = " + self.fields(channel.fields, prefix, f"{what} field", "    "))
            channels.append("  {\n    " + ",\n    ".join(rows) + ",\n  },")
        table = crc16_arc_table()
        crc_rows = ["  " + ", ".join(f"0x{v:04X}" for v in table[i : i + 8]) + "," for i in range(0, 256, 8)]
        out.append(
            "local SPEC = {\n"
            f"  arcnet_protocol_id = 0x{ARCNET_PROTOCOL_ID:02X},\n"
            f"  token_size = {p.token_size},\n"
            f"  frame_size = {p.frame_size},\n"
            f"  header_size = {p.header_size},\n"
            f"  system_data = {p.system_data_offset},\n"
            f"  system_size = {p.system_data_size},\n"
            f"  offsets = {{ {offsets} }},\n"
            f"  consts = {{ {consts} }},\n"
            f"  system_names = {{ {names} }},\n"
            f"  header = {header},\n"
            "  windows = {\n" + "\n".join(windows) + "\n  },\n"
            "  channels = {\n" + "\n".join(channels) + "\n  },\n"
            "}"
        )
        out.append("local CRC_TABLE = { [0] =\n" + "\n".join(crc_rows) + "\n}")
        return "\n\n".join(out)


def lua_dissector(protocol: Protocol, *, source: str, protocol_text: str | None = None) -> str:
    """The Lua dissector for ``protocol`` (read from ``source``, whose text is ``protocol_text``)."""
    from tokenring.observe.recording import tokenring_version

    digest = (
        f"\n-- protocol.yaml sha256 {protocol_sha256(protocol_text)}" if protocol_text is not None else ""
    )
    head = f"""-- tokenring.lua: Wireshark's dissector for the tokenring token, generated by
-- `tokenring dissector` (tokenring {tokenring_version()}) from {source}{digest}
-- Regenerate it whenever protocol.yaml changes: offsets, types and names all come from there.
--
-- Captures: `tokenring sniff --write FILE.pcapng` or `tokenring record --pcap FILE.pcapng` write
-- every frame as an ARCNET packet (link type DLT_ARCNET_LINUX, 129) with protocol ID
-- 0x{ARCNET_PROTOCOL_ID:02X}; Wireshark's ARCNET dissector hands the frame to this one.
--
-- Use:      tshark -X lua_script:tokenring.lua -r FILE.pcapng -V
--           wireshark -X lua_script:tokenring.lua FILE.pcapng
-- Install:  copy it into Wireshark's personal Lua plugins folder (Linux and macOS:
--           ~/.local/lib/wireshark/plugins/; Windows: %APPDATA%\\Wireshark\\plugins\\;
--           `tshark -G folders` names it), and every capture opens decoded.
-- Filters:  tokenring.sid == 10, tokenring.syscmd_code_name == "ARCNET_SCAN",
--           tokenring.motor.command.command == "STOP", tokenring.ok == 0"""
    return head + "\n\n" + _Generator(protocol).generate() + "\n" + _ENGINE


_ENGINE = r"""
-- ------------------------------------------------------------------------------------------
-- the engine: the same for every protocol.yaml

local proto = Proto("tokenring", "tokenring token")

-- bit operations: Lua 5.2's bit32, LuaBitOp's bit, or the operators of Lua 5.3 and later
local bxor, band, rshift
if bit32 then
  bxor, band, rshift = bit32.bxor, bit32.band, bit32.rshift
elseif bit then
  bxor, band, rshift = bit.bxor, bit.band, bit.rshift
else
  bxor, band, rshift = load(
    "return function(a, b) return a ~ b end, function(a, b) return a & b end, function(a, n) return a >> n end"
  )()
end

local function crc16_arc(bytes)
  local crc = 0
  for i = 1, #bytes do
    crc = bxor(CRC_TABLE[band(bxor(crc, bytes:byte(i)), 0xFF)], rshift(crc, 8))
  end
  return crc
end

local INTEGER = {
  u8 = ProtoField.uint8, u16 = ProtoField.uint16, u32 = ProtoField.uint32, u64 = ProtoField.uint64,
  i8 = ProtoField.int8, i16 = ProtoField.int16, i32 = ProtoField.int32, i64 = ProtoField.int64,
}
local all_fields = {}

local function declare(spec)
  local label = spec.name
  if spec.unit then label = label .. " [" .. spec.unit .. "]" end
  local field
  if spec.type == "str" or spec.type == "name" then
    field = ProtoField.string(spec.abbrev, label, base.ASCII, spec.doc)
  elseif spec.type == "f32" then
    field = ProtoField.float(spec.abbrev, label, nil, spec.doc)
  elseif spec.type == "f64" then
    field = ProtoField.double(spec.abbrev, label, nil, spec.doc)
  else
    field = INTEGER[spec.type](spec.abbrev, label, spec.base or base.DEC, spec.enum, nil, spec.doc)
  end
  spec.field = field
  all_fields[#all_fields + 1] = field
end

local function declare_all(specs)
  for _, spec in ipairs(specs) do declare(spec) end
end

local F = {
  length = ProtoField.uint32("tokenring.length", "length", base.DEC, nil, nil, "bytes of the frame"),
  ok = ProtoField.bool("tokenring.ok", "ok", base.NONE, nil, nil, "a receiver takes this frame"),
  crc_ok = ProtoField.bool("tokenring.crc_ok", "CRC ok", base.NONE, nil, nil,
    "the frame's length and CRC-16/ARC hold"),
  problem = ProtoField.string("tokenring.problem", "problem", base.ASCII,
    "why a receiver drops the frame: length, crc or marker"),
  crc = ProtoField.uint16("tokenring.crc", "CRC", base.HEX, nil, nil, "CRC-16/ARC of the token, little-endian"),
  syscmd_code_name = ProtoField.string("tokenring.syscmd_code_name", "system command", base.ASCII,
    "the name of syscmd_code"),
  header = ProtoField.none("tokenring.header", "Header", "the token's header"),
  system = ProtoField.none("tokenring.system", "System data",
    "the system command's window (saved user data while a command is in the token)"),
}
for _, field in pairs(F) do all_fields[#all_fields + 1] = field end
declare_all(SPEC.header)
for _, window in pairs(SPEC.windows) do
  for _, part in pairs(window) do declare_all(part) end
end
for _, channel in ipairs(SPEC.channels) do
  channel.field = ProtoField.none(channel.abbrev, channel.name, "the channel " .. channel.name)
  all_fields[#all_fields + 1] = channel.field
  declare_all(channel.fields)
  if channel.kind == "command" then
    declare(channel.command)
    for _, command in pairs(channel.commands) do declare_all(command.args) end
  end
end
proto.fields = all_fields

local EXPERT = {
  length = ProtoExpert.new("tokenring.problem.length", "not a frame: the length is wrong",
    expert.group.MALFORMED, expert.severity.ERROR),
  crc = ProtoExpert.new("tokenring.problem.crc", "the CRC does not match the token",
    expert.group.CHECKSUM, expert.severity.ERROR),
  marker = ProtoExpert.new("tokenring.problem.marker", "a constant header byte is wrong",
    expert.group.PROTOCOL, expert.severity.WARN),
}
proto.experts = { EXPERT.length, EXPERT.crc, EXPERT.marker }

local function read_uint(tvb, at, size)
  if size == 8 then return tvb(at, 8):le_uint64():tonumber() end
  return tvb(at, size):le_uint()
end

-- one field's value(s) into tree; base: where the field's block starts in the frame
local function add_value(tree, tvb, spec, base)
  local at = base + spec.offset
  if spec.type == "str" then
    -- up to the first NUL (where Wireshark's strings end), a byte that is not ASCII as U+FFFD
    local text = tvb:raw(at, spec.size):match("^[^%z]*"):gsub("[\128-\255]", "\239\191\189")
    return tree:add(spec.field, tvb(at, spec.size), text)
  end
  if spec.count then
    for i = 0, spec.count - 1 do
      tree:add_le(spec.field, tvb(at + i * spec.size, spec.size)):append_text(" (index " .. i .. ")")
    end
    return
  end
  return tree:add_le(spec.field, tvb(at, spec.size))
end

local function span(at, size)
  return string.format("bytes %d..%d", at, at + size - 1)
end

function proto.dissector(tvb, pinfo, tree)
  local length = tvb:len()
  pinfo.cols.protocol = "tokenring"
  local root = tree:add(proto, tvb())
  root:add(F.length, tvb(), length):set_generated()
  local problem
  if length ~= SPEC.frame_size then
    problem = "length"
  elseif crc16_arc(tvb:raw(0, SPEC.token_size)) ~= tvb(SPEC.token_size, 2):le_uint() then
    problem = "crc"
  else
    for _, const in ipairs(SPEC.consts) do
      if tvb(const.offset, 1):uint() ~= const.value then
        problem = "marker"
        break
      end
    end
  end
  root:add(F.ok, tvb(), problem == nil):set_generated()
  root:add(F.crc_ok, tvb(), problem ~= "crc" and problem ~= "length"):set_generated()
  if problem then
    local item = root:add(F.problem, tvb(), problem)
    item:set_generated()
    item:add_proto_expert_info(EXPERT[problem])
  end
  if length ~= SPEC.frame_size then
    pinfo.cols.info = string.format("%d bytes, not a %d-byte frame", length, SPEC.frame_size)
    root:append_text(string.format(", %d bytes (not a frame)", length))
    return length
  end

  local o = SPEC.offsets
  local function byte(name) return tvb(o[name], 1):uint() end
  local header = root:add(F.header, tvb(0, SPEC.header_size))
  for _, spec in ipairs(SPEC.header) do add_value(header, tvb, spec, 0) end
  local code = byte("syscmd_code")
  local name = SPEC.system_names[code] or (code == 0 and "NONE") or tostring(code)
  header:add(F.syscmd_code_name, tvb(o.syscmd_code, 1), name)
  local crc = root:add_le(F.crc, tvb(SPEC.token_size, 2))
  if problem == "crc" then
    crc:append_text(string.format(" [computed 0x%04x]", crc16_arc(tvb:raw(0, SPEC.token_size))))
  end
  local summary = string.format("#%d %d->%d epoch %d/%d", byte("counter"), byte("sid"), byte("did"),
    byte("epoch"), byte("epoch_origin"))
  if problem then summary = summary .. " [" .. problem .. "]" end
  local issuer = byte("syscmd_issuer")
  if issuer ~= 0 then
    summary = summary .. string.format(" sys %s %d->%d ack=%d", name, issuer, byte("syscmd_target"),
      byte("syscmd_ack"))
  end
  local window = SPEC.windows[code]
  if code ~= 0 and window then
    local part = "request"
    if (byte("syscmd_ack") ~= 0 and window.answer) or not window.request then part = "answer" end
    local data = root:add(F.system, tvb(SPEC.system_data, SPEC.system_size))
    data:set_text(string.format("System data (%s): %s %s", span(SPEC.system_data, SPEC.system_size), name, part))
    for _, spec in ipairs(window[part]) do add_value(data, tvb, spec, SPEC.system_data) end
  end

  for _, channel in ipairs(SPEC.channels) do
    local item = root:add(channel.field, tvb(channel.address, channel.size))
    item:set_text(string.format("%s (%s)", channel.name, span(channel.address, channel.size)))
    if not tvb:raw(channel.address, channel.size):find("[^%z]") then item:append_text(": empty") end
    for _, spec in ipairs(channel.fields) do add_value(item, tvb, spec, channel.address) end
    if channel.kind == "command" then
      local state = read_uint(tvb, channel.address + channel.state.offset, channel.state.size)
      local at = channel.address + channel.code.offset
      local command = channel.commands[read_uint(tvb, at, channel.code.size)]
      if state ~= 0 and command then
        item:add(channel.command.field, tvb(at, channel.code.size), command.name)
        item:append_text(": " .. command.name)
        for _, spec in ipairs(command.args) do add_value(item, tvb, spec, channel.address) end
        summary = summary .. " " .. channel.name .. ":" .. command.name
      end
    end
  end
  root:append_text(", " .. summary)
  pinfo.cols.info = summary
  return length
end

DissectorTable.get("arcnet.protocol_id"):add(SPEC.arcnet_protocol_id, proto)
"""
