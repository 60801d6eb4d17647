"""footnav's default Rerun blueprint (layout) and the static styling logged once per recording.

Layout, sized for a laptop screen::

    ┌──────────────────────────────┬───────────────────────┐
    │                              │ Foot clearance [m]    │
    │  3D: foot track (trail up to │ Stance                │
    │  the cursor), pose, k-sigma  │ [Position σ | Detector│
    │  ellipsoid, ground truth     │  | Gait | Events]     │
    └──────────────────────────────┴───────────────────────┘

The track is a per-sample Points3D entity drawn as a trail by a per-entity visible time range
(−inf … cursor), so the growing track is never re-logged. Everything else in the 3D view is
latest-at the cursor: one pose, one ellipsoid.
"""

from __future__ import annotations

from collections.abc import Sequence

import rerun as rr
import rerun.blueprint as rrb

from views.paths import (
    EVENTS,
    FLOOR,
    GAIT,
    PLOTS,
    TIMELINE,
    TRUTH,
    WORLD,
    FootPaths,
)

PLOT_WINDOW_S = 10.0
"""Clearance and stance plots show this many seconds before the cursor."""

TRACK_RADIUS_M = 0.004
TRUTH_RADIUS_M = 0.003
SHOE_HALF_SIZE_M = (0.13, 0.05, 0.035)
"""Half-size of the box drawn at the IMU pose (x forward along the shoe, z up in the body frame)."""
AXES_LENGTH_M = 0.15

SWING_RGB = (255, 140, 0)
STANCE_RGB = (0, 160, 255)
TRUTH_RGB = (150, 150, 150)
COV_RGBA = (255, 200, 0, 110)
FLOOR_RGBA = (110, 110, 110, 60)

FOOT_COLORS: dict[str, tuple[int, int, int]] = {
    "foot": (0, 200, 120),
    "left": (0, 160, 255),
    "right": (230, 80, 60),
}


def foot_color(foot: str) -> tuple[int, int, int]:
    """Series colour of a foot (a fixed palette; unknown names get the default colour)."""
    return FOOT_COLORS.get(foot, FOOT_COLORS["foot"])


def _trail() -> rrb.VisibleTimeRanges:
    return rrb.VisibleTimeRanges(
        rrb.VisibleTimeRange(
            TIMELINE, start=rrb.TimeRangeBoundary.infinite(), end=rrb.TimeRangeBoundary.cursor_relative()
        )
    )


def _window(seconds: float) -> rrb.VisibleTimeRange:
    return rrb.VisibleTimeRange(
        TIMELINE,
        start=rrb.TimeRangeBoundary.cursor_relative(seconds=-seconds),
        end=rrb.TimeRangeBoundary.cursor_relative(),
    )


def build_blueprint(
    feet: Sequence[str] = ("foot",), *, plot_window_s: float = PLOT_WINDOW_S
) -> rrb.Blueprint:
    """The default blueprint for a session with the given feet.

    Args:
        feet: foot names (see :class:`views.paths.FootPaths`); the camera follows the first one.
        plot_window_s: width of the scrolling clearance/stance window, s.
    """
    paths = [FootPaths(f) for f in feet]
    overrides: dict[str, list[rrb.VisibleTimeRanges | rr.Points3D]] = {}
    for p in paths:
        overrides[p.track] = [_trail(), rr.Points3D.from_fields(radii=TRACK_RADIUS_M, show_labels=False)]
        overrides[p.truth] = [_trail(), rr.Points3D.from_fields(radii=TRUTH_RADIUS_M, show_labels=False)]
    scene = rrb.Spatial3DView(
        name="Foot track",
        origin=f"/{WORLD}",
        overrides=overrides,  # type: ignore[arg-type]  # dict is invariant; values are VisualizerLike
        eye_controls=rrb.EyeControls3D(eye_up=[0, 0, 1], tracking_entity=f"/{paths[0].pose}"),
    )
    window = _window(plot_window_s)
    plots = rrb.Vertical(
        rrb.TimeSeriesView(name="Foot clearance [m]", origin=f"/{PLOTS}/clearance", time_ranges=window),
        rrb.TimeSeriesView(
            name="Stance",
            origin=f"/{PLOTS}/stance",
            time_ranges=window,
            axis_y=rrb.ScalarAxis(range=(-0.1, 1.1), zoom_lock=True),
        ),
        rrb.Tabs(
            rrb.TimeSeriesView(name="Position σ [m]", origin=f"/{PLOTS}/pos_sigma"),
            rrb.TimeSeriesView(name="ZUPT detector", origin=f"/{PLOTS}/detector", time_ranges=window),
            rrb.StateTimelineView(name="Gait", origin=f"/{GAIT}"),
            rrb.TextLogView(name="Events", origin=f"/{EVENTS}"),
        ),
        row_shares=[2, 1, 2],
    )
    return rrb.Blueprint(
        rrb.Horizontal(scene, plots, column_shares=[3, 2]),
        rrb.TimePanel(state="collapsed", timeline=TIMELINE, play_state="following"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        collapse_panels=False,
    )


def static_setup(feet: Sequence[str] = ("foot",)) -> list[tuple[str, rr.AsComponents]]:
    """Static ``(entity, archetype)`` pairs to log once, before any streamed data.

    Styling goes on the entities that carry the data but only on *other* components than the streamed
    ones (SeriesLines/SeriesPoints next to Scalars, colours next to positions), so nothing temporal
    is shadowed by a static value.
    """
    out: list[tuple[str, rr.AsComponents]] = [
        (WORLD, rr.ViewCoordinates.RIGHT_HAND_Z_UP),
        (WORLD, rr.AnnotationContext([(0, "swing", SWING_RGB), (1, "stance", STANCE_RGB)])),
        (TRUTH, rr.AnnotationContext([(0, "truth", TRUTH_RGB)])),
    ]
    for foot in feet:
        p = FootPaths(foot)
        rgb = foot_color(foot)
        out += [
            (p.pose, rr.TransformAxes3D(AXES_LENGTH_M)),
            (p.shoe, rr.Boxes3D(half_sizes=[SHOE_HALF_SIZE_M], colors=[(*rgb, 140)], fill_mode="solid")),
            (
                p.cov,
                rr.Ellipsoids3D.from_fields(colors=[COV_RGBA], fill_mode="majorwireframe", line_radii=0.002),
            ),
            (p.truth, rr.Points3D.from_fields(colors=[TRUTH_RGB])),
            (p.clearance, rr.SeriesLines(names=f"{foot} clearance", colors=[rgb], widths=1.5)),
            (p.stance, rr.SeriesLines(names=f"{foot} stance", colors=[rgb], widths=1.5)),
            (
                p.pos_sigma,
                rr.SeriesLines(
                    names=[f"{foot} σx", f"{foot} σy", f"{foot} σz", f"{foot} √trace"],
                    colors=[(230, 80, 60), (60, 180, 75), (0, 130, 200), (120, 120, 120)],
                    widths=1.5,
                ),
            ),
            (
                p.detector,
                rr.SeriesLines(
                    names=[f"{foot} statistic", f"{foot} threshold"],
                    colors=[rgb, (200, 0, 0)],
                    widths=[1.0, 1.0],
                ),
            ),
            (
                p.gait,
                rr.StateConfiguration(
                    values=["stance", "swing"],
                    colors=[(*STANCE_RGB, 255), (*SWING_RGB, 255)],
                ),
            ),
        ]
    return out


def floor_patch(floor_z_m: float, *, center_xy: tuple[float, float] = (0.0, 0.0)) -> tuple[str, rr.Boxes3D]:
    """Static 4 m × 4 m translucent patch of the floor the walk started on, at height ``floor_z_m``."""
    return FLOOR, rr.Boxes3D(
        centers=[(center_xy[0], center_xy[1], floor_z_m - 0.001)],
        half_sizes=[(2.0, 2.0, 0.001)],
        colors=[FLOOR_RGBA],
        fill_mode="solid",
    )
