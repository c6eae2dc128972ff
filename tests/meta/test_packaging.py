"""What the wheel ships and asks for: the version, the optional zmq backend, no generic packages."""

from __future__ import annotations

import importlib.util
import tomllib

import pytest

from tests.support.processes import REPO, run_tokenring
from tokenring.errors import UsageError
from tokenring.transport.factory import require_backend


def test_version_names_the_installed_distribution():
    import importlib.metadata

    import tokenring

    result = run_tokenring("--version")
    assert result.returncode == 0
    # one version: tokenring/__init__.py's, which pyproject.toml reads ([tool.hatch.version])
    config = tomllib.loads((REPO / "pyproject.toml").read_text())
    assert "version" in config["project"]["dynamic"] and "version" not in config["project"]
    assert config["tool"]["hatch"]["version"]["path"] == "tokenring/__init__.py"
    assert result.stdout.strip() == f"tokenring {tokenring.__version__}"
    assert importlib.metadata.version("tokenring") == tokenring.__version__


def test_a_missing_optional_backend_is_one_clear_line(monkeypatch):
    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "zmq" else real(name, *a)
    )
    with pytest.raises(
        UsageError,
        match=r"--transport zmq needs pyzmq, which is not installed: pip install 'tokenring\[zmq\]'",
    ):
        require_backend("zmq")
    require_backend("udp")  # the standard library's: nothing to install


def test_the_wheel_ships_the_ring_and_the_robot_only():
    config = tomllib.loads((REPO / "pyproject.toml").read_text())
    assert config["tool"]["hatch"]["build"]["targets"]["wheel"]["packages"] == ["tokenring", "modules"]
    assert "pyzmq" not in " ".join(config["project"]["dependencies"])
    assert config["project"]["optional-dependencies"]["zmq"] == ["pyzmq>=25"]


@pytest.mark.slow
def test_the_built_wheel_holds_what_the_nodes_import_and_registers_the_robot(tmp_path):
    import subprocess
    import sys
    import zipfile

    built = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path), str(REPO)],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert built.returncode == 0, built.stderr
    (wheel,) = tmp_path.glob("tokenring-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/", 1)[0] for n in names if not n.split("/", 1)[0].endswith(".dist-info")}
    assert tops == {"tokenring", "modules"}, tops
    assert "tokenring/_data/protocol.yaml" in names
    assert "modules/description/rooms/office.yaml" in names
    entry_points = next(n for n in names if n.endswith(".dist-info/entry_points.txt"))
    text = zipfile.ZipFile(wheel).read(entry_points).decode()
    assert "[tokenring.extensions]" in text and "robot = modules.plugin:RobotExtension" in text
