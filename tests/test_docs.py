"""The documentation's generated parts and links: the configuration reference covers every key, the
command reference every command, both pages are current, the plots are valid SVG, and every file the
README links exists.
(``mkdocs build --strict`` in ``.ci/run`` checks the site's own links and API references.)"""

from __future__ import annotations

import dataclasses
import importlib.util
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from types import ModuleType

import pytest
from footnav.app.config import defaults
from footnav.app.config_reference import attribute_docs, markdown_table, rows
from footnav.pipeline.navigation.profiles import UnitProfile

ROOT = Path(__file__).resolve().parents[1]


def _docs_module(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(f"docs_{name}", ROOT / "docs" / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_configuration_reference_describes_every_key() -> None:
    keys = {r.key: r for r in rows()}
    assert set(defaults().values) <= set(keys)
    profile_fields = {f"profiles.NAME.{f.name}" for f in dataclasses.fields(UnitProfile) if f.name != "name"}
    assert profile_fields <= set(keys)
    undescribed = [k for k, r in keys.items() if len(r.description) < 5]
    assert undescribed == []
    table = markdown_table()
    for key in defaults().values:
        section, _, name = key.partition(".")
        assert f"### [{section}]" in table and f"| `{name}` |" in table


def test_attribute_docs_reads_grouped_numpydoc_entries() -> None:
    class Example:
        """Something.

        Attributes
        ----------
        a, b
            Two at once, m.
        c
            One,
            on two lines.

        Notes
        -----
        not an attribute
        """

    assert attribute_docs(Example) == {"a": "Two at once, m.", "b": "Two at once, m.", "c": "One, on two lines."}


def test_the_command_reference_has_every_command() -> None:
    text = _docs_module("generate").cli_page()
    for command in ("demo", "live", "calibrate", "scan", "replay", "export", "evaluate", "config"):
        assert f"## footnav {command}" in text
    for experiment in ("calibration", "dual-imu", "tof"):
        assert f"## footnav experiment {experiment}" in text


def test_the_generated_pages_are_current() -> None:
    """docs/reference/cli.md and configuration.md are what the code says now (python docs/generate.py)."""
    generated_with = _docs_module("generate").GENERATED_WITH
    if sys.version_info[:2] != generated_with:
        pytest.skip(f"the pages were written with Python {generated_with}, whose argparse lays help out as they show")
    proc = subprocess.run(
        [sys.executable, str(ROOT / "docs" / "generate.py"), "--check"], capture_output=True, text=True, check=False
    )
    assert proc.returncode == 0, proc.stderr


def test_the_plots_are_svg_with_every_label() -> None:
    plots = _docs_module("plots")
    svg = plots.bar_chart("t", ["trial a", "trial b"], {"one": [0.1, 0.2], "two": [None, 0.3]}, "m")
    root = ET.fromstring(svg)
    texts = [e.text for e in root.iter("{http://www.w3.org/2000/svg}text")]
    assert {"trial a", "trial b", "one", "two", "0.300"} <= set(texts)
    bars = [e for e in root.iter("{http://www.w3.org/2000/svg}rect") if e.get("class") == "bar"]
    assert len(bars) == 3  # the missing value draws no bar


def test_every_file_the_readme_links_exists() -> None:
    readme = (ROOT / "README.md").read_text()
    targets = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", readme)
    local = [t for t in targets if not t.startswith(("http://", "https://"))]
    assert local, "the README links into the documentation"
    missing = [t for t in local if not (ROOT / t).exists()]
    assert missing == []
    assert len(readme.splitlines()) <= 250
