"""The names the command line offers as choices, as plain strings, so that building the parser
imports no numerics (``footnav --help`` starts at once). ``tests/test_layout.py`` checks each tuple
against the table it names."""

from __future__ import annotations

PATHS = ("rectangle", "line", "figure8", "stairs")
"""Emulated walking courses (:data:`footnav.device.emulator.motion.paths` builds them)."""
IMU_GRADES = ("adis16367", "gx3", "icm20948", "icm20948-board", "ideal", "mpu6500x4")
"""Emulated sensor grades: the keys of :data:`footnav.device.emulator.sensors.imu_errors.IMU_GRADES`."""
AXIS_ERRORS = ("gyro-bias-calibrated", "icm20948-datasheet", "none")
"""Emulated axis errors: the keys of :data:`footnav.device.emulator.sensors.imu_errors.AXIS_ERRORS`."""
PROFILES = ("adis16367", "generic", "gx3", "mpu6500x4")
"""Built-in unit profiles: the keys of :data:`footnav.pipeline.navigation.profiles.PROFILES`."""
RECORDING_FORMATS = ("csv", "mimu-log", "openshoe", "pyshoe", "xio")
"""Recording formats: the keys of :data:`footnav.device.files.recordings.LOADERS`."""
UNIT_MODELS = ("mimu22bl", "mimu22bt", "mimu4444", "oblu", "openshoe")
"""Unit models: the keys of :data:`footnav.device.models.UNIT_MODELS`."""
OUTPUT_MODES = ("auto", "imu", "raw", "ins", "steps")
"""``--mode``: ``auto`` and the outputs of :data:`footnav.device.models.OUTPUTS`."""
