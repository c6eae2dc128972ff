"""Running a ``tokenring`` command that must refuse its input: exit code 2, one line on stderr,
no traceback, nothing started — optionally under an address-space limit, so that input which
would take gigabytes fails the test instead of the machine."""

from __future__ import annotations

import os
import resource
import subprocess
from collections.abc import Callable

from tests.support.processes import REPO, TOKENRING

#: an address space a refusing CLI fits in with room to spare (it needs about 300 MB)
MEMORY_LIMIT = 768 * 1024 * 1024


def limit_memory(limit: int) -> Callable[[], None]:
    """A ``preexec_fn`` capping the child's address space at ``limit`` bytes."""

    def apply() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))

    return apply


def run_refused(
    *args: str, memory: int | None = None, timeout: float = 60.0, env: dict[str, str] | None = None
) -> subprocess.CompletedProcess:
    """Run ``tokenring ARGS`` where no ring can be found (``TOKENRING_ENDPOINT`` points at the
    discard port), within ``memory`` bytes of address space if given."""
    environment = dict(os.environ, TOKENRING_ENDPOINT="tcp/127.0.0.1:9", **(env or {}))
    return subprocess.run(
        [*TOKENRING, *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=REPO,
        env=environment,
        preexec_fn=limit_memory(memory) if memory else None,
    )


def refusal_line(result: subprocess.CompletedProcess, *needles: str) -> str:
    """The one line a refusal printed, after checking it is one: exit code 2, no traceback,
    nothing started, and every ``needle`` in it."""
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, (result.returncode, result.stdout[-500:], result.stderr[-1500:])
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr[-1500:]
    assert "starting" not in result.stdout, result.stdout[-500:]
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]
