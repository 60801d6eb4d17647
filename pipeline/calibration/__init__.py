"""Field calibration of the IMU: the accelerometer and gyroscope model, and the guided procedure."""
