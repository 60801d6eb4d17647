"""The documentation's pictures of the viewer, made from real runs: each recording is written by the
``footnav`` command a user would type, then rendered by the real Rerun viewer, headless
(``footnav.views.screenshot``; needs software Vulkan: ``apt-get install mesa-vulkan-drivers``).

    .venv/bin/python docs/screenshots.py [--data ../shared/data] [--only NAME ...]

Writes ``docs/images/<name>.png`` for each picture in :data:`PICTURES`.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

from footnav.views.screenshot import screenshot

IMAGES = Path(__file__).resolve().parent / "images"

PICTURES: dict[str, list[str]] = {
    "one-foot": ["demo", "--duration", "60", "--pace", "max"],
    "two-feet": ["demo", "--feet", "2", "--duration", "40", "--pace", "max"],
    "tof": ["demo", "--tof", "--path", "stairs", "--duration", "40", "--pace", "max"],
    "real-recording": ["replay", "{data}/xio-gait-tracking/short_walk.csv"],
    "pyshoe-truth": ["replay", "{data}/pyshoe-vicon/2017-11-22-11-22-03.mat"],
    "openshoe-log": ["replay", "{data}/openshoe/data_inert.txt"],
}
"""Picture name -> the footnav command that records it (``{data}``: the recordings folder)."""


def make(name: str, data: Path, work: Path) -> Path:
    """Record picture ``name`` with its command and render it to ``docs/images/<name>.png``."""
    rrd = work / f"{name}.rrd"
    argv = [a.format(data=data) for a in PICTURES[name]]
    argv += ["--no-viewer", "--save", str(rrd)]
    if argv[0] == "demo":
        argv += ["--sessions", str(work)]
    subprocess.run([sys.executable, "-m", "footnav.app", *argv], check=True, stdout=subprocess.DEVNULL)
    png = IMAGES / f"{name}.png"
    IMAGES.mkdir(parents=True, exist_ok=True)
    screenshot(rrd, png, settle_s=12.0)  # the viewer's start-up notices have faded by then
    return png


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python docs/screenshots.py", description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=Path("../shared/data"), help="the recordings folder")
    ap.add_argument("--only", nargs="+", choices=sorted(PICTURES), help="make only these pictures")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.only or PICTURES:
            print(f"{name}: {make(name, args.data.resolve(), Path(tmp))}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
