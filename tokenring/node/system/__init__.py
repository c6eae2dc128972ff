"""The system commands on the token (the seed's scan, configuration, download, start, stop): the
vocabulary, the issuing and receiving halves, and the layer a node mixes them into."""
