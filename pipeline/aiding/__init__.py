"""Aiding beyond zero velocity: the ToF foot-height measurement and the barometer."""
