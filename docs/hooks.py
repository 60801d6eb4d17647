"""MkDocs hooks: the API reference's source tree, and the pages generated from the code.

- ``on_config``: griffe (mkdocstrings) finds packages on paths, but ``footnav.*`` exists only through
  setuptools' ``package-dir`` mapping; a tree of links ``.docs-api/footnav/{app,device,pipeline,views}``
  gives it the namespace as installed.
- ``on_page_markdown``: ``<!-- footnav:configuration -->`` becomes the configuration reference
  (``footnav.app.config_reference``), ``<!-- footnav:cli -->`` the help of every command.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
API_TREE = ROOT / ".docs-api"
TOPS = ("app", "device", "pipeline", "views")


def on_config(config: Any) -> Any:
    package = API_TREE / "footnav"
    package.mkdir(parents=True, exist_ok=True)
    for top in TOPS:
        link = package / top
        if not link.is_symlink():
            os.symlink(ROOT / top, link)
    return config


def _cli_help() -> str:
    from footnav.app.parser import build_parser

    os.environ["COLUMNS"] = "100"  # argparse wraps help to this width
    parser = build_parser()
    out = ["```text", parser.format_help().rstrip(), "```"]
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name, command in sub.choices.items():
        if name == "experiment":
            from footnav.app.experiments import EXPERIMENTS, experiment_module

            for exp, (_, help_text) in EXPERIMENTS.items():
                one = argparse.ArgumentParser(prog=f"footnav experiment {exp}", description=help_text)
                experiment_module(exp).add_arguments(one)
                out += ["", f"## footnav experiment {exp}", "", "```text", one.format_help().rstrip(), "```"]
            continue
        out += ["", f"## footnav {name}", "", "```text", command.format_help().rstrip(), "```"]
    return "\n".join(out) + "\n"


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    if "<!-- footnav:configuration -->" in markdown:
        from footnav.app.config_reference import markdown_table

        markdown = markdown.replace("<!-- footnav:configuration -->", markdown_table())
    if "<!-- footnav:cli -->" in markdown:
        markdown = markdown.replace("<!-- footnav:cli -->", _cli_help())
    return markdown
