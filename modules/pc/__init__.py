"""The robot's PC side: what a person at the PC does with the robot (drive it, explore, fetch and
score the map, watch the LCD, read, replay and analyse the logs). The verbs (``commands/``)
parse, call and print; the library beside them does the work."""
