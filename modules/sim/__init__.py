"""The robot without a ring: main's and copro's classes and the world's physics stepped on one
simulated clock in one process, for tests and benchmarks (never imported by a program or the world)."""
