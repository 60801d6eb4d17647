"""The Rerun logger: one thread, fed by a bounded queue, batching NavBatches into ``send_columns``.

Callers (the asyncio pipeline included) only enqueue: :meth:`RerunLogger.put` never blocks by
default. Every Rerun call — sink set-up, static setup, ``send_columns``, flush, disconnect — happens
on the logger's own daemon thread, so the event loop never waits on the viewer or the disk.

Drop policy: the queue is bounded by a sample budget (default 120 000 samples, two minutes of 1 kHz,
about 25 MB). At 1 kHz the thread needs a few % of one core, so the budget only fills when a sink
stalls (e.g. a viewer that stopped reading) or when a replay runs far faster than real time. Then
``put`` drops the batch, counts it in :class:`LoggerStats` and the logger writes an ERROR entry to
``events`` in the recording, so the loss is visible in the viewer and the file. A producer that may
run ahead (as-fast-as-possible replay, off the event loop) can pass ``timeout_s`` to wait for room
instead of dropping. The estimator and the capture never depend on this queue.
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from types import TracebackType

import numpy as np
import rerun as rr
from footnav.pipeline.nav_types import ClearanceSeries, NavBatch, concat_batches
from footnav.views import convert, plan
from footnav.views.blueprint import build_blueprint, floor_patch, static_setup
from footnav.views.dual_imu import DualRunView, dual_columns, static_styles
from footnav.views.paths import DEFAULT_FOOT, EVENTS, STRIDES, TIMELINE, DualPaths, FootPaths, PlanPaths
from footnav.views.strides import StrideTable
from numpy.typing import NDArray
from rerun.sinks import LogSinkLike

log = logging.getLogger(__name__)

_STALLED_RECORDINGS: list[rr.RecordingStream] = []
"""Streams whose sink stalled on close; never released (see ``RerunLogger.close``)."""

APPLICATION_ID = "footnav"
FLUSH_PERIOD_S = 0.15
"""The viewer is updated about 7 times a second: every flush costs a fixed amount per entity, and at
0.1 s two feet at 1 kHz took 30.5 % of a core against 28.4 % at 0.15 s (``benchmarks.e2e``)."""
FILE_FLUSH_PERIOD_S = 2.0
"""A recording file's logger flushes this often: the ``.rrd`` footer keeps an index entry per chunk in
memory until the file closes (about 2 kB each; ~14 MB per minute of two feet at 0.15 s flushes, under
1 MB at 2 s), and larger chunks cost less CPU per sample."""
MAX_ROWS_PER_SEND = 20_000
DEFAULT_MAX_QUEUED_SAMPLES = 60_000
"""Samples a logger may hold (about 330 bytes each): 30 s of two feet at 1 kHz behind a stalled viewer
before samples are dropped (and counted); a replay waits for room instead."""
DEFAULT_ELLIPSOID_EVERY = 10
"""Ellipsoid decimation: 100 Hz at 1 kHz, visually the same, ~25 % smaller files than every sample."""
CLOSE_TIMEOUT_S = 10.0
DEFAULT_SERIES_EVERY = 10
"""Speed and heading are plotted at 100 Hz of a 1 kHz stream (every 10th sample)."""
SMOOTHED_EVERY = 10
"""The step-smoothed track and clearance are logged for every 10th sample (100 Hz of a 1 kHz stream:
the same trail and plot, a tenth of the file and the logging)."""
LINE_PERIOD_S = 0.5
"""The decimated track line is re-logged at most this often, in device time and in wall time (≤ 2 Hz)."""
DUAL_TRACK_EVERY = 10
"""A dual-IMU board's per-IMU tracks are logged every this many samples."""


@dataclass(frozen=True, slots=True)
class _Event:
    text: str
    level: str
    t_s: float | None


@dataclass(frozen=True, slots=True)
class _Truth:
    foot: str
    t_s: NDArray[np.float64]
    pos_n_m: NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class _SwingRest:
    foot: str
    series: ClearanceSeries


@dataclass(frozen=True, slots=True)
class _Dual:
    run: str
    view: DualRunView


@dataclass(frozen=True, slots=True)
class _Nav:
    foot: str
    nav: NavBatch


@dataclass(frozen=True, slots=True)
class _Link:
    foot: str
    t_s: float
    rate_hz: float
    lost_packets: int
    reconnects: int
    clock_rate_hz: float


_STOP = object()


@dataclass(slots=True)
class LoggerStats:
    """Counters of one :class:`RerunLogger` (read them any time; exact after :meth:`RerunLogger.close`).

    Attributes
    ----------
    samples_in
        samples accepted by ``put``.
    samples_logged
        samples handed to ``send_columns``.
    samples_dropped
        samples refused by ``put`` because the queue was full (or after close).
    batches_dropped
        NavBatches refused.
    sends
        ``send_columns`` rounds (one per ~100 ms flush).
    send_seconds
        time spent converting and in ``send_columns``, s.
    max_queued_samples
        high-water mark of the queue, samples.
    error
        first exception raised on the logger thread (the thread keeps draining after it).
    """

    samples_in: int = 0
    samples_logged: int = 0
    samples_dropped: int = 0
    batches_dropped: int = 0
    sends: int = 0
    send_seconds: float = 0.0
    max_queued_samples: int = 0
    error: BaseException | None = None


class RerunLogger:
    """Logs NavBatches to Rerun sinks from one background thread.

    Parameters
    ----------
    sinks
        where the recording goes (see :func:`footnav.views.outputs.open_session_views`); at least one.
    recording_id
        one id per walking session; files and viewers merge streams with equal ids.
    feet
        foot names that will be logged (sets up blueprint and static styling).
    sigma_scale
        covariance ellipsoids are drawn at this many σ.
    ellipsoid_every
        log the ellipsoid every n-th sample (1 = every sample, 0 = never).
    series_every
        log speed and heading every n-th sample.
    max_queued_samples
        queue budget; beyond it ``put`` drops (see module docstring).
    flush_period_s
        batching period of the thread.
    dual_runs
        dual-IMU boards that :meth:`log_dual` will be given (blueprint: trails and a plot).
    verify_writes
        wait for each flush to be written; after a failure (a full disk: ``stats.error``) discard what comes.

    Raises
    ------
    ValueError
        no sinks given.
    """

    def __init__(
        self,
        sinks: Sequence[LogSinkLike],
        *,
        recording_id: str,
        feet: Sequence[str] = (DEFAULT_FOOT,),
        sigma_scale: float = convert.DEFAULT_SIGMA_SCALE,
        ellipsoid_every: int = DEFAULT_ELLIPSOID_EVERY,
        series_every: int = DEFAULT_SERIES_EVERY,
        max_queued_samples: int = DEFAULT_MAX_QUEUED_SAMPLES,
        flush_period_s: float = FLUSH_PERIOD_S,
        dual_runs: Sequence[str] = (),
        tof: bool = False,
        truth: bool = False,
        verify_writes: bool = False,
    ) -> None:
        if not sinks:
            raise ValueError("RerunLogger needs at least one sink (a viewer or a file); none were given")
        self.recording_id = recording_id
        self.feet = tuple(feet)
        self.dual_runs = tuple(dual_runs)
        self.tof, self.truth = tof, truth
        self._strides = StrideTable(self.feet)
        self._dual_styled: set[str] = set()
        self._paths = {f: FootPaths(f) for f in self.feet}
        self._sinks = tuple(sinks)
        self._sigma_scale = sigma_scale
        self._ellipsoid_every = ellipsoid_every
        self._series_every = series_every
        self._max_queued = max_queued_samples
        self._flush_period_s, self._verify_writes, self._write_failed = flush_period_s, verify_writes, False
        self.stats = LoggerStats()

        self.recording = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id)
        self._queue: queue.SimpleQueue[object] = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._room = threading.Condition(self._lock)
        self._queued = 0
        self._waiting = 0  # producers blocked in put(timeout_s>0): flush at once rather than on the tick
        self._closed = False
        self._reported_drops = 0
        self._last_t_s: float | None = None
        self._last_stance: dict[str, bool | None] = dict.fromkeys(self.feet)
        self._foot_samples: dict[str, int] = dict.fromkeys(self.feet, 0)
        self._floor_logged = False
        self._lines: dict[str, plan.DecimatedLine] = {f: plan.DecimatedLine([]) for f in self.feet}
        self._grid: tuple[float, float, float, float] | None = None  # the plan view's grid bounds, plan axes, m
        self._truths: dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]] = {}
        """Per foot: the ground truth's times (n,) and positions (n, 3), once logged."""
        self._heading_deg: dict[str, float] = {}
        """Per foot: the last heading logged, degrees (the plot is a continuous turn)."""
        self._steps: dict[str, int] = dict.fromkeys(self.feet, 0)
        self._tof_totals: dict[str, np.ndarray] = {}
        """Per foot: ToF readings since the start [used, gated, invalid status] (``convert.tof_columns``)."""
        self._thread = threading.Thread(target=self._run, name="footnav-rerun", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ producer side (any thread)

    def put(self, nav: NavBatch, *, foot: str = DEFAULT_FOOT, timeout_s: float = 0.0) -> bool:
        """Queue a batch for logging; returns False if it was dropped (counted in :attr:`stats`).

        With ``timeout_s == 0`` (the default) this never blocks: safe on the event loop.
        """
        self._check_foot(foot)
        n = len(nav)
        if n == 0:
            return True
        with self._room:
            if not self._closed and self._queued + n > self._max_queued and timeout_s > 0:
                self._waiting += 1
                try:
                    self._room.wait_for(lambda: self._closed or self._has_room(n), timeout_s)
                finally:
                    self._waiting -= 1
            if self._closed or self._queued + n > self._max_queued:
                self.stats.samples_dropped += n
                self.stats.batches_dropped += 1
                return False
            self._queued += n
            self.stats.samples_in += n
            self.stats.max_queued_samples = max(self.stats.max_queued_samples, self._queued)
        self._queue.put(_Nav(foot, nav))
        return True

    def _check_foot(self, foot: str) -> None:
        if foot not in self._paths:
            raise ValueError(f"foot {foot!r} was not declared; this logger has feet={self.feet}")

    def _has_room(self, n: int) -> bool:
        return self._queued + n <= self._max_queued

    def log_event(self, text: str, *, level: str = "INFO", t_s: float | None = None) -> None:
        """Log a text event at device time ``t_s`` (default: the newest sample time seen). Never blocks."""
        if not self._closed:
            self._queue.put(_Event(text, level, t_s))

    def log_dual(self, view: DualRunView, *, run: str) -> None:
        """Queue a dual-IMU board's tracks and constraint residuals (:mod:`footnav.views.dual_imu`); not
        counted against the sample budget (a tenth of the tracks' points and a few residual rows)."""
        with self._lock:
            if not self._closed:
                self._queue.put(_Dual(run, view))

    def log_truth(self, pos_n_m: NDArray[np.float64], *, t_s: NDArray[np.float64], foot: str = DEFAULT_FOOT) -> None:
        """Log a ground-truth track: positions (n, 3), m, at device times (n,), s. Never blocks."""
        self._check_foot(foot)
        if not self._closed:
            self._queue.put(_Truth(foot, np.asarray(t_s, np.float64), np.asarray(pos_n_m, np.float64)))

    def log_swing_clearance(self, series: ClearanceSeries, *, foot: str = DEFAULT_FOOT) -> None:
        """Log whole-swing clearance values that came after the foot's last batch (the session's end:
        ``GaitEventTracker.finish``). Never blocks."""
        self._check_foot(foot)
        if not self._closed:
            self._queue.put(_SwingRest(foot, series))

    def log_link(
        self,
        *,
        foot: str = DEFAULT_FOOT,
        t_s: float,
        rate_hz: float,
        lost_packets: int,
        reconnects: int = 0,
        clock_rate_hz: float = math.nan,
    ) -> None:
        """Log link health at device time ``t_s``: samples received per second of host time, the rate by
        the unit's clock (NaN: not measured yet), cumulative lost packets and reconnects. Never blocks."""
        self._check_foot(foot)
        if not self._closed:
            self._queue.put(_Link(foot, t_s, rate_hz, lost_packets, reconnects, clock_rate_hz))

    @property
    def steps(self) -> dict[str, int]:
        """Steps logged per foot so far."""
        return dict(self._steps)

    def close(self, timeout_s: float = CLOSE_TIMEOUT_S) -> bool:
        """Log what is queued, flush, disconnect the sinks (file footers written), join the thread.

        Returns False if the thread did not finish within ``timeout_s`` (a stalled sink); the data
        already written stays readable.
        """
        with self._room:
            if self._closed:
                return not self._thread.is_alive()
            self._closed = True
            self._room.notify_all()
        self._queue.put(_STOP)
        self._thread.join(timeout_s)
        if self._thread.is_alive():
            log.error("Rerun logger did not finish within %.1f s; a sink may be stalled", timeout_s)
            # Once unreferenced, the SDK would sweep this "orphaned" stream from whichever thread
            # next deletes any RecordingStream, and disconnecting a sink that cannot deliver blocks
            # that thread for good. Keeping a reference keeps it out of the sweep.
            _STALLED_RECORDINGS.append(self.recording)
            return False
        return True

    def __enter__(self) -> RerunLogger:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    # ------------------------------------------------------------------ logger thread

    def _run(self) -> None:
        rec = self.recording
        try:
            blueprint = build_blueprint(
                self.feet, dual_runs=self.dual_runs, tof=self.tof, truth=self.truth, sigma_scale=self._sigma_scale
            )
            rec.set_sinks(*self._sinks, default_blueprint=blueprint)
            for path, archetype in static_setup(self.feet):
                rec.log(path, archetype, static=True)
        except Exception as exc:  # no usable sink: drain and discard rather than buffer in memory
            self._record_error(exc)
            self._discard_until_stop()
            return
        pending: dict[str, list[NavBatch]] = {f: [] for f in self.feet}
        events: list[_Event] = []
        links: list[_Link] = []
        n_pending = 0
        deadline: float | None = None
        while True:
            timeout = None if deadline is None else max(0.0, deadline - time.monotonic())
            try:
                item = self._queue.get(timeout=timeout)
            except queue.Empty:
                item = None
            if isinstance(item, _Nav):
                pending[item.foot].append(item.nav)
                n_pending += len(item.nav)
            elif isinstance(item, _Event):
                events.append(item)
            elif isinstance(item, _Link):
                links.append(item)
                if len(links) >= 64:
                    self._guarded(self._send_links, links)
            elif isinstance(item, _Dual | _Truth | _SwingRest):
                if not isinstance(item, _Dual):  # after the earlier batches
                    self._flush(pending, events)
                    n_pending, deadline = 0, None
                self._send_apart(item)
                continue
            stop = item is _STOP
            if deadline is None and item is not None and not stop:
                deadline = time.monotonic() + self._flush_period_s
            if stop or item is None or n_pending >= MAX_ROWS_PER_SEND or (n_pending and self._waiting):
                self._flush(pending, events)
                if links:
                    self._guarded(self._send_links, links)
                n_pending, deadline = 0, None
            if stop:
                break
        self._guarded(self._send_lines, True)
        self._guarded(self._finish)

    def _check_written(self) -> bool:
        """Wait for the sinks to write; True if they failed: the error is kept and the stream parked (sends to
        a file sink whose writer died may block for good), what comes goes to a disabled stream."""
        try:
            self.recording.flush(timeout_sec=CLOSE_TIMEOUT_S)
        except Exception as exc:
            self._write_failed, self.stats.error = True, self.stats.error or exc
            _STALLED_RECORDINGS.append(self.recording)
            self.recording = rr.RecordingStream(APPLICATION_ID, recording_id=self.recording_id, default_enabled=False)
        return self._write_failed

    def _send_apart(self, item: _Dual | _Truth | _SwingRest) -> None:
        """The items sent as they come, not held for the next flush."""
        if isinstance(item, _Dual):
            self._guarded(self._send_dual, item)
        elif isinstance(item, _Truth):
            self._guarded(self._send_truth, item)
        else:
            self._guarded(self._send_swing_rest, item)

    def _discard_until_stop(self) -> None:
        while (item := self._queue.get()) is not _STOP:
            if isinstance(item, _Nav):
                with self._room:
                    self._queued -= len(item.nav)
                    self.stats.samples_dropped += len(item.nav)
                    self._room.notify_all()

    def _flush(self, pending: dict[str, list[NavBatch]], events: list[_Event]) -> None:
        start = time.perf_counter()
        n_done = 0
        for foot, batches in pending.items():
            if not batches:
                continue
            n = sum(len(b) for b in batches)
            try:
                self._send_nav(foot, concat_batches(batches))
            except Exception as exc:
                self._record_error(exc)
            batches.clear()
            n_done += n
        with self._room:
            self._queued -= n_done
            self.stats.samples_logged += n_done
            dropped = self.stats.samples_dropped
            self._room.notify_all()
        if dropped > self._reported_drops:
            events.append(
                _Event(
                    f"viewer/recording fell behind: {dropped - self._reported_drops} samples not logged "
                    f"({dropped} in total); the capture and the estimates are unaffected",
                    "ERROR",
                    None,
                )
            )
            self._reported_drops = dropped
        if events:
            self._guarded(self._send_events, events)
            events.clear()
        if n_done:
            self._guarded(self._send_lines, False)
            self.stats.sends += 1
            self.stats.send_seconds += time.perf_counter() - start
        if self._verify_writes:
            self._check_written()

    def _send_nav(self, foot: str, nav: NavBatch) -> None:
        paths = self._paths[foot]
        rec = self.recording
        arrays = convert.nav_arrays(nav, sigma_scale=self._sigma_scale, heading_before_deg=self._heading_deg.get(foot))
        if arrays.heading.size:
            self._heading_deg[foot] = float(arrays.heading[-1])
        if not self._floor_logged:
            floor_z = float(arrays.pos[0, 2] - arrays.clearance[0])
            if np.isfinite(floor_z):
                rec.log(
                    *floor_patch(floor_z, center_xy=(float(arrays.pos[0, 0]), float(arrays.pos[0, 1]))),
                    static=True,
                )
                self._floor_logged = True
        first = self._foot_samples[foot]
        columns_list = convert.nav_columns(
            arrays, paths, ellipsoid_every=self._ellipsoid_every, first_index=first, series_every=self._series_every
        )
        onsets = nav.step_onsets if nav.step_onsets is not None else np.zeros(0, dtype=np.intp)
        columns_list += convert.step_columns(arrays, nav.pos_cov_n_m2, onsets, paths, sigma_scale=self._sigma_scale)
        columns_list += plan.step_columns(
            arrays.t_s[onsets],
            nav.pos_n_m[onsets],
            nav.pos_cov_n_m2[onsets],
            PlanPaths(foot),
            sigma_scale=self._sigma_scale,
        )
        columns_list += convert.tof_columns(nav, paths, self._tof_totals.setdefault(foot, np.zeros(3, np.int64)))
        if nav.smoothed is not None:
            columns_list += convert.smoothed_columns(nav.smoothed, paths, every=SMOOTHED_EVERY)
        if nav.swing_clearance is not None:
            columns_list += convert.series_columns(paths.swing_clearance, *nav.swing_clearance)
        if (truth := self._truths.get(foot)) is not None:
            every = slice((-first) % max(1, self._series_every), None, max(1, self._series_every))
            error = convert.horizontal_error_m(arrays.t_s[every], nav.pos_n_m[every], *truth)
            columns_list += convert.series_columns(paths.truth_error, arrays.t_s[every], error)
        for path, index, columns in columns_list:
            rec.send_columns(path, indexes=[index], columns=columns)
        self._steps[foot] += int(onsets.size)
        self._lines[foot].add(arrays.t_s, arrays.pos)
        self._foot_samples[foot] += len(nav)
        gait = convert.gait_columns(arrays.t_s, nav.stance, paths, previous=self._last_stance[foot])
        if gait is not None:
            rec.send_columns(gait[0], indexes=[gait[1]], columns=gait[2])
        self._last_stance[foot] = bool(nav.stance[-1])
        self._last_t_s = max(float(arrays.t_s[-1]), self._lines[foot].last_t_s)  # a lead-in filled in ends before
        if self._strides.update(foot, nav):
            rec.set_time(TIMELINE, duration=self._last_t_s)
            rec.log(STRIDES, rr.TextDocument(self._strides.markdown(), media_type=rr.MediaType.MARKDOWN))

    def _send_events(self, events: list[_Event]) -> None:
        default_t = self._last_t_s if self._last_t_s is not None else 0.0
        t = np.array([default_t if e.t_s is None else e.t_s for e in events], dtype=np.float64)
        self.recording.send_columns(
            EVENTS,
            indexes=[convert.time_column(t)],
            columns=rr.TextLog.columns(text=[e.text for e in events], level=[e.level for e in events]),
        )

    def _send_links(self, links: list[_Link]) -> None:
        by_foot: dict[str, list[_Link]] = {}
        for item in links:
            by_foot.setdefault(item.foot, []).append(item)
        links.clear()
        for foot, items in by_foot.items():
            paths = self._paths[foot]
            index = convert.time_column(np.array([i.t_s for i in items], dtype=np.float64))
            rates = np.array([[i.rate_hz, i.clock_rate_hz] for i in items], dtype=np.float64)
            self.recording.send_columns(paths.rate, indexes=[index], columns=rr.Scalars.columns(scalars=rates))
            errors = np.array([[i.lost_packets, i.reconnects] for i in items], dtype=np.float64)
            self.recording.send_columns(paths.link_errors, indexes=[index], columns=rr.Scalars.columns(scalars=errors))

    def _send_lines(self, final: bool) -> None:
        """Re-log each foot's decimated track line, in 3D and in the plan view (with its grid), if it grew
        and ≥ LINE_PERIOD_S passed (device and wall)."""
        now = time.monotonic()
        rec = self.recording
        for foot, line in self._lines.items():
            if not line.dirty or len(line.points) < 2:
                continue
            t = line.last_t_s
            if not final and (t - line.logged_t_s < LINE_PERIOD_S or now - line.logged_wall < LINE_PERIOD_S):
                continue
            points = np.asarray(line.points, dtype=np.float32)
            rec.set_time(TIMELINE, duration=t)
            rec.log(self._paths[foot].line, rr.LineStrips3D([points]))
            for entity, archetype in plan.line_archetypes(points, PlanPaths(foot)):
                rec.log(entity, archetype)
            if (grid := plan.grid_bounds(plan.to_plan(points), self._grid)) is not None:
                self._grid = grid
                for entity, archetype in plan.grid_archetypes(grid):
                    rec.log(entity, archetype)
            line.logged_t_s, line.logged_wall, line.dirty = t, now, False

    def _send_dual(self, item: _Dual) -> None:
        paths = DualPaths(item.run)
        if item.run not in self._dual_styled:
            for entity, archetype in static_styles(item.view, paths):
                self.recording.log(entity, archetype, static=True)
            self._dual_styled.add(item.run)
        for entity, index, columns in dual_columns(item.view, paths, track_every=DUAL_TRACK_EVERY):
            self.recording.send_columns(entity, indexes=[index], columns=columns)

    def _send_truth(self, truth: _Truth) -> None:
        self._truths[truth.foot] = (truth.t_s, truth.pos_n_m)
        self.recording.send_columns(
            self._paths[truth.foot].truth,
            indexes=[convert.time_column(truth.t_s)],
            columns=rr.Points3D.columns(positions=truth.pos_n_m.astype(np.float32)),
        )
        if truth.t_s.size:  # the whole path from its first time on, from above
            self.recording.set_time(TIMELINE, duration=float(truth.t_s[0]))
            self.recording.log(PlanPaths(truth.foot).truth, rr.LineStrips2D([plan.to_plan(truth.pos_n_m)]))

    def _send_swing_rest(self, item: _SwingRest) -> None:
        for path, index, columns in convert.series_columns(self._paths[item.foot].swing_clearance, *item.series):
            self.recording.send_columns(path, indexes=[index], columns=columns)

    def _finish(self) -> None:
        if not (self._verify_writes and self._check_written()):
            self.recording.flush(timeout_sec=CLOSE_TIMEOUT_S)
            self.recording.disconnect()

    def _guarded(self, fn: Callable[..., None], *args: object) -> None:
        try:
            fn(*args)
        except Exception as exc:
            self._record_error(exc)

    def _record_error(self, exc: BaseException) -> None:
        log.exception("Rerun logger error (logging continues)", exc_info=exc)
        if self.stats.error is None:
            self.stats.error = exc
