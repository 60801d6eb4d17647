"""Accuracy table of every recording with ground truth, causal, step-smoothed (as live sessions show each
step once it has ended) and RTS-smoothed, in one command.

    .venv/bin/python -m benchmarks.accuracy [--data ../shared/data] [--no-emulator] [--no-smooth] [--no-real]
        [--axis-errors none|gyro-bias-calibrated] [--json FILE]

Real recordings (``../shared/data``, see its DATA.md): the PyShoe VICON trials (ARMSE-2D as the
PyShoe authors compute it, ``footnav.pipeline.metrics.armse_2d_pyshoe``, and ATE-3D after a yaw +
translation fit), the x-io and OpenShoe closed loops (loop closure 3D and 2D). Emulated walks
(``footnav.device.emulator``, MPU-6500-class errors, the seeds of ``tests/test_accuracy.py``; ``--axis-errors``
adds scale-factor and cross-axis errors, ``footnav.device.emulator.sensors.imu_errors.AXIS_ERRORS``): end-point error
as % of distance for the rectangle, figure-eight and stairs, and the filter's consistency, the mean
NEES of the 3D position (error ᵀ P⁻¹ error over all samples; for a consistent filter its mean is 3,
Bar-Shalom, Li, Kirubarajan, "Estimation with Applications to Tracking and Navigation", 2001,
§5.4.2, and the 95 % band of a time average over N independent samples is χ²₃ₙ/N; samples of one
walk are strongly correlated, so the band is only indicative).

One default configuration for every file (``footnav.app.commands.export.navigate_recording``); nothing is tuned to
a file. The ground truth is used only to measure.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
from footnav.app.commands.evaluate import evaluate_file, find_recordings
from footnav.device.emulator.motion.gait import simulate_walk
from footnav.device.emulator.sensors.imu_errors import AXIS_ERRORS, corrupt
from footnav.pipeline.navigation.navigator import NavConfig, navigate
from footnav.pipeline.navigation.profiles import get_profile

DEFAULT_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
EMULATED = (("rectangle", 240.0, 7), ("figure8", 240.0, 7), ("stairs", 60.0, 1))


def real_rows(data: Path, smooth: str | None) -> list[tuple[str, str, float, float, float, float]]:
    """(name, format, ARMSE-2D, ATE-3D, loop 3D, loop 2D) per recording (NaN where not applicable),
    causal (``smooth`` None) or smoothed (``footnav.app.commands.export.SMOOTHING``)."""
    rows = []
    for f in find_recordings([data]):
        e = evaluate_file(f, smooth)
        rows.append((e.name, e.format, e.armse_2d_m, e.ate_3d_m, e.loop_3d_m, e.loop_2d_m))
    return rows


def emulated_row(path: str, duration_s: float, seed: int, axes: str = "none") -> tuple[float, float, float]:
    """(end-point error % of distance, final vertical error m, mean position NEES) of one emulated walk."""
    truth = simulate_walk(path, duration_s, rate_hz=1000.0, seed=0)
    acc, gyr, _ = corrupt(truth.acc_b_mps2, truth.gyr_b_radps, truth.rate_hz, "mpu6500x4", seed=seed, axes=axes)
    nav, _ = navigate(truth.t_s, acc, gyr, truth.rate_hz, NavConfig(profile=get_profile("mpu6500x4")))
    assert nav is not None
    true_pos = truth.pos_n_m[-len(nav) :]
    err = nav.pos_n_m - true_pos
    pct = 100.0 * float(np.linalg.norm(err[-1])) / truth.distance_m
    cov = nav.pos_cov_n_m2
    # skip the first second: the covariance starts tiny and the error at exactly 0
    k0 = int(truth.rate_hz)
    e, c = err[k0:], cov[k0:]
    nees = np.einsum("ni,nij,nj->n", e, np.linalg.inv(c), e)
    return pct, float(err[-1, 2]), float(nees.mean())


def _f(v: float) -> str:
    return f"{'-':>7}" if math.isnan(v) else f"{v:7.3f}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--no-emulator", action="store_true")
    ap.add_argument("--no-smooth", action="store_true")
    ap.add_argument("--no-real", action="store_true", help="the emulated walks only")
    ap.add_argument("--axis-errors", choices=sorted(AXIS_ERRORS), default="none", help="of the emulated IMU")
    ap.add_argument(
        "--json", type=Path, metavar="FILE", help="also write the real recordings' rows as JSON (docs/plots.py)"
    )
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    modes: list[str | None] = [] if args.no_real else [None] if args.no_smooth else [None, "step", "whole"]
    results = {m: real_rows(args.data, m) for m in modes}
    prefix = {None: "", "step": "st.", "whole": "s."}
    if modes:
        print(
            f"{'recording':<22} {'format':<8} "
            + " ".join(f"{prefix[m] + h:>7}" for m in modes for h in ("ARMSE", "ATE3D", "loop3D", "loop2D"))
        )
    for i, row in enumerate(results.get(None, [])):
        cells = []
        for m in modes:
            cells += [_f(v) for v in results[m][i][2:]]
        print(f"{row[0][:22]:<22} {row[1]:<8} " + " ".join(cells))
    for m in modes:
        a = np.array([r[2] for r in results[m] if r[1] == "pyshoe"])
        loops = {r[0]: (r[4], r[5]) for r in results[m] if not math.isnan(r[4])}
        label = {None: "causal", "step": "step-smoothed", "whole": "smoothed"}[m]
        loop_txt = "  ".join(f"{k} 3D {v[0]:.3f} 2D {v[1]:.3f}" for k, v in loops.items())
        print(
            f"{label:<13}: PyShoe ARMSE-2D mean {a.mean():.4f} median {np.median(a):.3f} max {a.max():.3f} m;  "
            f"{loop_txt}"
        )
    if args.json is not None:
        fields = ("name", "format", "armse_2d_m", "ate_3d_m", "loop_3d_m", "loop_2d_m")
        table = {
            str(m or "causal"): [dict(zip(fields, row, strict=True)) for row in rows] for m, rows in results.items()
        }
        args.json.write_text(json.dumps(table, indent=1, allow_nan=True))
    if not args.no_emulator:
        for path, dur, seed in EMULATED:
            pct, dz, nees = emulated_row(path, dur, seed, args.axis_errors)
            print(
                f"emulated {path:<10} ({args.axis_errors}) end error {pct:.3f} % of distance, final dz {dz:+.3f} m, "
                f"mean NEES(pos) {nees:.2f}"
            )
    print(f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
