"""The emulated sensors: IMU errors, ToF range sensors, the dual-IMU board, the miscalibrated unit on its jig."""
