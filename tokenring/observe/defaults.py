"""The observers' defaults that a verb's options show (``tokenring foxglove --help``), apart from
the servers (the Foxglove SDK) so that showing them imports nothing else."""

from __future__ import annotations

#: the Foxglove bridge's WebSocket port: Foxglove's own default
FOXGLOVE_PORT = 8765
