"""Reproducible experiments on the emulator: ``footnav experiment NAME`` prints one table.

Each experiment is one module of this package, listed in :data:`EXPERIMENTS` with its command-line
name and one line of help, and defines::

    def add_arguments(parser: argparse.ArgumentParser) -> None
    def run(args: argparse.Namespace) -> int    # prints its table, returns the exit status

The parser lists every experiment from the table and imports only the module of the one asked for,
so ``footnav experiment --help`` starts at once (tests/test_layout.py checks the table against the
package's modules).
"""

from __future__ import annotations

import argparse
import importlib
from collections.abc import Sequence
from types import ModuleType

EXPERIMENTS: dict[str, tuple[str, str]] = {
    "calibration": (
        "calibration",
        "icosahedron calibration of an emulated miscalibrated unit: parameters vs truth, walk with/without",
    ),
    "dual-imu": (
        "dual_imu",
        "dual-IMU board vs single-IMU ZUPT on the rectangle and the stairs (max and mean position error)",
    ),
    "tof": ("tof", "foot clearance and vertical error with and without the ToF sensors (70 s walk, stairs)"),
}
"""Command-line name -> (module in this package, one line of help)."""


def experiment_module(name: str) -> ModuleType:
    """The module of the experiment called ``name`` on the command line."""
    return importlib.import_module(f"{__name__}.{EXPERIMENTS[name][0]}")


def experiment_parser(argv: Sequence[str] = ()) -> argparse.ArgumentParser:
    """``footnav experiment``'s parser: one sub-command per experiment; only the one that ``argv``
    names has its options added (and its module imported)."""
    parser = argparse.ArgumentParser(
        prog="footnav experiment", description="Run a reproducible emulator experiment and print its table."
    )
    names = parser.add_subparsers(dest="experiment", required=True, metavar="NAME")
    chosen = next((a for a in argv if not a.startswith("-")), None)
    for name, (_, help_text) in EXPERIMENTS.items():
        sub = names.add_parser(name, help=help_text, description=help_text)
        if name == chosen:
            experiment_module(name).add_arguments(sub)
    return parser


def run_experiment(args: argparse.Namespace) -> int:
    """Run the experiment ``args.experiment`` chose."""
    return int(experiment_module(args.experiment).run(args))
