"""Estimation on streamed samples: detectors, the error-state Kalman filter, and the stage runner.

Estimators here are pure and synchronous (numpy, numba); only ``pipeline.runner`` knows asyncio.
"""
