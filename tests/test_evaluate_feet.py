"""``footnav evaluate --left L --right R``: two feet's CSV recordings with ground truth, coupled and independent."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from footnav.app.api.feet import navigate_pair
from footnav.app.cli import main
from footnav.app.commands.evaluate import Reading, evaluate_file, evaluate_pair
from footnav.device.emulator.motion.gait import GaitTruth, two_feet_walks
from footnav.device.emulator.sensors.imu_errors import IMU_GRADES, corrupt
from footnav.device.files.recordings import load_recording
from footnav.pipeline.two_feet import FootSeparation

RIGHT_LATE_S = 0.37
"""The right foot's file starts this much later on the shared clock (its first rows cut off)."""
CLOCK_START_S = 1000.0


def _write_csv(path: Path, truth: GaitTruth, seed: int, first: int = 0) -> None:
    acc, gyr, _ = corrupt(
        truth.acc_b_mps2,
        truth.gyr_b_radps,
        truth.rate_hz,
        IMU_GRADES["mpu6500x4"],
        seed=seed,
        axes="gyro-bias-calibrated",
    )
    table = np.column_stack([CLOCK_START_S + truth.t_s, acc, gyr, truth.pos_n_m])[first:]
    header = "t,ax,ay,az,gx,gy,gz,gt_x_m,gt_y_m,gt_z_m"
    np.savetxt(path, table, fmt="%.10g", delimiter=",", header=header, comments="")


@pytest.fixture(scope="module")
def pair(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    folder = tmp_path_factory.mktemp("feet")
    left, right = two_feet_walks("rectangle", 45.0, seed=2)
    paths = folder / "left.csv", folder / "right.csv"
    _write_csv(paths[0], left, seed=2)
    _write_csv(paths[1], right, seed=3, first=round(RIGHT_LATE_S * right.rate_hz))
    return paths


def test_csv_ground_truth_and_clock_are_read(pair: tuple[Path, Path]) -> None:
    left, right = (load_recording(p) for p in pair)
    assert left.gt_pos_m is not None and left.gt_pos_m.shape == (len(left), 3)
    assert left.t_start_s == pytest.approx(CLOCK_START_S)
    assert right.t_start_s == pytest.approx(CLOCK_START_S + RIGHT_LATE_S)
    assert left.t_s[0] == 0.0 and right.t_s[0] == 0.0


def test_independent_rows_are_the_one_foot_evaluation(pair: tuple[Path, Path]) -> None:
    rows = evaluate_pair(*pair)
    assert [(r.name.split()[0], r.feet) for r in rows] == [
        ("L", "coupled"),
        ("R", "coupled"),
        ("L", "independent"),
        ("R", "independent"),
    ]
    for row, path in zip(rows[2:], pair, strict=True):
        alone = evaluate_file(path)
        assert row.ate_2d_m == pytest.approx(alone.ate_2d_m, abs=1e-12)
        assert row.end_point_m == pytest.approx(alone.end_point_m, abs=1e-12)
    # the coupled solution is another one, measured against the same truth
    assert rows[0].ate_2d_m != rows[2].ate_2d_m
    assert all(np.isfinite(r.ate_2d_m) and r.ate_2d_m < 2.0 for r in rows)


def test_coupled_feet_keep_within_the_bound_on_the_shared_clock(pair: tuple[Path, Path]) -> None:
    left, right = (load_recording(p) for p in pair)
    bound = FootSeparation(heading=None)  # the bound alone (with the relative heading the feet stay inside it)
    coupled = navigate_pair(left, right, bound=bound)
    apart = navigate_pair(left, right, coupled=False)
    assert coupled.corrections, "the axis errors drive the independent feet apart: the bound must act"
    assert coupled.left is not None and coupled.right is not None
    t = np.intersect1d(np.round(coupled.left.t_s, 6), np.round(coupled.right.t_s, 6))
    assert t.size > 0.9 * 40.0 * left.rate_hz  # matched on the shared clock, the right file's late start included
    largest, beyond = [], []
    for res in (coupled, apart):
        assert res.left is not None and res.right is not None
        il = np.searchsorted(np.round(res.left.t_s, 6), t)
        ir = np.searchsorted(np.round(res.right.t_s, 6), t)
        left_m = res.left.pos_n_m[il] + np.asarray(bound.left_origin_m)
        delta = left_m - res.right.pos_n_m[ir] - np.asarray(bound.right_origin_m)
        d = np.hypot(delta[:, 0], delta[:, 1])
        largest.append(float(d.max()))
        beyond.append(int(np.count_nonzero(d > bound.max_m)))
    # the bound is applied after each 50 ms lockstep batch: within one a swinging foot can pass it by centimetres
    assert largest[0] < bound.max_m + 0.06 < largest[1]
    assert beyond[0] < beyond[1] / 4


def test_cli_prints_both_solutions_and_their_comparison(
    pair: tuple[Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["evaluate", "--left", str(pair[0]), "--right", str(pair[1])]) == 0
    out = capsys.readouterr().out
    rows = [line.split()[:2] for line in out.splitlines() if line[:2] in ("L ", "R ")]
    assert rows == [["L", "coupled"], ["R", "coupled"], ["L", "independent"], ["R", "independent"]]
    coupled_line = next(line for line in out.splitlines() if line.startswith("two feet coupled:"))
    assert re.search(r"\(\d+ corrections of the distance bound, \d+ relative heading updates\)$", coupled_line)
    assert "two feet independent:" in out
    assert re.search(r"^coupled against independent: [-+]\d+\.\d % mean (ATE-2D|loop closure 2D)$", out, re.MULTILINE)
    assert main(["evaluate", "--left", str(pair[0]), "--right", str(pair[1]), "--independent-feet"]) == 0
    out = capsys.readouterr().out
    rows = [line.split()[:2] for line in out.splitlines() if line[:2] in ("L ", "R ")]
    assert rows == [["L", "independent"], ["R", "independent"]] and "two feet coupled:" not in out


def test_heading_coupling_is_another_coupled_solution(
    pair: tuple[Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """The default couples the relative heading too; ``--distance-only`` the bound alone."""
    distance = evaluate_pair(*pair, heading=False)
    heading = evaluate_pair(*pair)
    assert [r.ate_2d_m for r in heading[2:]] == [r.ate_2d_m for r in distance[2:]]  # independent: the same
    assert all(h.ate_2d_m != d.ate_2d_m for h, d in zip(heading[:2], distance[:2], strict=True))
    assert (
        main(["evaluate", "--left", str(pair[0]), "--right", str(pair[1]), "--distance-only", "--independent-feet"])
        == 2
    )
    assert "give one of them" in capsys.readouterr().err


def test_cli_refuses_half_a_pair_and_files_that_do_not_overlap(
    pair: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["evaluate", "--left", str(pair[0])]) != 0
    assert "--left FILE --right FILE" in capsys.readouterr().err
    later = tmp_path / "later.csv"
    text = pair[1].read_text().splitlines()
    rows = np.loadtxt(text[1:], delimiter=",")
    rows[:, 0] += 3600.0
    np.savetxt(later, rows, fmt="%.10g", delimiter=",", header=text[0], comments="")
    assert main(["evaluate", "--left", str(pair[0]), "--right", str(later)]) != 0
    assert "do not overlap in time" in capsys.readouterr().err


def test_columns_and_profile_are_read_as_export_reads_them(
    pair: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``evaluate --columns/--profile``: another tool's names and units (time in ms, acceleration in g, the ground
    truth as X;Y;Z) give the figures of the file in footnav's names; the profile reaches each foot's navigator."""
    table = np.loadtxt(pair[0], delimiter=",", skiprows=1)
    table[:, 0] *= 1000.0
    table[:, 1:4] /= 9.80665
    renamed = tmp_path / "other-tool.csv"
    np.savetxt(renamed, table, fmt="%.10g", delimiter=",", header="ms,a1,a2,a3,w1,w2,w3,X,Y,Z", comments="")
    spec = "time=ms:ms,acc=a1;a2;a3:g,gyr=w1;w2;w3,gt=X;Y;Z"
    assert main(["evaluate", str(renamed)]) == 2  # footnav's own names are not there
    capsys.readouterr()
    reference = evaluate_file(pair[0])
    for jobs in ("1", "2"):  # in this process, and in worker processes (the reading pickled to them)
        assert main(["evaluate", str(renamed), str(pair[0]), "--columns", spec, "--jobs", jobs]) == 2
        out, err = capsys.readouterr()
        row = out.splitlines()[2].split()
        assert row[0] == "other-tool" and float(row[4]) == pytest.approx(reference.ate_2d_m, abs=1e-3)
        assert "left.csv" in err and "not found" in err  # footnav's own names are not those of --columns
    assert main(["evaluate", "--left", str(renamed), "--right", str(renamed), "--columns", spec]) == 0
    assert "two feet coupled:" in capsys.readouterr().out
    generic, mpu = (evaluate_pair(*pair, reading=Reading(profile=p)) for p in ("generic", "mpu6500x4"))
    assert [r.ate_2d_m for r in generic] == [r.ate_2d_m for r in evaluate_pair(*pair)]  # a CSV's default profile
    assert all(g.ate_2d_m != m.ate_2d_m for g, m in zip(generic, mpu, strict=True))


def test_a_pairs_input_handling_is_each_files_own(pair: tuple[Path, Path], tmp_path: Path) -> None:
    """Gyroscopes cut off at 4 rad/s: each foot's row of a pair tells what was done with its clipped rates, as
    ``evaluate`` of the file alone tells it."""
    clipped = []
    for path in pair:
        table = np.loadtxt(path, delimiter=",", skiprows=1)
        table[:, 4:7] = np.clip(table[:, 4:7], -4.0, 4.0)
        clipped.append(tmp_path / path.name)
        np.savetxt(clipped[-1], table, fmt="%.10g", delimiter=",", header=path.read_text().split("\n")[0], comments="")
    rows = evaluate_pair(*clipped)
    for side, path in enumerate(clipped):
        alone = evaluate_file(path).handling
        assert "gyroscope values taken as clipped" in alone
        assert rows[side].handling == rows[2 + side].handling == alone  # coupled and independent rows alike
