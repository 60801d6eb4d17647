"""Stance detection: zero-velocity detectors on the IMU, the foot-height detector, floor levels from the stances."""
