"""``python -m bench``: for now the round-trip benchmark of ``tokenring bench``."""

import sys

from tokenring.cli import main

sys.exit(main(["bench", *sys.argv[1:]]))
