"""The documentation pages generated from the code: the command reference (every command's help, from
the command line's own parser) and the configuration reference (``footnav.app.config_reference``).

    .venv/bin/python docs/generate.py          # rewrite docs/reference/cli.md and configuration.md
    .venv/bin/python docs/generate.py --check  # exit 1 if either is out of date (tests/test_docs.py)

The pages are committed, so they read as they are on any Markdown viewer; the test keeps them equal
to what the code says.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

REFERENCE = Path(__file__).resolve().parent / "reference"
GENERATED_WITH = (3, 11)
"""The Python the committed pages were written with: argparse's help layout changes between versions."""
HELP_COLUMNS = "100"
"""Width argparse wraps the help to (its ``COLUMNS``), so the page does not depend on the terminal."""

CLI_HEAD = """# Commands

The help of every command, generated from the command line's own parser by `python docs/generate.py`.
Run any of them with `--help` for the same text.
"""
CONFIGURATION_HEAD = """# Configuration keys

Every key a `footnav.toml` (or `--config FILE`) may hold, with its default and meaning, generated from
the code (`footnav.app.config_reference`) by `python docs/generate.py`. How the file, the command line
and a capture's recorded settings combine is in the [configuration guide](../guide/configuration.md);
`footnav config` prints the values in force and where each came from.
"""


def _block(text: str) -> list[str]:
    return ["```text", text.rstrip(), "```"]


def cli_page() -> str:
    """Every command's help, then each experiment's (argparse wraps to ``COLUMNS``, set meanwhile)."""
    columns = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = HELP_COLUMNS
    try:
        return _cli_page()
    finally:
        if columns is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = columns


def _cli_page() -> str:
    from footnav.app.experiments import EXPERIMENTS, experiment_module
    from footnav.app.parser import build_parser

    parser = build_parser()
    out = [CLI_HEAD, *_block(parser.format_help())]
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name, command in commands.choices.items():
        if name == "experiment":
            for exp, (_, help_text) in EXPERIMENTS.items():
                one = argparse.ArgumentParser(prog=f"footnav experiment {exp}", description=help_text)
                experiment_module(exp).add_arguments(one)
                out += ["", f"## footnav experiment {exp}", "", *_block(one.format_help())]
            continue
        out += ["", f"## footnav {name}", "", *_block(command.format_help())]
    return "\n".join(out) + "\n"


def configuration_page() -> str:
    from footnav.app.config_reference import markdown_table

    return CONFIGURATION_HEAD + "\n" + markdown_table()


PAGES = {"cli.md": cli_page, "configuration.md": configuration_page}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python docs/generate.py", description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="only check that the pages are current")
    args = ap.parse_args(argv)
    stale = []
    for name, make in PAGES.items():
        path = REFERENCE / name
        text = make()
        if args.check:
            if not path.exists() or path.read_text(encoding="utf-8") != text:
                stale.append(str(path))
        else:
            path.write_text(text, encoding="utf-8")
            print(f"wrote {path}")
    if stale:
        print(f"out of date (run python docs/generate.py): {', '.join(stale)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
