"""The documentation's accuracy plots, as SVG, from the accuracy benchmark's output.

    .venv/bin/python -m benchmarks.accuracy --no-emulator --json accuracy.json
    .venv/bin/python docs/plots.py accuracy.json [--data ../shared/data]

Writes ``docs/images/accuracy-pyshoe.svg`` (ARMSE-2D per PyShoe trial: footnav causal and smoothed,
one configuration for every trial, against the PyShoe authors' SHOE detector with its threshold tuned
per trial, the ``trial_error`` each trial's ``.mat`` file stores) and ``docs/images/accuracy-loops.svg``
(loop closure of the two closed loops against the figures of ``../shared/data/DATA.md``).
"""

from __future__ import annotations

import argparse
import json
from html import escape
from pathlib import Path

IMAGES = Path(__file__).resolve().parent / "images"
COLOURS = ("#3f51b5", "#26a69a", "#ff9800", "#9e9e9e")
PEER_LOOPS_3D_M = {
    "short_walk": {"x-io (published)": 0.082, "pyshoe": 0.248, "gaitmap": 0.597},
    "data_inert": {"pyshoe": 0.833, "gaitmap": 0.832},
}
"""Loop closure, 3D, of the peers' methods with their defaults (``../shared/data/DATA.md``), m."""


def bar_chart(title: str, groups: list[str], series: dict[str, list[float | None]], unit: str) -> str:
    """A horizontal grouped bar chart: one group of bars per label in ``groups``, one bar per series."""
    names = list(series)
    bar_h, gap, left, width, top = 9, 10, 170, 420, 40
    group_h = bar_h * len(names) + gap
    height = top + group_h * len(groups) + 50
    vmax = max(v for values in series.values() for v in values if v is not None) * 1.12
    out = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{left + width + 90}" height="{height}" '
        'font-family="sans-serif" font-size="11">',
        f'<rect width="100%" height="100%" fill="white"/><text x="10" y="20" font-size="13" '
        f'font-weight="bold">{escape(title)}</text>',
    ]
    for tick in range(6):
        value = vmax * tick / 5
        x = left + width * tick / 5
        out.append(f'<line x1="{x:.1f}" y1="{top - 5}" x2="{x:.1f}" y2="{height - 45}" stroke="#e0e0e0"/>')
        out.append(f'<text x="{x:.1f}" y="{height - 32}" text-anchor="middle">{value:.2f}</text>')
    out.append(f'<text x="{left + width / 2}" y="{height - 16}" text-anchor="middle">{escape(unit)}</text>')
    for g, label in enumerate(groups):
        y0 = top + g * group_h
        out.append(
            f'<text x="{left - 6}" y="{y0 + bar_h * len(names) / 2 + 4}" text-anchor="end">{escape(label)}</text>'
        )
        for s, name in enumerate(names):
            value = series[name][g]
            if value is None:
                continue
            y = y0 + s * bar_h
            w = width * value / vmax
            out.append(
                f'<rect class="bar" x="{left}" y="{y}" width="{w:.1f}" height="{bar_h - 1}" fill="{COLOURS[s]}"/>'
            )
            out.append(f'<text x="{left + w + 3:.1f}" y="{y + bar_h - 1}" font-size="9">{value:.3f}</text>')
    for s, name in enumerate(names):
        x = left + s * 150 - 160
        out.append(f'<rect x="{max(x, 10)}" y="{height - 12}" width="10" height="8" fill="{COLOURS[s]}"/>')
        out.append(f'<text x="{max(x, 10) + 14}" y="{height - 4}">{escape(name)}</text>')
    out.append("</svg>")
    return "\n".join(out) + "\n"


def pyshoe_tuned(data: Path, trial: str) -> float:
    """The PyShoe authors' ARMSE-2D of ``trial`` with the SHOE detector's threshold tuned to it, m."""
    import numpy as np
    from footnav.device.files.mat_reader import load_mat

    errors = load_mat(data / "pyshoe-vicon" / f"{trial}.mat")["trial_error"]  # SHOE, ARED, AMVD, MBGTD, VICON
    return float(np.asarray(errors).ravel()[0])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python docs/plots.py", description=__doc__.splitlines()[0])
    ap.add_argument("json", type=Path, help="benchmarks.accuracy --json output")
    ap.add_argument("--data", type=Path, default=Path("../shared/data"), help="the recordings folder")
    args = ap.parse_args(argv)
    table = json.loads(args.json.read_text())
    causal = {r["name"]: r for r in table["causal"]}
    if "whole" not in table:
        raise SystemExit(f"{args.json} has no smoothed figures: run benchmarks.accuracy without --no-smooth")
    smoothed = {r["name"]: r for r in table["whole"]}
    trials = sorted(n for n, r in causal.items() if r["format"] == "pyshoe")
    IMAGES.mkdir(exist_ok=True)
    series: dict[str, list[float | None]] = {
        "footnav, causal": [causal[t]["armse_2d_m"] for t in trials],
        "footnav, smoothed": [smoothed[t]["armse_2d_m"] for t in trials],
        "pyshoe, tuned per trial": [pyshoe_tuned(args.data, t) for t in trials],
    }
    svg = bar_chart("PyShoe VICON trials: ARMSE-2D (lower is better)", trials, series, "m")
    (IMAGES / "accuracy-pyshoe.svg").write_text(svg)
    loops = sorted(PEER_LOOPS_3D_M)
    peers = sorted({p for v in PEER_LOOPS_3D_M.values() for p in v})
    loop_series: dict[str, list[float | None]] = {"footnav, causal": [causal[n]["loop_3d_m"] for n in loops]}
    loop_series |= {p: [PEER_LOOPS_3D_M[n].get(p) for n in loops] for p in peers}
    names = {"short_walk": "x-io loop, 24 m", "data_inert": "OpenShoe loop, 85-90 m"}
    labels = [names.get(n, n) for n in loops]
    svg = bar_chart("Closed loops: end-to-start distance, 3D (lower is better)", labels, loop_series, "m")
    (IMAGES / "accuracy-loops.svg").write_text(svg)
    print(f"wrote {IMAGES / 'accuracy-pyshoe.svg'} and {IMAGES / 'accuracy-loops.svg'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
