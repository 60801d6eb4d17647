"""The navigation filter: the causal navigator, the error-state Kalman filter and its compiled kernels, alignment,
quaternions, unit profiles, clipped rates."""
