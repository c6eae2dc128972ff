"""What is on the wire and in operators' files: protocol.yaml compiled, the token's frame, every
Zenoh key, the ring's rules, the fault vocabulary. It starts no threads and opens no sessions."""
