"""``python -m tokenring`` is the ``tokenring`` command."""

import sys

from tokenring.cli.main import main

sys.exit(main())
