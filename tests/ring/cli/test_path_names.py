"""Names that become paths (issue 52): ``node --name ../../../X`` created a folder and a file
outside the program store. A node's name is checked like a ring's — letters, digits, ``_ - .``,
starting with a letter or digit, at most 64 — before anything is created or started."""

from __future__ import annotations

import pytest

from tests.support.refusal import refusal_line, run_refused
from tokenring.contract import keys
from tokenring.errors import UsageError

HOSTILE_NAMES = ["../../../X", "a/b", "/etc", "..", ".hidden", "", "x" * 65, "name with space", "ä"]


@pytest.mark.parametrize("name", HOSTILE_NAMES)
def test_a_path_like_node_name_is_refused_before_anything_is_created(name, tmp_path):
    store = tmp_path / "a" / "store"
    before = sorted(tmp_path.rglob("*"))
    result = run_refused("node", "--id", "15", "--name", name, "--store", str(store), "--duration", "1")
    refusal_line(result, "--name", "node name", "letters, digits, _ - . only")
    assert sorted(tmp_path.rglob("*")) == before  # not even the store
    assert not (tmp_path / "X").exists()


@pytest.mark.parametrize("name", HOSTILE_NAMES)
def test_the_node_name_rule_is_the_ring_name_rule(name):
    with pytest.raises(UsageError, match="node name"):
        keys.check_node_name(name)
    with pytest.raises(UsageError, match="ring name"):
        keys.check_ring_name(name)


@pytest.mark.parametrize("name", ["sonar", "node90", "Extra-1", "lab.2", "a" * 64])
def test_plain_names_pass(name):
    assert keys.check_node_name(name) == name == keys.check_ring_name(name)
