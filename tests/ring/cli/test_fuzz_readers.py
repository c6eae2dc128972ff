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
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from modules.description import load_world
from modules.localization.config import load_config
from modules.localization.logs import read_log
from modules.navigation.actions import load_actions
from tokenring.chaos.runner import load_scenario
from tokenring.contract.protocol import load_protocol
from tokenring.errors import TokenRingError

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
@example(data=b"._")  # once resolved as a float with no digit, and float(".") raised ValueError
def test_random_bytes_are_a_clean_error(name, data, tmp_path_factory):
    reader, suffix = READERS[name]
    path = tmp_path_factory.mktemp("fuzz") / f"input{suffix}"
    path.write_bytes(data)
    clean(reader, path)


@pytest.mark.slow
@pytest.mark.parametrize("name", [n for n in READERS if n != "log"])
@FUZZ
@given(tree=TREES)
@example(tree={"anomalies": True})  # a world's anomalies once iterated as given: TypeError
def test_extreme_but_valid_yaml_is_a_clean_error(name, tree, tmp_path_factory):
    reader, suffix = READERS[name]
    path = tmp_path_factory.mktemp("fuzz") / f"input{suffix}"
    path.write_text(yaml.safe_dump(tree, allow_unicode=True))
    clean(reader, path)


#: what a data log's records are made of, so that random records reach every reader's fields
LOG_KEYS = ["gen", "n", "v", "dl", "dr", "count", "heading", "heading_cdeg", "distances", "distances_mm",
            "walls", "x", "y", "psi", "theta", "valid", "steps_left", "steps_right", "period_ms",
            "counts", "event", "start", "seq", "alpha", "d"]  # fmt: skip
LOG_VALUES = st.recursive(
    SCALARS,
    lambda inner: st.one_of(
        st.lists(inner, max_size=4), st.dictionaries(st.sampled_from(LOG_KEYS), inner, max_size=6)
    ),
    max_leaves=16,
)
RECORDS = st.lists(
    st.tuples(
        st.integers(min_value=0, max_value=2**31),
        st.sampled_from(list("SOGWBLKC")),
        st.sampled_from(list("RCPSTWE")),
        st.dictionaries(st.sampled_from(LOG_KEYS), LOG_VALUES, max_size=6),
    ),
    min_size=1,
    max_size=12,
)


@pytest.mark.slow
@FUZZ
@given(records=RECORDS)
def test_records_of_the_right_shape_with_junk_inside_are_a_clean_error(records, tmp_path_factory):
    """Junk with a record's shape (a stamp, known letters, a payload of the wrong fields or
    types) is damage the reader reports; whatever it accepts, every converter takes."""
    import msgpack

    from modules.localization.logs import DataLog, convert_csv, convert_text, summary
    from modules.pc.analysis import Series, summarise

    path = tmp_path_factory.mktemp("fuzz") / "junk.trlog"
    with DataLog(path, "20260101-000000", {}) as log:
        log.close()
    with path.open("ab") as out:
        for stamp, source, kind, payload in records:
            out.write(msgpack.packb([stamp, source, kind, payload]))
    for salvage in (False, True):
        try:
            log = read_log(path, salvage=salvage)
        except TokenRingError as exc:
            assert "\n" not in str(exc).strip()
            continue
        convert_text(log)
        convert_csv(log)
        summary(log)
        summarise(Series(log))
