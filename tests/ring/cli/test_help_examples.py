"""Every verb's and sub-verb's ``--help`` ends with examples a user can copy: an ``examples:``
section with at least one ``tokenring <verb> [<sub-verb>] ...`` line. The verbs are read from
``tokenring --help`` as a user sees them (the ring's and the installed robot's), not from the
CLI's code; each help runs in its own process, as a user would type it."""

from __future__ import annotations

import re
import subprocess
from concurrent.futures import ThreadPoolExecutor

import pytest

from tests.support.processes import TOKENRING

#: a listed verb or sub-verb: its name indented by four spaces under the metavar's line
LISTED = re.compile(r"^    ([a-z][a-z0-9-]*)(?:\s|$)")


def helps(*commands: tuple[str, ...]) -> dict[tuple[str, ...], subprocess.CompletedProcess]:
    """``tokenring WORDS --help`` of each command, two at a time (the machine's cores)."""

    def one(words: tuple[str, ...]) -> subprocess.CompletedProcess:
        return subprocess.run([*TOKENRING, *words, "--help"], capture_output=True, text=True, timeout=60)

    with ThreadPoolExecutor(max_workers=2) as pool:
        return dict(zip(commands, pool.map(one, commands), strict=True))


def listed(text: str, metavar: str) -> list[str]:
    """The names a help lists under its ``metavar`` line (``COMMAND``, ``VERB``)."""
    lines = text.splitlines()
    try:
        start = lines.index(f"  {metavar}")
    except ValueError:
        return []
    names = []
    for line in lines[start + 1 :]:
        if not line.strip() or not line.startswith("    "):
            break
        match = LISTED.match(line)
        if match:
            names.append(match.group(1))
    return names


def examples(text: str) -> list[str]:
    """The command lines of a help's ``examples:`` section (comments and blank lines left out)."""
    lines = text.splitlines()
    if "examples:" not in lines:
        return []
    found = []
    for line in lines[lines.index("examples:") + 1 :]:
        if line and not line.startswith(" "):
            break
        if line.strip() and not line.strip().startswith("#"):
            found.append(line.strip())
    return found


@pytest.mark.slow
def test_every_verb_and_sub_verb_help_has_examples_of_itself():
    top = helps(())[()]
    assert top.returncode == 0, top.stderr
    verbs = listed(top.stdout, "COMMAND")
    assert {"up", "status", "fault", "drive", "log", "world", "web"} <= set(verbs), verbs
    verb_helps = helps(*((v,) for v in verbs))
    subs = []
    for (verb,), result in verb_helps.items():
        assert result.returncode == 0, (verb, result.stderr)
        if f"tokenring {verb} [-h] VERB ..." in result.stdout:
            names = listed(result.stdout, "VERB")
            assert names, f"{verb} takes a VERB but lists none"
            subs += [(verb, name) for name in names]
    assert ("log", "info") in subs and ("world", "generate") in subs, subs
    missing = []
    for words, result in {**verb_helps, **helps(*subs)}.items():
        assert result.returncode == 0, (words, result.stderr)
        own = "tokenring " + " ".join(words)
        if not any(line == own or line.startswith(own + " ") for line in examples(result.stdout)):
            missing.append(" ".join(words))
    assert missing == [], f"no 'examples:' line starting with 'tokenring <verb>' in the help of: {missing}"


def test_web_takes_a_duration_with_its_range():
    bad = subprocess.run([*TOKENRING, "web", "--duration", "-5"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "--duration" in bad.stderr and "Traceback" not in bad.stderr
    assert len(bad.stderr.strip().splitlines()) == 1 and "above 0" in bad.stderr


def test_world_generate_size_states_its_range():
    result = helps(("world", "generate"))[("world", "generate")]
    assert "2000..20000" in " ".join(result.stdout.split())
    for size in ("100x100", "abc", "6200x4600x", "99999x3000"):
        bad = subprocess.run(
            [*TOKENRING, "world", "generate", "--seed", "1", "--size", size],
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert bad.returncode == 2 and "Traceback" not in bad.stderr, (size, bad.stderr)
        assert len(bad.stderr.strip().splitlines()) == 1 and "2000..20000" in bad.stderr, (size, bad.stderr)
