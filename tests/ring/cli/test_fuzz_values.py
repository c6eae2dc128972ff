"""Fuzzing the inputs of issue 52 (hypothesis, quick tier): numbers of every kind through each
numeric check (the command line's types, a fault request as a node receives it), YAML whose
aliases nest, repeat and refer to themselves through every loader, and text with a byte-order
mark and mixed line ends. Each must give a clean one-line error or a value within its range —
never another exception, never unbounded memory."""

from __future__ import annotations

import argparse
import math
import os
import tracemalloc

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from modules.description import load_world
from modules.localization.config import load_config
from modules.navigation.actions import parse_actions
from modules.world.__main__ import MAX_SPEED, MIN_SPEED, parse_speed
from tests.support.processes import REPO
from tokenring._util.strict_yaml import read_yaml
from tokenring.chaos.runner import load_scenario
from tokenring.cli.args import MAX_SECONDS, int_within, node_id, number_within, seconds
from tokenring.contract.faults import KINDS, MAX_DELAY_MS, MAX_LOSE, validate
from tokenring.contract.protocol import load_protocol
from tokenring.contract.ring import MAX_BITRATE, MIN_BITRATE, parse_bitrate
from tokenring.errors import TokenRingError, UsageError

FUZZ = settings(
    max_examples=int(os.environ.get("TOKENRING_FUZZ_EXAMPLES", "60")),
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)

#: numbers as a user types them: NaN and infinities in their spellings, signs, exponents, junk
NUMBER_TEXT = st.one_of(
    st.sampled_from(["nan", "NaN", "-nan", "inf", "-inf", "Infinity", "1e300", "-1e300", "1e-300", "0", "-0",
                     "-1", "1e12", "0x10", "1_000", " 5 ", "", "5k", "2.5M", "max", "1e400", "9" * 400]),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(min_value=-(10**30), max_value=10**30).map(str),
    st.text(max_size=8),
)  # fmt: skip
#: values as they arrive in a request or a YAML file: any type
ANY_VALUE = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(2**64), max_value=2**64),
    NUMBER_TEXT,
    st.booleans(),
    st.none(),
    st.lists(st.integers(min_value=-5, max_value=300), max_size=3),
)


def one_line(exc: BaseException) -> None:
    assert str(exc).strip() and "\n" not in str(exc).strip(), repr(exc)


@FUZZ
@given(text=NUMBER_TEXT)
@example(text="nan")
@example(text="1e400")
def test_the_numeric_option_types_give_a_value_in_range_or_one_line(text):
    types = [
        (number_within(0, MAX_DELAY_MS, "ms"), 0, MAX_DELAY_MS),
        (int_within(1, 255), 1, 255),
        (seconds, 0, MAX_SECONDS),
        (node_id, 1, 255),
    ]
    for kind, low, high in types:
        try:
            value = kind(text)
        except argparse.ArgumentTypeError as exc:
            one_line(exc)
            continue
        assert math.isfinite(value) and low <= value <= high, (kind, text, value)


@FUZZ
@given(text=NUMBER_TEXT)
def test_a_bitrate_and_a_speed_up_are_in_range_or_one_line(text):
    try:
        bitrate = parse_bitrate(text)
        assert bitrate is None or MIN_BITRATE <= bitrate <= MAX_BITRATE, (text, bitrate)
    except UsageError as exc:
        one_line(exc)
    try:
        speed = parse_speed(text)
        assert MIN_SPEED <= speed <= MAX_SPEED, (text, speed)
    except UsageError as exc:
        one_line(exc)


REQUEST_KEYS = ["ms", "value", "jitter_ms", "p", "count", "groups", "soft"]


@FUZZ
@given(
    kind=st.sampled_from([*KINDS, "explode", None]),
    fields=st.dictionaries(st.sampled_from(REQUEST_KEYS), ANY_VALUE, max_size=4),
    groups=st.none() | st.lists(st.lists(ANY_VALUE, max_size=3), max_size=3),
)
@example(kind="delay", fields={"ms": 5, "jitter_ms": 1e300}, groups=None)
@example(kind="lose", fields={"count": 2**64}, groups=None)
def test_a_fault_request_is_refused_in_one_line_or_within_every_range(kind, fields, groups):
    """What a node may be sent over its control key: whatever the shared check lets through,
    the token path can apply without raising."""
    request = {"kind": kind, **fields}
    if groups is not None:
        request["groups"] = groups
    try:
        spec = validate(request)
    except UsageError as exc:
        one_line(exc)
        return
    for key in ("ms", "jitter_ms"):
        if key in spec:
            assert math.isfinite(spec[key]) and 0 <= spec[key] <= MAX_DELAY_MS, spec
    if "p" in spec:
        assert math.isfinite(spec["p"]) and 0 <= spec["p"] <= 1, spec
    if "count" in spec:
        assert type(spec["count"]) is int and 1 <= spec["count"] <= MAX_LOSE, spec
    for group in spec.get("groups", []):
        assert group and all(type(i) is int and 1 <= i <= 255 for i in group), spec


@FUZZ
@given(value=NUMBER_TEXT, kind=st.sampled_from(["s", "r", "v 50 50", "c 500 50"]))
def test_an_action_value_is_in_range_or_one_line(value, kind):
    try:
        actions = parse_actions(f"{kind} {value}\n", "a.act")
    except UsageError as exc:
        one_line(exc)
        return
    assert all(math.isfinite(a) and abs(a) <= 3_600_000 for action in actions for a in action.args)


LOADERS = {
    "protocol": load_protocol,
    "world": load_world,
    "localizer": load_config,
    "scenario": load_scenario,
    "yaml": read_yaml,
}
#: keys the loaders know, so that an aliased document reaches past their first checks
DOC_KEYS = ["walls", "faults", "ring", "nodes", "sensors", "filter", "start", "circles", "token", "settle"]
LEAVES = st.sampled_from(
    ["1", "lol", ".nan", "1e300", "-1", "[0, 0, 1000, 0]", "{at: 1, node: sonar, kind: crash}"]
)


@st.composite
def aliased_documents(draw: st.DrawFn) -> str:
    """Entries that each name the ones before (or themselves) by alias, a few times over: from
    plain reuse to recursion and exponential expansion."""
    lines = []
    for index in range(draw(st.integers(min_value=1, max_value=9))):
        refer = st.integers(min_value=0, max_value=index).map(lambda j: f"*a{j}")
        items = draw(st.lists(st.one_of(LEAVES, refer) if index else LEAVES, min_size=1, max_size=12))
        key = draw(st.sampled_from(DOC_KEYS)) + (str(index) if draw(st.booleans()) else "")
        if draw(st.booleans()):
            body = "[" + ", ".join(items) + "]"
        else:
            body = "{" + ", ".join(f"k{n}: {item}" for n, item in enumerate(items)) + "}"
        lines.append(f"{key}: &a{index} {body}")
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("loader", LOADERS)
@FUZZ
@given(text=aliased_documents())
@example(text="walls: &a0 [*a0]\n")
def test_aliases_of_any_shape_load_or_are_refused_in_bounded_memory(loader, text, tmp_path_factory):
    path = tmp_path_factory.mktemp("aliases") / "input.yaml"
    path.write_text(text)
    tracemalloc.start()
    try:
        LOADERS[loader](path)
    except TokenRingError as exc:
        one_line(exc)
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    assert peak < 64 * 1024 * 1024, f"{peak / 1e6:.0f} MB for {len(text)} bytes"


WINDOWS_READERS = {
    "protocol": (REPO / "protocol.yaml", lambda p: sorted(load_protocol(p).nodes)),
    "scenario": (REPO / "scenarios/every-fault.yaml", lambda p: [f.request for f in load_scenario(p).faults]),
    "localizer": (REPO / "config/localization.yaml", load_config),
    "world": (REPO / "modules/description/rooms/office.yaml", lambda p: load_world(p).walls),
}


#: a whole repository file per example (a protocol's YAML takes a fifth of a second): fewer
FEW = settings(FUZZ, max_examples=max(1, FUZZ.max_examples // 8))


@pytest.mark.parametrize("name", WINDOWS_READERS)
@FEW
@given(ends=st.lists(st.sampled_from(["\n", "\r\n"]), min_size=1, max_size=8), mark=st.booleans())
def test_mixed_line_ends_and_a_mark_read_as_the_plain_file(name, ends, mark, tmp_path_factory):
    source, read = WINDOWS_READERS[name]
    lines = source.read_text().splitlines()
    text = "".join(line + ends[n % len(ends)] for n, line in enumerate(lines))
    folder = tmp_path_factory.mktemp("windows")
    path = folder / source.name
    path.write_bytes((b"\xef\xbb\xbf" if mark else b"") + text.encode())
    if name == "localizer":
        (folder / "logs").mkdir(exist_ok=True)  # its data logs go beside it
        plain = folder / "plain.yaml"
        plain.write_text(source.read_text())
        assert read(path) == read(plain)
    else:
        assert read(path) == read(source)


ACTION_LINES = st.sampled_from(["e", "s 100", "s -250", "r 90", "r -45.5", "v 50 40 1000", "c 500 60 2000",
                                "# a comment", "", "  s 10   # inline"])  # fmt: skip


@FUZZ
@given(lines=st.lists(ACTION_LINES, min_size=1, max_size=10), ends=st.sampled_from(["\n", "\r\n", "\r"]))
def test_an_action_file_from_any_editor_parses_as_written(lines, ends, tmp_path_factory):
    from modules.navigation.actions import load_actions

    path = tmp_path_factory.mktemp("act") / "drive.act"
    plain = "\n".join(lines) + "\n"
    path.write_bytes(b"\xef\xbb\xbf" + plain.replace("\n", ends).encode())
    try:
        expected = parse_actions(plain, str(path))
    except UsageError:  # only blank lines and comments: refused alike
        with pytest.raises(UsageError):
            load_actions(path)
        return
    assert load_actions(path) == expected
