"""``python -m bench``: the benchmark suite (see :mod:`bench.suite`)."""

import sys

from bench.suite import main
from tokenring import TokenRingError

try:
    sys.exit(main())
except TokenRingError as exc:  # bad options: a message, exit code 2, no traceback
    sys.stderr.write(f"python -m bench: {exc}\n")
    sys.exit(2)
