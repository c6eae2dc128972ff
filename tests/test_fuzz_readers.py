"""Fuzzing every reader of an operator's file (hypothesis): random bytes, and YAML that is valid
but extreme (huge, tiny, NaN, negative, deep, of the wrong type), must give a clean error
(:class:`~tokenring.errors.TokenRingError`, exit code 2 on the command line) or a result —
never another exception, never a hang."""

from __future__ import annotations

import math
import os
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from modules.common.actions import load_actions
from modules.common.locconfig import load_config
from modules.common.logs import read_log
from modules.description import load_world
from tokenring.chaos import load_scenario
from tokenring.errors import TokenRingError
from tokenring.protocol import load_protocol

FUZZ = settings(
    max_examples=int(os.environ.get("TOKENRING_FUZZ_EXAMPLES", "60")),
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)

EXTREME_NUMBERS = st.sampled_from(
    [
        0,
        -1,
        1,
        -(10**12),
        10**12,
        2**63,
        1e300,
        -1e300,
        1e-300,
        math.inf,
        -math.inf,
        math.nan,
        0.5,
        255,
        256,
        65536,
    ]
)
SCALARS = st.one_of(EXTREME_NUMBERS, st.text(max_size=12), st.booleans(), st.none())
#: the keys tokenring's files use, so that random trees reach past the first checks
KEYS = [
    "walls",
    "start",
    "x",
    "y",
    "angle_deg",
    "polygon",
    "faults",
    "at",
    "kind",
    "node",
    "value",
    "ring",
    "nodes",
    "sensors",
    "filter",
    "logs",
    "token",
    "size",
    "header",
    "version",
    "from",
    "to",
    "circles",
    "r",
    "floors",
    "anomalies",
    "settle",
    "duration",
    "use",
    "command",
    "data",
    "address",
]
#: YAML trees in the shape of tokenring's files (mappings of lists of mappings), with extreme leaves
TREES = st.recursive(
    SCALARS,
    lambda children: st.one_of(
        st.lists(children, max_size=5), st.dictionaries(st.sampled_from(KEYS), children, max_size=5)
    ),
    max_leaves=25,
)

READERS = {
    "protocol": (load_protocol, ".yaml"),
    "world": (load_world, ".yaml"),
    "config": (load_config, ".yaml"),
    "scenario": (load_scenario, ".yaml"),
    "actions": (load_actions, ".act"),
    "log": (read_log, ".trlog"),
}


def clean(reader, path: Path) -> None:
    try:
        reader(path)
    except TokenRingError as exc:
        assert str(exc).strip(), "an error must say what is wrong"
        assert "\n" not in str(exc).strip(), f"one line, not: {exc}"


@pytest.mark.parametrize("name", READERS)
@FUZZ
@given(data=st.binary(max_size=600))
def test_random_bytes_are_a_clean_error(name, data, tmp_path_factory):
    reader, suffix = READERS[name]
    path = tmp_path_factory.mktemp("fuzz") / f"input{suffix}"
    path.write_bytes(data)
    clean(reader, path)


@pytest.mark.parametrize("name", [n for n in READERS if n != "log"])
@FUZZ
@given(tree=TREES)
def test_extreme_but_valid_yaml_is_a_clean_error(name, tree, tmp_path_factory):
    reader, suffix = READERS[name]
    path = tmp_path_factory.mktemp("fuzz") / f"input{suffix}"
    path.write_text(yaml.safe_dump(tree, allow_unicode=True))
    clean(reader, path)
