"""Every numeric option and file value is range-checked before anything starts (issue 52): NaN,
the infinities, a negative and a huge number each give one line naming the option (or the file
and entry) and its range, exit code 2, no traceback. Options are checked as the command line
is parsed (in process: parsing runs nothing); values checked by a verb's own code are run as a
user would (a subprocess, no ring to find); the node's side of a fault request is checked on a
real node (``test_a_node_answers_a_bad_fault_request_and_lives``)."""

from __future__ import annotations

import argparse
import math
import signal
import time

import pytest

from modules.navigation.actions import parse_actions
from modules.world.__main__ import parse_speed
from tests.support.refusal import refusal_line, run_refused
from tokenring.chaos.runner import load_scenario
from tokenring.cli.commands import fault as fault_verb
from tokenring.cli.main import build_parser
from tokenring.contract.faults import MAX_DELAY_MS, MAX_LOSE, validate
from tokenring.contract.ring import parse_bitrate
from tokenring.errors import UsageError

#: NaN, infinity, a negative, a huge number: what every numeric input is tried with
BAD = ["nan", "inf", "-1", "1e300"]

WEEK = "604800"  # the longest number of seconds an option takes (tokenring.cli.args.MAX_SECONDS)

#: (command line with {v}, the option, its range as the message says it) of every numeric
#: option that the parser checks
OPTIONS = [
    ("fault sonar delay 5 --jitter {v}", "--jitter", f"0..{MAX_DELAY_MS} ms"),
    ("fault sonar lose --count {v}", "--count", f"1..{MAX_LOSE}"),
    ("fault sonar crash --timeout {v}", "--timeout", WEEK),
    ("chaos --random {v} --dry-run", "--random", "0..4294967295"),
    ("chaos --random 1 --duration {v}", "--duration", WEEK),
    ("chaos --random 1 --shrink-runs {v}", "--shrink-runs", "0..1000"),
    ("up --duration {v}", "--duration", WEEK),
    ("up --boot-wave {v}", "--boot-wave", "1..255"),
    ("up --share {v}", "--share", "1..255"),
    ("up --share 2 --lost-after {v}", "--lost-after", WEEK),
    ("up --web-port {v}", "--web-port", "1..65535"),
    ("up --foxglove-port {v}", "--foxglove-port", "1..65535"),
    ("up --metrics {v}", "--metrics", "1..65535"),
    ("watch --metrics {v}", "--metrics", "0..65535"),
    ("up --seed {v}", "--seed", "0..4294967295"),
    ("up --action-speed {v}", "--action-speed", "1..100"),
    ("node --id {v}", "--id", "1..255"),
    ("node --id 90 --capacity {v}", "--capacity", "1..16777216"),
    ("node --id 90 --expect {v}", "--expect", "1..255"),
    ("node --id 90 --duration {v}", "--duration", WEEK),
    ("bench --warmup {v}", "--warmup", "0..1000000000"),
    ("bench --repeat {v}", "--repeat", "1..1000"),
    ("bench --timeout {v}", "--timeout", WEEK),
    ("web --port {v}", "--port", "0..65535"),
    ("web --duration {v}", "--duration", WEEK),
    ("world drive --world office --seed {v}", "--seed", "0..4294967295"),
    ("world generate --seed {v}", "--seed", "0..4294967295"),
    ("world drive --world office --seed 1 --legs {v}", "--legs", "1..100"),
]
PARSED = [(line, option, span, value) for line, option, span in OPTIONS for value in BAD]


def parse(argv: list[str]) -> argparse.Namespace:
    parser, _ = build_parser(argv[0])
    return parser.parse_args(argv)


@pytest.mark.parametrize(
    ("line", "option", "span", "value"),
    PARSED,
    ids=[f"{o}={v}:{line.split()[0]}" for line, o, _, v in PARSED],
)
def test_a_numeric_option_out_of_range_is_one_line_naming_it_and_its_range(line, option, span, value, capsys):
    with pytest.raises(SystemExit) as stopped:
        parse(line.format(v=value).split())
    message = capsys.readouterr().err.strip()
    assert stopped.value.code == 2, message
    assert len(message.splitlines()) == 1 and option in message and span in message, message


#: the numeric options of these verbs must each be in OPTIONS or checked by the verb's own
#: code (RUN_CHECKED): a new option without a range fails here
VERBS = [
    ("fault",),
    ("chaos",),
    ("up",),
    ("node",),
    ("bench",),
    ("web",),
    ("world", "generate"),
    ("world", "drive"),
]
#: numeric options whose range the verb's code checks (test_run_level_values_*), or which are
#: given as text the verb parses (a bitrate, a speed-up)
RUN_CHECKED = {"--nodes", "--rounds", "--interleave", "--window", "--bitrate", "--speed", "--size"}


def probe(kind: object) -> object:
    """What an option's type makes of a small number (None if it refuses one: not numeric)."""
    try:
        return kind("5")  # type: ignore[operator]
    except (argparse.ArgumentTypeError, ValueError, TypeError):
        return None


@pytest.mark.parametrize("words", VERBS, ids=[" ".join(w) for w in VERBS])
def test_every_numeric_option_has_a_checked_range(words):
    parser, _ = build_parser(words[0])
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    sub._build(words[0])  # an application's verb is built when the command line picks it
    verb = sub.choices[words[0]]
    for word in words[1:]:
        inner = next(a for a in verb._actions if isinstance(a, argparse._SubParsersAction))
        verb = inner.choices[word]
    tested = {option for line, option, _ in OPTIONS if line.split()[: len(words)] == list(words)}
    for action in verb._actions:
        option = max(action.option_strings, key=len, default="")
        if action.type in (int, float) and not action.choices:  # (choices are a range of their own)
            pytest.fail(f"{' '.join(words)} {option}: type={action.type.__name__} checks no range")
        numeric = (
            action.type is not None and not action.choices and isinstance(probe(action.type), int | float)
        )
        if numeric and option and option not in RUN_CHECKED:
            assert option in tested, f"{' '.join(words)} {option} is not in this test's OPTIONS"


#: (command line, what the one line says) of values a verb's own code checks, run as a user would
RUN_LEVEL = [
    (["fault", "sonar", "delay", "nan"], ["delay", f"0..{MAX_DELAY_MS} ms"]),
    (["fault", "sonar", "delay", "1e12"], ["delay", f"0..{MAX_DELAY_MS} ms"]),
    (["fault", "sonar", "drop", "inf"], ["probability", "0..1"]),
    (["up", "--speed", "1e-9", "--duration", "1"], ["--speed", "0.01..1000"]),
    (["up", "--speed", "nan", "--duration", "1"], ["--speed", "0.01..1000"]),
    (["up", "--bitrate", "1e300", "--duration", "1"], ["bitrate", "10k..100G"]),
    (["up", "--bitrate", "500k", "--speed", "0.01", "--duration", "1"], ["--speed", "10k..100G"]),
    (["up", "--nodes", ",,,", "--duration", "1"], ["--nodes", "names no node"]),
    (["up", "--store", "/proc", "--duration", "1"], ["--store /proc", "cannot write"]),
    (["node", "--id", "90", "--bitrate", "-1", "--duration", "1"], ["bitrate", "10k..100G"]),
    (["bench", "--nodes", "-1"], ["--nodes", "2..255"]),
    (["bench", "--nodes", "nan"], ["--nodes", "2..255"]),
    (["bench", "--rounds", "1e300"], ["--rounds", "10..16000"]),
    (["bench", "--interleave", "-1"], ["--interleave", "2..10000"]),
]


@pytest.mark.parametrize(("argv", "says"), RUN_LEVEL, ids=[" ".join(a) for a, _ in RUN_LEVEL])
def test_run_level_values_are_refused_before_anything_starts(argv, says):
    refusal_line(run_refused(*argv), *says)


@pytest.mark.parametrize("value", [*BAD, "1e12", "-0.5", "abc", "60001"])
def test_a_delay_is_a_finite_number_of_ms_within_its_range(value):
    args = argparse.Namespace(kind="delay", value=value, jitter=0.0, count=1, soft=False)
    with pytest.raises(UsageError, match=rf"delay .*0\.\.{MAX_DELAY_MS} ms"):
        fault_verb.build_request(args, lambda item: 20)


#: requests as a node may receive them over its control key (from any tool, or a hostile one)
BAD_REQUESTS = [
    {"kind": "delay", "ms": math.nan},
    {"kind": "delay", "ms": math.inf},
    {"kind": "delay", "ms": -1},
    {"kind": "delay", "ms": 1e12},
    {"kind": "delay", "ms": 5, "jitter_ms": 1e300},
    {"kind": "delay", "ms": 5, "jitter_ms": math.nan},
    {"kind": "delay", "ms": 5, "jitter_ms": -1},
    {"kind": "delay", "ms": 10**400},
    {"kind": "delay", "ms": True},
    {"kind": "delay", "ms": [5]},
    {"kind": "drop", "p": math.nan},
    {"kind": "corrupt", "p": 1e300},
    {"kind": "duplicate", "p": -1},
    {"kind": "lose", "count": 0},
    {"kind": "lose", "count": 10**30},
    {"kind": "lose", "count": 2.5},
    {"kind": "lose", "count": True},
    {"kind": "partition", "groups": [[10], ["x"]]},
    {"kind": "partition", "groups": [[10], [256]]},
    {"kind": "partition", "groups": [[10], [math.nan]]},
    {"kind": "partition", "groups": [[10]]},
    ["delay", 5],
]


@pytest.mark.parametrize("request_", BAD_REQUESTS, ids=[repr(r)[:60] for r in BAD_REQUESTS])
def test_the_shared_check_refuses_a_bad_request_in_one_line(request_):
    with pytest.raises(UsageError) as refused:
        validate(request_)
    assert "\n" not in str(refused.value)


SCENARIO_ENTRIES = [
    ("at: {v}", "faults.0.at", "0..86400"),
    ("at: 1, value: {v}", "faults.0", f"0..{MAX_DELAY_MS} ms"),
    ("at: 1, value: 5, jitter: {v}", "faults.0", f"0..{MAX_DELAY_MS} ms"),
]
YAML_VALUES = {"nan": ".nan", "inf": ".inf", "-1": "-1", "1e300": "1e300", "1e12": "1e12"}
SCENARIOS = [(entry, where, span, v) for entry, where, span in SCENARIO_ENTRIES for v in YAML_VALUES]


@pytest.mark.parametrize(("entry", "where", "span", "value"), SCENARIOS)
def test_a_scenario_value_out_of_range_names_its_entry_and_range(entry, where, span, value, tmp_path):
    body = entry.format(v=YAML_VALUES[value])
    if "value:" not in body:
        body += ", value: 5"
    path = tmp_path / "s.yaml"
    path.write_text(f"faults:\n  - {{{body}, node: sonar, kind: delay}}\n")
    with pytest.raises(UsageError) as refused:
        load_scenario(path)
    message = str(refused.value)
    assert f"{path}:2: {where}" in message and span in message, message


def test_a_scenario_at_1e12_is_refused_by_the_command_line(tmp_path):
    path = tmp_path / "late.yaml"
    path.write_text("faults:\n  - {at: 1e12, node: sonar, kind: crash}\n")
    refusal_line(run_refused("chaos", str(path)), f"{path}:2", "faults.0.at", "0..86400")


@pytest.mark.parametrize("value", ["1e300", "0", "0.4", "-5", "3600001"])
def test_an_action_time_is_within_its_range(value):
    with pytest.raises(UsageError, match=r"a\.act:1: .*1\.\.3600000 ms"):
        parse_actions(f"v 50 50 {value}\n", "a.act")


@pytest.mark.parametrize("value", [*BAD, "0", "1e-9", "1001"])
def test_a_speed_up_is_within_its_range(value):
    with pytest.raises(UsageError, match=r"--speed .*0\.01\.\.1000"):
        parse_speed(value)


@pytest.mark.parametrize("value", ["nan", "-1", "1e300", "-inf", "0", "9k", "1e12", 10**400, -(10**400)])
def test_a_bitrate_is_within_its_range(value):
    """('inf', like 'max', is an unpaced wire by design.)"""
    with pytest.raises(UsageError, match=r"10k\.\.100G"):
        parse_bitrate(value)


@pytest.mark.slow
def test_a_node_answers_a_bad_fault_request_and_lives(procs, ring_name, endpoint):
    """A tool that skips the checks (or a hostile one) sends the node NaN, infinities, huge and
    negative values: each is answered with an error, the node's faults stay as they were, and
    its token goes on (it once died of a jitter of 1e300 in its token thread)."""
    import msgpack

    from tests.support.processes import TOKENRING, wait_gone
    from tokenring.contract import keys
    from tokenring.contract.protocol import default_protocol
    from tokenring.transport.session import query
    from tokenring.transport.zenoh_config import make_config, open_session

    launcher = procs.start(
        [*TOKENRING, "up", "--ring", ring_name, "--nodes", "main,sonar", "--no-programs", "--no-world",
         "-l", endpoint, "--bitrate", "max"]
    )  # fmt: skip
    sonar = default_protocol().nodes["sonar"].id
    with open_session(make_config(connect=[endpoint])) as session:

        def stats() -> dict | None:
            answers = query(session, keys.control(ring_name, sonar, "stats"), timeout=1.0)
            return answers[0][1]["result"] if answers and answers[0][1].get("ok") else None

        deadline = time.monotonic() + 90.0  # hang guard: eight interpreters on a loaded machine
        while (first := stats()) is None and time.monotonic() < deadline:
            assert launcher.poll() is None, "the launcher ended"
            time.sleep(0.2)
        assert first is not None, "the sonar node never answered"
        for request in BAD_REQUESTS[:-1]:
            try:
                msgpack.packb(request)
            except OverflowError:
                continue  # an integer no wire format carries: it can never reach a node
            answers = query(session, keys.control(ring_name, sonar, "fault"), request, timeout=5.0)
            assert answers, f"no answer to {request}"
            assert not answers[0][1].get("ok") and answers[0][1].get("error"), (request, answers[0][1])
        listing = query(session, keys.control(ring_name, sonar, "fault"), {"kind": "list"}, timeout=5.0)
        assert listing[0][1]["result"]["faults"] == {}
        visits = first["stats"]["visits"]
        while (now := stats()) is not None and now["stats"]["visits"] <= visits + 10:
            assert time.monotonic() < deadline, "the token stopped visiting the sonar"
            time.sleep(0.1)
        assert now is not None and now["pid"] == first["pid"], "the sonar node died"
    procs.watch([first["pid"]])
    launcher.send_signal(signal.SIGTERM)
    launcher.communicate(timeout=60)
    assert wait_gone([first["pid"]], 30) == []
