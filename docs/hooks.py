"""MkDocs hook: the API reference's source tree.

griffe (mkdocstrings) finds packages on paths, but ``footnav.*`` exists only through setuptools'
``package-dir`` mapping; a tree of links ``.docs-api/footnav/{app,device,pipeline,views}`` gives it
the namespace as installed.
"""

from __future__ import annotations

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
