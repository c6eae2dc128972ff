"""The sensor and actuator modules' arithmetic: sonar contacts and behaviours, the compass's bridges,
the motor's steps and dead reckoning, the charger's battery."""
