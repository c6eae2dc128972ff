"""Where the robot is: sensor synchronisation, the EKF, the walls it localises against, its
configuration and logs (the Darmstadt program), and main's correction of the motor's pose."""
