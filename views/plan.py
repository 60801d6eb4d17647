"""The plan view: the horizontal track from above, in metres, with a labelled grid, start and end marks
and the step ellipses at a stated sigma.

Rerun's 2D views put +y down (image axes), so every plan point is drawn at ``(x, −y)`` of the
navigation frame: north (the navigation +y) is up and the turn direction reads as on a map. The
grid covers the track's extent plus a margin, in :data:`GRID_STEP_M` cells, with a labelled line every
:data:`LABEL_STEP_M`; it is logged again only when the track leaves it. A step ellipse is the
``sigma_scale``-sigma contour of the step's horizontal position covariance P (2×2):
``p(θ) = c + k·V·diag(√λ)·(cos θ, sin θ)`` with ``P = V diag(λ) Vᵀ``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import rerun as rr
from footnav.views.convert import SendColumns, horizontal_block, time_column
from footnav.views.paths import PLAN, PlanPaths
from numpy.typing import NDArray

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]

LINE_POINT_SPACING_S = 0.1
"""The decimated track keeps one point per this much device time to start with ..."""
LINE_MAX_POINTS = 500
"""... and halves its points (doubling the spacing) whenever it holds more than this, so each
re-log costs at most ~6 kB however long the session runs."""

GRID_STEP_M = 1.0
LABEL_STEP_M = 5.0
GRID_MARGIN_M = 2.0
ELLIPSE_VERTICES = 33
"""Vertices of a drawn ellipse (closed: the first repeated)."""
GRID_RGBA = (120, 120, 120, 70)
GRID_MAJOR_RGBA = (170, 170, 170, 140)
START_RGB = (240, 240, 240)
END_RGB = (240, 228, 66)


@dataclass(slots=True)
class DecimatedLine:
    """Decimated track of one foot, drawn in 3D and in the plan view (kept on the logger thread)."""

    points: list[tuple[float, float, float]]
    spacing_s: float = LINE_POINT_SPACING_S
    next_t_s: float = -np.inf
    logged_t_s: float = -np.inf
    logged_wall: float = -np.inf
    last_t_s: float = -np.inf
    first_t_s: float = np.inf
    dirty: bool = False

    def add(self, t_s: NDArray[np.float64], pos: NDArray[np.float32]) -> None:
        """Take the samples (n,) at (n, 3) positions that fall on the line's spacing. Samples that all
        precede the line's first point (a lead-in filled in: ``footnav.pipeline.navigation.lead_in``)
        go before it, at the same spacing."""
        if t_s.shape[0] == 0:
            return
        if self.points and float(t_s[-1]) < self.first_t_s:
            earlier, _ = self._spaced(t_s, pos, -np.inf)
            self.points[:0] = earlier
            self.first_t_s = float(t_s[0])
        else:
            later, self.next_t_s = self._spaced(t_s, pos, self.next_t_s)
            if later and not self.points:
                self.first_t_s = float(t_s[0])
            self.points += later
            self.last_t_s = float(t_s[-1])
        while len(self.points) > LINE_MAX_POINTS:
            self.points = self.points[::2]
            self.spacing_s *= 2.0

    def _spaced(
        self, t_s: NDArray[np.float64], pos: NDArray[np.float32], next_t_s: float
    ) -> tuple[list[tuple[float, float, float]], float]:
        """The samples from ``next_t_s`` on that are :attr:`spacing_s` apart, and the time of the next."""
        taken: list[tuple[float, float, float]] = []
        for k in range(t_s.shape[0]):
            if t_s[k] >= next_t_s:
                taken.append((float(pos[k, 0]), float(pos[k, 1]), float(pos[k, 2])))
                next_t_s = float(t_s[k]) + self.spacing_s
        self.dirty = self.dirty or bool(taken)
        return taken, next_t_s


def to_plan(xy_n_m: NDArray[np.floating]) -> F32:
    """(n, 2) or (n, 3) navigation-frame positions as (n, 2) plan points ``(x, −y)``, float32."""
    xy = np.asarray(xy_n_m, dtype=np.float64)[:, :2]
    return np.column_stack([xy[:, 0], -xy[:, 1]]).astype(np.float32)


def ellipse_strips(center_n_m: F64, cov_n_m2: F64, *, sigma_scale: float) -> F32:
    """(k, :data:`ELLIPSE_VERTICES`, 2) plan polylines of the ``sigma_scale``-sigma ellipses of the
    (k, ≥2, ≥2) covariances' horizontal blocks around the (k, ≥2) centres."""
    evals, evecs = np.linalg.eigh(horizontal_block(cov_n_m2))
    theta = np.linspace(0.0, 2.0 * math.pi, ELLIPSE_VERTICES)
    unit = np.stack([np.cos(theta), np.sin(theta)])  # (2, m)
    axes = evecs * (sigma_scale * np.sqrt(np.clip(evals, 0.0, None)))[:, None, :]  # (k, 2, 2)
    pts = np.asarray(center_n_m, dtype=np.float64)[:, None, :2] + np.einsum("kij,jm->kmi", axes, unit)
    pts[..., 1] *= -1.0
    return pts.astype(np.float32)


def grid_bounds(
    points_plan: F32, current: tuple[float, float, float, float] | None
) -> tuple[float, float, float, float] | None:
    """The grid's ``(x0, x1, y0, y1)`` (plan axes, m) to draw for ``points_plan`` (n, 2): None while
    the points stay inside ``current``, else ``current`` grown to their extent plus
    :data:`GRID_MARGIN_M`, on whole :data:`LABEL_STEP_M`."""
    lo = points_plan.min(axis=0)
    hi = points_plan.max(axis=0)
    if (
        current is not None
        and lo[0] >= current[0]
        and hi[0] <= current[1]
        and lo[1] >= current[2]
        and hi[1] <= current[3]
    ):
        return None
    snap = LABEL_STEP_M
    x0, y0 = (math.floor((float(v) - GRID_MARGIN_M) / snap) * snap for v in lo)
    x1, y1 = (math.ceil((float(v) + GRID_MARGIN_M) / snap) * snap for v in hi)
    if current is not None:  # grow, never shrink (the other foot's track is inside the old grid)
        x0, x1, y0, y1 = min(x0, current[0]), max(x1, current[1]), min(y0, current[2]), max(y1, current[3])
    return x0, x1, y0, y1


def grid_archetypes(bounds: tuple[float, float, float, float]) -> list[tuple[str, rr.AsComponents]]:
    """The grid's lines (minor every :data:`GRID_STEP_M`, major and labelled every :data:`LABEL_STEP_M`)
    and its scale labels, in metres of the navigation frame, for ``bounds`` in plan axes."""
    x0, x1, y0, y1 = bounds
    xs = np.arange(x0, x1 + 1e-9, GRID_STEP_M)
    ys = np.arange(y0, y1 + 1e-9, GRID_STEP_M)

    def lines(values_x: F64, values_y: F64) -> list[F32]:
        v = [np.array([[x, y0], [x, y1]], dtype=np.float32) for x in values_x]
        return v + [np.array([[x0, y], [x1, y]], dtype=np.float32) for y in values_y]

    label_x, major_y = xs[_major(xs)], ys[_major(ys)]
    label_y = major_y[major_y < y1]  # the bottom line's corner carries an x label
    positions = np.concatenate(
        [np.column_stack([label_x, np.full(label_x.size, y1)]), np.column_stack([np.full(label_y.size, x0), label_y])]
    ).astype(np.float32)
    labels = [f"x {x + 0.0:g} m" for x in label_x] + [f"y {0.0 - y:g} m" for y in label_y]
    return [
        (
            f"{PLAN}/grid/minor",
            rr.LineStrips2D(lines(xs[~_major(xs)], ys[~_major(ys)]), colors=[GRID_RGBA], radii=-0.5),
        ),
        (f"{PLAN}/grid/major", rr.LineStrips2D(lines(label_x, major_y), colors=[GRID_MAJOR_RGBA], radii=-1.0)),
        (f"{PLAN}/grid/labels", rr.Points2D(positions, labels=labels, radii=-2.0, colors=[GRID_MAJOR_RGBA])),
    ]


def _major(values_m: F64) -> NDArray[np.bool_]:
    """Which grid values are multiples of :data:`LABEL_STEP_M`."""
    r = np.mod(values_m, LABEL_STEP_M)
    return np.asarray(np.isclose(r, 0.0) | np.isclose(r, LABEL_STEP_M))


def step_columns(t_s: F64, pos_n_m: F64, cov_n_m2: F64, paths: PlanPaths, *, sigma_scale: float) -> list[SendColumns]:
    """The plan's step markers and ellipses for steps at ``t_s`` (k,) (empty if none)."""
    if t_s.size == 0:
        return []
    index = time_column(t_s)
    strips = ellipse_strips(pos_n_m, cov_n_m2, sigma_scale=sigma_scale)
    return [
        (paths.steps, index, rr.Points2D.columns(positions=to_plan(pos_n_m))),
        (paths.step_cov, index, rr.LineStrips2D.columns(strips=list(strips))),
    ]


def line_archetypes(points_n_m: F32, paths: PlanPaths) -> list[tuple[str, rr.AsComponents]]:
    """The decimated track from above, its start and its current end."""
    plan = to_plan(points_n_m)
    return [
        (paths.line, rr.LineStrips2D([plan])),
        (
            paths.ends,
            rr.Points2D([plan[0], plan[-1]], labels=["start", "end"], colors=[START_RGB, END_RGB], radii=-4.0),
        ),
    ]
