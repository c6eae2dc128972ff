"""The nemesis's vocabulary, apart from the nemesis (YAML, the schedules) so that
``tokenring chaos --help`` shows it without importing anything else."""

from __future__ import annotations

#: what --kinds accepts; each names an operation
OPERATIONS = ("crash", "crashloop", "hang", "softhang", "delay", "drop", "corrupt", "duplicate", "lose", "leave",
              "partition")  # fmt: skip
