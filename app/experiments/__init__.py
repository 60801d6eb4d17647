"""Reproducible experiments on the emulator: ``footnav experiment NAME`` prints one table.

Each module in this package is one experiment and defines::

    NAME: str                                   # the command-line name
    HELP: str                                   # one line for --help
    def add_arguments(parser: argparse.ArgumentParser) -> None
    def run(args: argparse.Namespace) -> int    # prints its table, returns the exit status

Modules are found by listing the package, so adding an experiment touches no other file.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
from types import ModuleType


def experiment_modules() -> dict[str, ModuleType]:
    """The experiments by command-line name, in module-name order."""
    found: dict[str, ModuleType] = {}
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        found[module.NAME] = module
    return found


def experiment_parser() -> argparse.ArgumentParser:
    """``footnav experiment``'s parser: one sub-command per experiment (imports every experiment)."""
    parser = argparse.ArgumentParser(
        prog="footnav experiment", description="Run a reproducible emulator experiment and print its table."
    )
    names = parser.add_subparsers(dest="experiment", required=True, metavar="NAME")
    for name, module in experiment_modules().items():
        module.add_arguments(names.add_parser(name, help=module.HELP, description=module.HELP))
    return parser


def run_experiment(args: argparse.Namespace) -> int:
    """Run the experiment ``args.experiment`` chose."""
    return int(experiment_modules()[args.experiment].run(args))
