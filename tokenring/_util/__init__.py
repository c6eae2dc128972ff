"""Small helpers that know nothing of the ring: files, strict YAML, process lifetime, tables."""
