"""Gait quantities from a navigation solution: steps, foot clearance."""
