"""Throughput benchmarks of footnav's estimators against a plain numpy baseline.

Run ``python -m benchmarks`` from the repository root (see ``benchmarks/README.md``).
"""
