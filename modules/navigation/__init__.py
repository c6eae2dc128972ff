"""Where the robot goes: main's navigators (the exploration strategies), its pilot, action files,
the compass's calibration turn and the frontiers left to explore."""
