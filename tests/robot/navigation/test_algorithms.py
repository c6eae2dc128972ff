"""``--algorithms seed|ours|MODULE=...`` (modules/variants.py): the grammar, what a
program reads from its environment, and ``up``'s refusals and implied seed pace."""

from __future__ import annotations

import threading

import pytest

from modules.variants import (
    ENV,
    algorithm,
    all_seed,
    body_mounts,
    format_algorithms,
    parse_algorithms,
)
from tests.support.processes import run_tokenring
from tests.support.ringutil import tap, wait_until
from tokenring.errors import UsageError
from tokenring.host.pclink import PcLink


def test_the_grammar_sets_every_part_then_overrides_later_items():
    parts = ("sonar", "copro", "main", "motor", "body")
    assert parse_algorithms("ours") == dict.fromkeys(parts, "ours")
    assert parse_algorithms("seed") == dict.fromkeys(parts, "seed")
    assert parse_algorithms("sonar=seed") == {**dict.fromkeys(parts, "ours"), "sonar": "seed"}
    assert parse_algorithms("body=seed") == {**dict.fromkeys(parts, "ours"), "body": "seed"}
    mixed = parse_algorithms(" seed , copro = ours ")
    assert mixed == {**dict.fromkeys(parts, "seed"), "copro": "ours"}
    assert not all_seed(mixed) and all_seed(parse_algorithms("seed"))
    assert not all_seed(parse_algorithms("seed,body=ours"))
    assert parse_algorithms(format_algorithms(mixed)) == mixed


def test_a_program_finds_its_bodys_sonar_mounts_in_the_environment():
    """The body is hardware: the modules that place sonar readings take the mounts the world
    simulator was built with (``up`` passes it ``--body``, see test_the_seed_body_*)."""
    seed = body_mounts({ENV: "seed"})
    ours = body_mounts({})
    assert seed[7].x - seed[6].x == 100.0 and ours[7].x - ours[6].x == 160.0
    assert [m.angle for m in seed] == [m.angle for m in ours]


@pytest.mark.parametrize(
    ("text", "needle"),
    [("", "give seed"), ("sonar=", "not seed or ours"), ("lcd=seed", "no part 'lcd'"), ("seed,,", "empty item"),
     ("both", "'both' is not seed or ours")],
)  # fmt: skip
def test_bad_choices_are_named(text, needle):
    with pytest.raises(UsageError, match=needle):
        parse_algorithms(text)


def test_a_program_reads_its_choice_from_the_environment():
    assert algorithm("sonar", {}) == "ours"
    env = {ENV: "sonar=seed,copro=ours,main=ours,motor=seed"}
    assert [algorithm(m, env) for m in ("sonar", "copro", "motor")] == ["seed", "ours", "seed"]
    assert algorithm("sonar", {ENV: "garbage"}) == "ours"  # a program started by hand with a bad one


def test_up_refuses_a_bad_choice_before_anything_starts():
    out = run_tokenring("up", "--algorithms", "lcd=seed", "--duration", "5", timeout=60)
    assert out.returncode == 2 and "--algorithms 'lcd=seed'" in out.stderr, out.stderr
    assert "Traceback" not in out.stderr and len(out.stderr.strip().splitlines()) == 1
    assert "starting" not in out.stdout


@pytest.mark.slow
@pytest.mark.parametrize(
    ("extra", "profile"), [((), True), (("--bitrate", "10M"), False), (("--algorithms", "sonar=seed"), False)]
)
def test_the_seed_robot_runs_at_the_seeds_pace_unless_a_bitrate_is_given(extra, profile, ring_name):
    args = ["--algorithms", "seed", *extra] if "--algorithms" not in extra else list(extra)
    out = run_tokenring(
        "up", "--ring", ring_name, "--no-world", "--no-programs", "--nodes", "main", "--duration", "2", *args,
        timeout=120,
    )  # fmt: skip
    starting = next(line for line in out.stdout.splitlines() if "starting 1 nodes" in line)
    assert ("profile arcnet" in starting) == profile, starting


@pytest.mark.slow
def test_up_runs_the_seed_robot_exploring_and_draws_its_map(procs, ring_name, endpoint, tmp_path):
    """The issue's own command: ``up --algorithms seed --explore 2 --map-out m.png`` runs the seed's
    robot (its Explore 2 begins with the calibration turn) and leaves the map as a PNG."""
    png = tmp_path / "m.png"
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--algorithms", "seed", "--explore", "2",
        "--map-out", str(png), "--speed", "10", "--bitrate", "max", "--duration", "400",
    )  # fmt: skip  # --duration: a hang guard; exploring is stopped below, as its end would
    lines: list[str] = []

    def read() -> None:
        assert launcher.stdout is not None
        for line in launcher.stdout:
            lines.append(line)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    # once the calibration turn has begun, Stop ends Explore 2: the mission then fetches the map,
    # writes the PNG and stops the ring, as when --duration runs out
    wait_until(lambda: "calibrate 360" in "".join(lines), 240, "the calibration turn")
    with tap(endpoint) as session:
        PcLink(session, ring_name, timeout=10).request("stop")
    assert launcher.wait(120) == 0, "".join(lines)[-3000:]
    reader.join(10)
    text = "".join(lines)
    assert "navigator SeedCalibrated started" in text and "calibrate 360" in text, text[-3000:]
    assert "body seed" in text, text[-3000:]  # the world built the 2001 body (side pairs 10 cm apart)
    assert png.read_bytes().startswith(b"\x89PNG")
