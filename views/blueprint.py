"""footnav's default Rerun blueprint (layout) and the static styling logged once per recording.

Layout, sized for a laptop screen (1366×768 and up)::

    ┌──────────────────────────────┬──────────────────────────────┐
    │ Plan view: the track from    │ Foot clearance [m]           │
    │ above in metres, grid and    │ [Speed | Stance and swing |  │
    │ scale, start/end, step       │  Heading (continuous)]       │
    │ ellipses at k sigma, truth   │ [Detector (log10) | Pos. σ | │
    ├──────────────────────────────┤  ToF readings | Altitude]    │
    │ 3D: per foot the track       │ [Strides | Link rate |       │
    │ (trail + decimated line),    │  Link errors | Events]       │
    │ pose, steps with floor       │                              │
    │ ellipses, k-sigma ellipsoid  │                              │
    └──────────────────────────────┴──────────────────────────────┘

Panels appear only for what the session has (ToF panels for ToF units, a residual plot per
dual-IMU board). Colours are chosen together for the dark theme and colour-vision deficiencies
(Okabe-Ito palette): each foot its colour, stance yellow and swing grey, thresholds and markers light.

The track is a per-sample Points3D entity drawn as a trail by a per-entity visible time range
(−inf … cursor), so the growing track is never re-logged at sample rate; the decimated line is
re-logged at most twice a second. Step markers and their ellipses are trails too. Everything else in
the 3D view is latest-at the cursor: one pose, one ellipsoid. Left and right always get the same
colours (:data:`FOOT_COLORS`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import rerun as rr
import rerun.blueprint as rrb
from footnav.views.paths import (
    EVENTS,
    FLOOR,
    GAIT,
    PLAN,
    PLOTS,
    STRIDES,
    TIMELINE,
    TRUTH,
    WORLD,
    DualPaths,
    FootPaths,
    PlanPaths,
)

MULTI_SERIES = frozenset({"detector", "pos_sigma", "rate", "link_errors", "tof_readings"})
"""Plots with several series per foot: their legend is shown even for one foot."""
PLOT_WINDOW_S = 10.0
"""Clearance, stance, speed and detector plots show this many seconds before the cursor."""

TRACK_RADIUS_M = 0.004
TRUTH_RADIUS_M = 0.003
SHOE_HALF_SIZE_M = (0.13, 0.05, 0.035)
"""Half-size of the box drawn at the IMU pose (x forward along the shoe, z up in the body frame)."""
AXES_LENGTH_M = 0.15
STEP_RADIUS_M = 0.025
LINE_RADIUS_M = 0.012
FLOOR_HIT_RADIUS_M = 0.003

# Colours from the Okabe-Ito palette (distinguishable with the common colour-vision deficiencies),
# chosen together for the dark theme: the feet carry identity; stance and swing are yellow and grey.
SWING_RGB = (190, 190, 190)
STANCE_RGB = (240, 228, 66)
TRUTH_RGB = (245, 245, 245)
SMOOTHED_RGB = (204, 121, 167)
"""The step-smoothed track and clearance (``footnav.pipeline.smoothing.stepwise``)."""
TOF_RGB = ((204, 121, 167), (240, 228, 66), (86, 180, 233))
"""Colours of the three ToF sensors' measured heights (toe, mid-foot, heel)."""
TOF_PLACES = ("toe", "mid-foot", "heel")
"""Where the three ToF sensors sit on the shoe (the order of the ``[tof]`` configuration)."""
MARKER_RGB = (235, 235, 235)
COV_RGBA = (240, 228, 66, 170)
FLOOR_RGBA = (110, 110, 110, 60)
STEP_COV_ALPHA = 120

FOOT_COLORS: dict[str, tuple[int, int, int]] = {
    "foot": (0, 158, 115),
    "left": (86, 180, 233),
    "right": (213, 94, 0),
}


def foot_color(foot: str) -> tuple[int, int, int]:
    """Series colour of a foot (a fixed palette; unknown names get the default colour)."""
    return FOOT_COLORS.get(foot, FOOT_COLORS["foot"])


def _darker(rgb: tuple[int, int, int]) -> tuple[int, int, int]:
    return (rgb[0] // 2, rgb[1] // 2, rgb[2] // 2)


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
    feet: Sequence[str] = ("foot",),
    *,
    plot_window_s: float = PLOT_WINDOW_S,
    dual_runs: Sequence[str] = (),
    tof: bool = False,
    truth: bool = False,
    sigma_scale: float = 3.0,
) -> rrb.Blueprint:
    """The default blueprint for a session with the given feet.

    Parameters
    ----------
    feet
        foot names (see :class:`footnav.views.paths.FootPaths`); the camera frames the whole scene.
    plot_window_s
        width of the scrolling clearance/stance window, s.
    dual_runs
        dual-IMU boards in the session (:class:`footnav.views.paths.DualPaths`): their IMU tracks are drawn as trails
        and their constraint residuals get a plot of their own.
    tof
        the session has ToF units: their readings' and the pressure altitude's panels are shown.
    truth
        the session has a ground truth: the estimate's error from it gets a panel.
    sigma_scale
        the ellipses' size in standard deviations (stated in the plan view's title).
    """
    paths = [FootPaths(f) for f in feet]
    overrides: dict[str, list[rrb.VisibleTimeRanges | rr.Points3D | rr.Points2D]] = {}
    for f in feet:
        overrides[PlanPaths(f).steps] = [_trail(), rr.Points2D.from_fields(radii=-3.0, show_labels=False)]
        overrides[PlanPaths(f).step_cov] = [_trail()]
    for p in paths:
        overrides[p.track] = [_trail(), rr.Points3D.from_fields(radii=TRACK_RADIUS_M, show_labels=False)]
        overrides[p.truth] = [_trail(), rr.Points3D.from_fields(radii=TRUTH_RADIUS_M, show_labels=False)]
        overrides[p.smoothed] = [_trail(), rr.Points3D.from_fields(radii=TRACK_RADIUS_M, show_labels=False)]
        overrides[p.steps] = [_trail(), rr.Points3D.from_fields(radii=STEP_RADIUS_M, show_labels=False)]
        overrides[p.step_cov] = [_trail()]
        overrides[p.floor_hits] = [_trail(), rr.Points3D.from_fields(radii=FLOOR_HIT_RADIUS_M, show_labels=False)]
    for run in dual_runs:
        for imu in ("imu1", "imu2"):
            overrides[DualPaths(run).imu(imu)] = [_trail(), rr.Points3D.from_fields(radii=TRACK_RADIUS_M)]
    scene = rrb.Spatial3DView(
        name="Foot track (3D)",
        origin=f"/{WORLD}",
        overrides={k: v for k, v in overrides.items() if k.startswith(WORLD)},
        # no tracking: the viewer frames the whole walk (following the pose put the camera on the shoe)
        eye_controls=rrb.EyeControls3D(eye_up=[0, 0, 1]),
    )
    plan = rrb.Spatial2DView(
        name=f"Plan view [m], north up; step ellipses {sigma_scale:g}σ",
        origin=f"/{PLAN}",
        overrides={k: v for k, v in overrides.items() if k.startswith(PLAN)},
    )
    window = _window(plot_window_s)

    def series(name: str, quantity: str, *, windowed: bool = True, **kw: Any) -> rrb.TimeSeriesView:
        # legends on the left (older data), over the zero line of quantities that rest at zero in stance
        corner = rrb.Corner2D.LeftBottom if quantity in ("clearance", "speed") else rrb.Corner2D.LeftTop
        legend = rrb.PlotLegend(corner, visible=len(feet) > 1 or quantity in MULTI_SERIES)
        return rrb.TimeSeriesView(
            name=name,
            origin=f"/{PLOTS}/{quantity}",
            time_ranges=window if windowed else None,
            plot_legend=legend,
            **kw,
        )

    tof_panels = (
        [
            series("ToF readings (cumulative): used, gated, invalid", "tof_readings", windowed=False),
            series("Pressure altitude [m]", "altitude", windowed=False),
        ]
        if tof
        else []
    )
    plots = rrb.Vertical(
        series("Foot clearance [m]", "clearance"),
        rrb.Tabs(
            series("Speed [m/s]", "speed"),
            rrb.StateTimelineView(name="Stance and swing", origin=f"/{GAIT}", time_ranges=window),
            series("Heading [°], continuous", "heading", windowed=False),
        ),
        rrb.Tabs(
            series("ZUPT detector: log10 statistic, log10 threshold", "detector"),
            series("Position σ [m]", "pos_sigma", windowed=False),
            *([series("Error from the truth [m], horizontal", "truth_error", windowed=False)] if truth else []),
            *tof_panels,
        ),
        *[
            rrb.TimeSeriesView(
                name=f"Dual-IMU residuals ({run})", origin=f"/{DualPaths(run).plots}", time_ranges=window
            )
            for run in dual_runs
        ],
        rrb.Tabs(
            rrb.TextDocumentView(name="Strides", origin=f"/{STRIDES}"),
            series("Link: samples/s received, rate by the unit's clock", "rate", windowed=False),
            series("Link: lost packets, reconnects", "link_errors", windowed=False),
            rrb.TextLogView(name="Events", origin=f"/{EVENTS}"),
        ),
        row_shares=[3, 3, 3, *([2] * len(dual_runs)), 3],
    )
    return rrb.Blueprint(
        rrb.Horizontal(rrb.Vertical(plan, scene, row_shares=[1, 1]), plots, column_shares=[3, 2]),
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
        p, plan = FootPaths(foot), PlanPaths(foot)
        rgb = foot_color(foot)
        out += [
            (p.pose, rr.TransformAxes3D(AXES_LENGTH_M)),
            (p.shoe, rr.Boxes3D(half_sizes=[SHOE_HALF_SIZE_M], colors=[(*rgb, 140)], fill_mode="solid")),
            (
                p.cov,
                rr.Ellipsoids3D.from_fields(colors=[COV_RGBA], fill_mode="majorwireframe", line_radii=0.004),
            ),
            (p.truth, rr.Points3D.from_fields(colors=[TRUTH_RGB])),
            (p.smoothed, rr.Points3D.from_fields(colors=[SMOOTHED_RGB])),
            (p.line, rr.LineStrips3D.from_fields(colors=[rgb], radii=LINE_RADIUS_M)),
            (p.steps, rr.Points3D.from_fields(colors=[rgb])),
            (p.step_cov, rr.Ellipsoids3D.from_fields(colors=[(*rgb, STEP_COV_ALPHA)], fill_mode="solid")),
            (plan.line, rr.LineStrips2D.from_fields(colors=[rgb], radii=-1.5)),
            (plan.steps, rr.Points2D.from_fields(colors=[rgb])),
            (plan.step_cov, rr.LineStrips2D.from_fields(colors=[(*rgb, 200)], radii=-1.0)),
            (plan.truth, rr.LineStrips2D.from_fields(colors=[TRUTH_RGB], radii=-1.0)),
            (p.speed, rr.SeriesLines(names=f"{foot} speed", colors=[rgb], widths=1.5)),
            (p.heading, rr.SeriesLines(names=f"{foot} heading", colors=[rgb], widths=1.5)),
            (
                p.rate,
                rr.SeriesLines(
                    names=[f"{foot} samples/s received", f"{foot} Hz by the unit's clock"],
                    colors=[rgb, (*_darker(rgb),)],
                    widths=[1.5, 1.5],
                ),
            ),
            (
                p.link_errors,
                rr.SeriesLines(
                    names=[f"{foot} lost packets", f"{foot} reconnects"],
                    colors=[rgb, (*_darker(rgb),)],
                    widths=[1.5, 1.5],
                ),
            ),
            (p.clearance, rr.SeriesLines(names=f"{foot} clearance", colors=[rgb], widths=1.5)),
            (
                p.smoothed_clearance,
                rr.SeriesLines(names=f"{foot} clearance (step-smoothed)", colors=[SMOOTHED_RGB], widths=1.5),
            ),
            (
                p.swing_clearance,
                rr.SeriesLines(names=f"{foot} clearance (whole swing)", colors=[(*_darker(rgb),)], widths=1.0),
            ),
            (p.stance, rr.SeriesLines(names=f"{foot} stance", colors=[rgb], widths=1.5)),
            *(
                (p.tof_height(k), rr.SeriesPoints(names=f"{foot} ToF {place}", colors=[c], marker_sizes=1.5))
                for k, (place, c) in enumerate(zip(TOF_PLACES, TOF_RGB, strict=True))
            ),
            (
                p.stride_clearance,
                rr.SeriesPoints(
                    names=[f"{foot} stride min", f"{foot} stride max"],
                    colors=[MARKER_RGB, MARKER_RGB],
                    markers=["down", "up"],
                    marker_sizes=[5.0, 5.0],
                ),
            ),
            (
                p.tof_readings,
                rr.SeriesLines(
                    names=[f"{foot} used", f"{foot} gated", f"{foot} invalid status"],
                    colors=[(0, 158, 115), (213, 94, 0), (150, 150, 150)],
                    widths=1.5,
                ),
            ),
            (p.altitude, rr.SeriesLines(names=f"{foot} pressure altitude", colors=[rgb], widths=1.5)),
            (p.truth_error, rr.SeriesLines(names=f"{foot} error from the truth", colors=[rgb], widths=1.5)),
            (
                p.pos_sigma,
                rr.SeriesLines(
                    names=[f"{foot} σx", f"{foot} σy", f"{foot} σz", f"{foot} √trace"],
                    colors=[(213, 94, 0), (0, 158, 115), (0, 114, 178), (150, 150, 150)],
                    widths=1.5,
                ),
            ),
            (
                p.detector,
                rr.SeriesLines(
                    names=[f"{foot} log10 statistic", f"{foot} log10 threshold"],
                    colors=[rgb, MARKER_RGB if len(feet) == 1 else _darker(rgb)],
                    widths=[1.0, 1.5],
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
