"""Code shared by the module programs (present on every node, like the seed's OS library)."""
