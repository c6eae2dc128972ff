"""YAML that does not survive a naive loader (issue 52): a "billion laughs" (aliases that expand
exponentially), the same through merge keys, a document that contains itself, and absurd
nesting. Every loader of the project refuses each in one line naming the file and line, within
a bounded memory (measured in process; the command line runs under an address-space limit),
and still reads aliases used as intended."""

from __future__ import annotations

import tracemalloc

import pytest

from modules.description import load_world
from modules.localization.config import load_config
from tests.support.refusal import MEMORY_LIMIT, refusal_line, run_refused
from tokenring._util.strict_yaml import MAX_DEPTH, read_yaml
from tokenring.chaos.runner import load_scenario
from tokenring.contract.protocol import load_protocol
from tokenring.errors import TokenRingError


def laughs(levels: int = 9, width: int = 9) -> str:
    """The classic: each level a list of ``width`` aliases of the one before (9**9 leaves)."""
    lines = ['a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for level in range(1, levels):
        lines.append(f"a{level}: &a{level} [" + ", ".join([f"*a{level - 1}"] * width) + "]")
    return "\n".join(lines) + "\n"


def merge_laughs(levels: int = 9) -> str:
    """The same through merge keys: every level merges nine copies of the mapping before it."""
    lines = ["m0: &m0 {k0: 1, k1: 2, k2: 3}"]
    for level in range(1, levels):
        lines.append(f"m{level}: &m{level} {{<<: [" + ", ".join([f"*m{level - 1}"] * 9) + "]}")
    return "\n".join(lines) + "\n"


HOSTILE = {
    "laughs": (laughs(), "alias bomb"),
    "merge-laughs": (merge_laughs(), "alias bomb"),
    "self-list": ("walls: &w\n  - [0, 0, 1000, 0]\n  - *w\n", "recursive"),
    "self-map": ("faults: &f\n  next: *f\n", "recursive"),
    "self-merge": ("ring: &r\n  <<: *r\n", "recursive"),
    "deep": ("walls: " + "[" * (MAX_DEPTH + 50) + "]" * (MAX_DEPTH + 50) + "\n", "deeper than"),
}

LOADERS = {
    "protocol": load_protocol,
    "world": load_world,
    "localizer": load_config,
    "scenario": load_scenario,
    "yaml": read_yaml,
}


@pytest.mark.parametrize("kind", HOSTILE)
@pytest.mark.parametrize("loader", LOADERS)
def test_every_loader_refuses_it_in_one_line_and_little_memory(loader, kind, tmp_path):
    text, says = HOSTILE[kind]
    path = tmp_path / f"{kind}.yaml"
    path.write_text(text)
    tracemalloc.start()
    try:
        with pytest.raises(TokenRingError) as caught:
            LOADERS[loader](path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    message = str(caught.value)
    assert "\n" not in message and says in message and str(path) in message, message
    assert peak < 32 * 1024 * 1024, f"{peak / 1e6:.0f} MB to refuse {len(text)} bytes"


#: (reader, arguments with {f} for the file) of every command-line option that reads YAML
CLI_READERS = [
    ("world", ["up", "--world", "{f}", "--duration", "1"]),
    ("world-drive", ["world", "drive", "--world", "{f}", "--seed", "1"]),
    ("localizer", ["up", "--localizer", "{f}", "--duration", "1"]),
    ("scenario", ["chaos", "{f}"]),
    ("protocol", ["up", "--protocol", "{f}", "--duration", "1"]),
    ("sniff-protocol", ["sniff", "--protocol", "{f}", "-n", "1"]),
]
CLI_CASES = [(name, template, kind) for name, template in CLI_READERS for kind in ("laughs", "self-list")]


@pytest.mark.parametrize(("reader", "template", "kind"), CLI_CASES, ids=[f"{r}-{k}" for r, _, k in CLI_CASES])
def test_the_command_line_refuses_it_within_a_memory_limit(reader, template, kind, tmp_path):
    text, says = HOSTILE[kind]
    path = tmp_path / f"{kind}.yaml"
    path.write_text(text)
    result = run_refused(*(a.format(f=path) for a in template), memory=MEMORY_LIMIT)
    refusal_line(result, str(path), says)


def test_aliases_used_as_intended_still_read(tmp_path):
    scenario = tmp_path / "anchors.yaml"
    scenario.write_text(
        "ring: {nodes: &nodes [main, sonar, motor]}\n"
        "settle: &settle 2.0\n"
        "faults:\n"
        "  - {at: 1.0, node: sonar, kind: delay, value: &ms 5}\n"
        "  - {at: *settle, node: motor, kind: delay, value: *ms}\n"
        "  - {at: 3.0, node: all, kind: clear}\n"
    )
    loaded = load_scenario(scenario)
    assert [(f.at, f.node, f.kind) for f in loaded.faults] == [
        (1.0, "sonar", "delay"),
        (2.0, "motor", "delay"),
        (3.0, "all", "clear"),
    ]
    assert loaded.faults[1].request["ms"] == 5.0
