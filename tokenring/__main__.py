"""``python -m tokenring`` is the ``tokenring`` command."""

import sys

from tokenring.cli import main

sys.exit(main())
