"""A virtual shoe: gait motion model, IMU error model, and the unit's protocol served on a pty."""
