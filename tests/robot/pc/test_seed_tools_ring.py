"""``tokenring analyze --seed-out`` on a drive recorded from a live ring, then the real ``gnuplot``.

``test_seed_tools.py`` draws a log made in process (``tests.support.locsim`` feeding the
LocalizationCore); here the log is the one copro's Localizer writes on a real ring with the world
and the Darmstadt sensors (``up --sensors darmstadt``: gyroscope, floor correlator, LOPS), while
``tokenring drive`` moves the robot half a metre and turns it. The ring is stopped as a user
stops it (Ctrl-C), the analyser writes the seed's files, and ``gnuplot command`` runs in every
module's directory as the seed's user ran it (seed 000, §9.2, appendix B.4).

The judges are typed out here, never the analyser's code: the plots the ``command`` file names
(its ``set output`` lines) must be PNGs, every data file it plots must have one row per record
of its kind in the log (the log's msgpack records counted by their letters, docs/localization.md
and ``modules/localization/logs.py``'s table), and the filter's last position must be where the
world's ground truth (``world/truth``, read by hand) left the robot.
"""

from __future__ import annotations

import json
import math
import re
import shutil
import signal
import subprocess
from collections import Counter
from pathlib import Path
from typing import Any

import msgpack
import pytest
import yaml

from tests.support.processes import TOKENRING
from tests.support.ringutil import launcher_pids, tap, wait_ring, wait_until
from tests.support.worldtruth import Truth

PNG = b"\x89PNG\r\n\x1a\n"
#: the ring: the Darmstadt sensors need gyro and correlator beside the drive, sonar and copro
NODES = {"main": 10, "motor": 20, "sonar": 30, "compass": 40, "copro": 50, "gyro": 90, "correlator": 100}
#: the six modules of the seed's logfileanalyser (table B.9), all of which this drive has data for
MODULES = {"position", "odometrie", "gyroskop", "lops", "sonar", "time"}
#: each sensor's letter in the data log (config/localization.yaml, docs/darmstadt-sensors.md)
LETTERS = {
    "odometry": "O",
    "compass": "M",
    "gyro": "G",
    "correlator": "C",
    "sonar": "W",
    "battery": "B",
    "truth": "T",
    "lops": "L",
}
#: the position files' names: the seed's two, then the sensors' own names
POSITIONS = {"kalman": "K", "odometrie": "O", **LETTERS}
#: a sonar that heard no echo (cm), as the log's W R records carry it
NO_CONTACT_CM = 255
#: the world's start in the Darmstadt hall (modules/description/rooms/square.yaml)
START = (1000.0, 1000.0)


def gnuplot_binary() -> str:
    path = shutil.which("gnuplot")
    if path is None:
        pytest.fail(
            "gnuplot is not installed: install the Debian package gnuplot (apt-get install gnuplot, "
            "or gnuplot-nox); this test runs the real gnuplot on the analyser's output"
        )
    return path


def log_objects(path: Path) -> list[Any]:
    """The data log's msgpack stream, read here without the log module: its header map, then one
    array a record (a torn last object, as while copro writes it, ends the list)."""
    unpacker = msgpack.Unpacker(raw=False, strict_map_key=False)
    unpacker.feed(path.read_bytes())
    return list(unpacker)


def log_records(path: Path) -> list[list[Any]]:
    """The data log's records ``[stamp_ms, source, kind, payload]``, after its header."""
    objects = log_objects(path)
    assert objects and isinstance(objects[0], dict) and objects[0].get("tokenring_log") == "data", objects[:1]
    records = objects[1:]
    assert all(isinstance(r, list) and len(r) == 4 for r in records), [r for r in records if len(r) != 4][:3]
    return records


def expected_rows(records: list[list[Any]]) -> dict[str, dict[str, int]]:
    """How many rows each module's data file must have, counted from the log's records: per
    module, per file name."""
    kinds = Counter((source, kind) for _, source, kind, _ in records)
    placed = Counter(
        source
        for _, source, kind, p in records
        if kind == "P" and all(p.get("valid", [True, True])[:2]) and math.isfinite(p["x"])
    )
    raw = [p.get("v", {}) for _, source, kind, p in records if (source, kind) == ("L", "R")]
    sweeps = [
        p.get("v", {}).get("distances", []) for _, source, kind, p in records if (source, kind) == ("W", "R")
    ]
    sonars = max((len(d) for d in sweeps), default=0)
    return {
        "position": {name: placed[letter] for name, letter in POSITIONS.items()},
        "odometrie": {"links": kinds["O", "C"], "rechts": kinds["O", "C"]},
        "gyroskop": {"gyroskop": kinds["G", "R"]},
        "lops": {f"empfaenger{i + 1}": sum(v.get(f"d{i + 1}") is not None for v in raw) for i in range(3)},
        "sonar": {
            f"empfaenger{i}": sum(len(d) > i and d[i] != NO_CONTACT_CM for d in sweeps) for i in range(sonars)
        },
        # a cycle time per stamp but the first
        "time": {
            "synchronisation": kinds["S", "S"] - 1,
            **{name: kinds[letter, "R"] - 1 for name, letter in LETTERS.items()},
        },
    }


def quoted(text: str) -> str:
    return text[1:-1]


def command_file(folder: Path) -> tuple[list[str], list[str]]:
    """What a gnuplot control file writes (its ``set output`` files) and the data files its
    ``plot`` reads, parsed here (continuation lines joined as gnuplot joins them)."""
    text = (folder / "command").read_text().replace("\\\n", " ")
    outputs, data = [], []
    for line in text.splitlines():
        line = line.strip()
        if match := re.fullmatch(r"set\s+output\s+('[^']*'|\"[^\"]*\")", line):
            outputs.append(quoted(match.group(1)))
        elif line.startswith("plot "):
            data += [quoted(m) for m in re.findall(r"('[^']*'|\"[^\"]*\")\s+using\b", line)]
    return outputs, data


def drive(endpoint: str, ring: str, *args: str) -> dict:
    proc = subprocess.run(
        [*TOKENRING, "drive", *args, "--ring", ring, "--connect", endpoint, "--json", "--timeout", "60"],
        capture_output=True,
        text=True,
        timeout=120,  # a hang guard: the tool's own --timeout ends every wait
    )
    assert proc.returncode == 0, (args, proc.stdout, proc.stderr)
    return json.loads(proc.stdout)


@pytest.mark.slow
@pytest.mark.timeout(300)  # a hang guard: seven interpreters boot, drive, stop; ~1 min unloaded
def test_gnuplot_draws_the_seed_plots_of_a_drive_recorded_on_a_live_ring(
    procs, ring_name: str, endpoint: str, tmp_path: Path
) -> None:
    gnuplot = gnuplot_binary()  # before anything starts: missing, the test fails at once
    logs = tmp_path / "logs"
    config = tmp_path / "localization.yaml"  # the logs' folder; LOPS's distances in the filter
    config.write_text(
        yaml.safe_dump({"logs": {"directory": str(logs)}, "sensors": {"lops": {"filter": True}}})
    )
    launcher = procs.tokenring(
        "up", "--ring", ring_name, "--listen", endpoint, "--nodes", ",".join(NODES),
        "--world", "square", "--speed", "10", "--bitrate", "max", "--sensors", "darmstadt",
        "--localizer", str(config), "--duration", "280",
    )  # fmt: skip  # --duration: a hang guard only, the test stops the ring itself
    try:
        with tap(endpoint) as session:
            wait_ring(session, ring_name, sorted(NODES.values()), timeout=180)
            procs.watch(launcher_pids(session, ring_name))
            truth = Truth(session, ring_name)
            start = truth.wait(lambda p: True, "the world's truth")
            assert math.dist(start[:2], START) < 1.0, start

            # the Localizer is logging, LOPS's packets among its records, before the robot moves
            def logging() -> bool:
                found = sorted(logs.glob("*.trlog"))
                return bool(found) and any(r[1:3] == ["L", "R"] for r in log_objects(found[0])[1:])

            wait_until(logging, 60, "copro's data log with LOPS records", interval=0.5)
            # the Darmstadt Pioneer answered moves only after "Motoren an" (seed 000 §6.7, key e)
            drive(endpoint, ring_name, "motors", "on")
            forward = drive(endpoint, ring_name, "forward", "500")
            turned = drive(endpoint, ring_name, "turn", "left", "90")
            end = truth.settled()
            assert math.dist(end[:2], start[:2]) > 400, (start, end, forward)  # it drove
            assert abs(math.remainder(end[2] - start[2] - math.pi / 2, math.tau)) < 0.2, (end, turned)
    finally:
        if launcher.poll() is None:
            launcher.send_signal(signal.SIGINT)  # Ctrl-C, as a user stops the ring
    output, _ = launcher.communicate(timeout=60)
    assert launcher.returncode == 130, output[-3000:]  # up's exit code after Ctrl-C: stopped whole
    assert "Traceback" not in output, output[-3000:]

    (log,) = sorted(logs.glob("*.trlog"))
    records = log_records(log)
    out = tmp_path / "seed"
    analysed = subprocess.run(
        [*TOKENRING, "analyze", str(log), "--seed-out", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert analysed.returncode == 0, analysed.stderr
    assert {p.name for p in out.iterdir() if p.is_dir()} == MODULES, analysed.stderr

    expected = expected_rows(records)
    for module in sorted(MODULES):
        folder = out / module
        images, data = command_file(folder)
        assert images == [f"{module}.png"], (module, images)  # the default terminal: pngcairo
        assert data, module
        assert not any((folder / image).exists() for image in images)  # gnuplot draws them, below
        result = subprocess.run(
            [gnuplot, "command"], cwd=folder, capture_output=True, text=True, timeout=60, check=False
        )
        assert result.returncode == 0, (module, result.stderr)
        for image in images:
            drawn = (folder / image).read_bytes()
            assert len(drawn) > len(PNG) and drawn[:8] == PNG, (module, image, drawn[:16])
        for name in data:
            rows = (folder / name).read_text().splitlines()
            assert rows and all(len(row.split()) == 2 for row in rows), (module, name, rows[:3])
            assert len(rows) == expected[module][name], (module, name, len(rows), expected[module][name])

    # every kind of data the drive made is drawn, not just what was there
    assert set(command_file(out / "lops")[1]) == {"empfaenger1", "empfaenger2", "empfaenger3"}
    assert {"kalman", "odometrie", "lops", "truth"} <= set(command_file(out / "position")[1])
    assert {"synchronisation", "odometry", "gyro", "lops"} <= set(command_file(out / "time")[1])
    assert expected["gyroskop"]["gyroskop"] > 100 and expected["odometrie"]["links"] > 50

    # the positions' last rows: the truth where the ring's world left the robot, the filter near
    def last(name: str) -> tuple[float, float]:
        x, y = (out / "position" / name).read_text().splitlines()[-1].split()
        return float(x), float(y)

    assert math.dist(last("truth"), end[:2]) < 2.0, (last("truth"), end)
    assert math.dist(last("kalman"), end[:2]) < 100.0, (last("kalman"), end)
