"""Step-wise RTS smoothing, live: each step's track smoothed as soon as the foot stands again.

The causal filter's estimate in a swing uses only the samples up to it; the zero-velocity updates of
the next stance then reveal the velocity error the swing built up, and the causal track jumps there
instead of bending back over the swing. The whole-recording smoother (``footnav.pipeline.smoothing.rts``) spreads
that back, but needs the recording's end. On a foot-mounted INS almost all it gains comes from the
next stance alone: the position and heading are not observable to zero-velocity updates, so what a
stance tells about earlier samples is mostly the velocity, tilt and bias errors of the swing just
before it (docs/design/smoothing.md). So the samples since the last step are smoothed when the
next stance has lasted ``close_after_s`` (or ended, if shorter), conditioned on the data up to then:
a track one step (about a second) behind the foot, while the causal one stays as it was
(Colomar, Nilsson, Händel, "Smoothing for ZUPT-aided INSs", IPIN 2012; Suh, Park, "A smoother for
attitude and position estimation using inertial sensors with zero velocity intervals", IEEE Sensors
J. 12(5), 2012: both smooth each step between zero-velocity intervals).

How: the samples of the open *window* (since the previous close) are kept with the filter's state at
its start (a checkpoint). At a close at sample b the window is filtered again from its checkpoint,
keeping what the Rauch-Tung-Striebel backward pass needs (``smoother.store_span``: the causal filter
step for step, the stance height updates between its calls as in the navigator), and the backward
pass runs from b, where the smoothed estimate is the filtered one, down to the window's first sample
(``smoother._backward_pass``: the states alone for sessions, with the covariance for
``step_smooth_recording``). The state after b is the next window's checkpoint. The second forward
pass reproduces the causal filter bit for bit (``tests/test_step_smoother.py``), and each window's
result is the whole-recording smoother's on the recording cut at b.

Sessions ask for it with ``--step-smoothing`` or ``[filter] step_smoothing`` (``NavConfig.step_smoothing``,
``footnav.app.feet.foot_run``); it is off by default for its cost.

A window longer than ``max_window_s`` (a long stance, a foot that never stands) is closed there, to
bound the memory the backward pass needs (about 3.9 KB per sample of a window). The stance height
levels are constants here (``StanceLevelParams.level_states = 0``: the passes store the 15 error
states), as in the whole-recording smoother. ToF aiding adds floor states, so a ToF unit is
navigated without step smoothing.
"""

from __future__ import annotations

import dataclasses
from typing import cast

import numpy as np
from footnav.pipeline.aiding.tof_types import RangeBatch, TofConfig
from footnav.pipeline.nav_types import NavBatch, SmoothedSpan
from footnav.pipeline.navigation import eskf
from footnav.pipeline.navigation.navigator import NavConfig, Navigator, NavStats
from footnav.pipeline.samples import ImuBatch
from footnav.pipeline.smoothing.rts import _backward_pass, store_span
from footnav.pipeline.stance.levels import StanceLevelParams, StanceLevels, height_update
from numpy.typing import NDArray

F64 = NDArray[np.float64]

STEP_CLOSE_AFTER_S = 0.1
"""A window closes when a stance has lasted this long (or at its end, if shorter), s: the foot is
flat by then, and the stance level's update falls there too (``footnav.pipeline.stance.levels``). Chosen
before measuring; on the PyShoe trials (ARMSE-2D mean) 0 / 0.05 / 0.1 / 0.2 / 0.3 s give 0.0606 /
0.0600 / 0.0599 / 0.0600 / 0.0600 m (the whole-recording smoother 0.0591)."""
MAX_WINDOW_S = 5.0
"""A window is closed after this long without one, s (memory: 3.9 KB per sample while closing)."""

_N_INPUTS = 8  # acc, gyr, gyr_var, dt, still, T/γ, t, floor


class StepSmoothingNavigator(Navigator):
    """The causal :class:`Navigator`, whose batches also carry the step-smoothed estimates of the
    samples whose step has ended (``NavBatch.smoothed``; module docstring).

    ToF readings add floor states to the filter, which the smoothing passes do not store: the first
    one (:meth:`add_ranges`) ends the smoothing, and the navigator goes on as a causal one.

    Parameters
    ----------
    config, rate_hz, tof
        as for :class:`Navigator`.
    close_after_s
        stance time after which a window closes, s.
    max_window_s
        longest window, s.
    with_covariance
        also smooth the covariance (``SmoothedSpan.cov_pos_yaw``); it costs most of the work
        (``smoother._backward_pass``), so live sessions go without.
    """

    def __init__(
        self,
        config: NavConfig,
        rate_hz: float,
        tof: TofConfig | None = None,
        close_after_s: float = STEP_CLOSE_AFTER_S,
        max_window_s: float = MAX_WINDOW_S,
        with_covariance: bool = False,
    ) -> None:
        self._close_after_s, self._max_window_s = close_after_s, max_window_s
        super().__init__(config, rate_hz, tof=tof)
        self.with_covariance = with_covariance
        self.smoothing = True
        """False once ToF readings have arrived (class docstring)."""
        self.level_updates = []
        self._checkpoint: tuple[F64, F64, int, NDArray[np.int64]] | None = None  # x, P, level updates, filter state
        self._window_start = 0  # index of the open window's first sample (0: first after alignment)
        self._pieces: list[tuple[int, tuple[NDArray[np.generic], ...]]] = []  # (first index, inputs)
        self._work = np.empty((2, eskf.N_STATE))
        self.closes: list[int] = []
        """Index of each window's last sample, in order (0: the first sample after alignment; one
        number per step)."""
        _load_kernels()

    def _init_rate(self, rate_hz: float) -> None:
        super()._init_rate(rate_hz)
        self.levels = StanceLevels(StanceLevelParams(use=self.config.stance_levels, level_states=0), rate_hz)
        self.close_after = max(1, round(self._close_after_s * rate_hz))
        self.max_window = max(self.close_after + 1, round(self._max_window_s * rate_hz))

    def add_ranges(self, readings: RangeBatch) -> None:
        if len(readings) and self.smoothing:
            self.smoothing = False
            self._pieces, self._checkpoint = [], None
        super().add_ranges(readings)

    def finish(self) -> SmoothedSpan | None:
        """Close the open window at the last sample navigated (the end of a session or recording):
        its smoothed estimates, or None when there is none."""
        end = self.stats.samples_out - 1
        if self._checkpoint is None or end < self._window_start:
            return None
        return self._close(end)

    def _run(self, batch: ImuBatch, stat: F64, threshold: F64, still: NDArray[np.bool_]) -> NavBatch:
        assert self._x is not None
        if not self.smoothing:
            return super()._run(batch, stat, threshold, still)
        if self._checkpoint is None:
            self._checkpoint = (self._x.copy(), self._P.copy(), 0, self._filter_state.copy())
        first = self.stats.samples_out
        run0 = int(self._filter_state[eskf.STATE_STANCE_RUN])  # stance samples in a row before this batch
        out = super()._run(batch, stat, threshold, still)
        assert self._filter_inputs is not None
        self._pieces.append((first, (*self._filter_inputs, batch.t_s, out.pos_n_m[:, 2] - out.clearance_m)))
        closes = self._closes(first, still, run0)
        if not closes:
            return out
        return dataclasses.replace(out, smoothed=SmoothedSpan.concat([self._close(b) for b in closes]))

    def _closes(self, first: int, still: NDArray[np.bool_], run0: int) -> list[int]:
        """Indices of the samples after which windows close in a batch starting at sample ``first``,
        after ``run0`` stance samples in a row."""
        n, close_after = still.shape[0], self.close_after
        candidates: list[int] = []
        if still.all():  # most live batches are all stance or all swing: no arrays needed
            if run0 < close_after <= run0 + n:
                candidates = [first + close_after - run0 - 1]
        elif not still.any():
            if 0 < run0 < close_after:  # a short stance ended with the previous batch
                candidates = [first - 1]
        else:
            k = np.arange(n)
            last_swing = np.maximum.accumulate(np.where(still, -1, k))
            run = np.where(still, k - last_swing + np.where(last_swing < 0, run0, 0), 0)
            previous = np.concatenate([[run0], run[:-1]])
            at = np.flatnonzero(run == close_after)  # the stance has lasted close_after samples
            ended = np.flatnonzero(~still & (previous > 0) & (previous < close_after)) - 1  # a short one ended
            candidates = sorted(int(c) + first for c in np.concatenate([at, ended]))
        closes: list[int] = []
        start = self._window_start
        for b in candidates:
            while b - start + 1 > self.max_window:
                start += self.max_window
                closes.append(start - 1)
            if b >= start:
                closes.append(b)
                start = b + 1
        while first + n - start >= self.max_window:  # the window has reached its longest
            start += self.max_window
            closes.append(start - 1)
        return closes

    def _close(self, b: int) -> SmoothedSpan:
        """Smooth the open window up to sample ``b`` and open the next one after it."""
        assert self._checkpoint is not None
        a = self._window_start
        x0, P0, applied, state0 = self._checkpoint
        window, rest = _split(self._pieces, a, b)
        self._pieces = rest
        acc, gyr, gyr_var, dt, ratio, t, floor = (cast(F64, window[i]) for i in (0, 1, 2, 3, 5, 6, 7))
        still = cast(NDArray[np.bool_], window[4])
        m = b - a + 1
        x, P, filter_state = x0.copy(), P0.copy(), state0.copy()
        level_r = self.levels.params.sigma_m**2
        updates = self.level_updates or []
        for k, z in updates[applied:]:
            if k < a:  # due after the previous window's last sample, found after its close
                height_update(x, P, -1, z, level_r, self._work)
        local = [(k - a, z) for k, z in updates[applied:] if a <= k <= b]
        buffers = _buffers(m)
        inputs = (acc, gyr, gyr_var, dt, still, ratio)
        store_span(
            x, P, 0, m, inputs, self._par, local, [k for k, _ in local], level_r, buffers, self._work, filter_state
        )
        while applied < len(updates) and updates[applied][0] <= b:  # in order of their samples
            applied += 1
        self._checkpoint = (x, P, applied, filter_state)
        self._window_start = b + 1
        self.closes.append(b)
        xf, Pf, xp, Pp, fn, Rm = buffers
        pos, vel, quat = np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 4))
        cov = np.empty((m if self.with_covariance else 0, 4, 4))  # no rows: the states alone
        ds, Ps, xs = np.zeros(eskf.N_STATE), Pf[m - 1].copy(), xf[m - 1].copy()
        _backward_pass(xf, Pf, xp, Pp, fn, Rm, dt, m - 1, True, ds, Ps, xs, pos, vel, quat, cov)
        return SmoothedSpan(a, t, pos, vel, quat, pos[:, 2] - floor, cov if self.with_covariance else None)


def _buffers(m: int) -> tuple[F64, F64, F64, F64, F64, F64]:
    """What ``smoother.store_span`` keeps for m samples: xf, Pf, xp, Pp, fn, Rm."""
    n = eskf.N_STATE
    return (
        np.empty((m, 16)),
        np.empty((m, n, n)),
        np.empty((m, 16)),
        np.empty((m, n, n)),
        np.empty((m, 3)),
        np.empty((m, 3, 3)),
    )


_LOADED: list[bool] = []


def _load_kernels() -> None:
    """Compile (or load from numba's cache) the smoothing kernels now, on three still samples, so
    that a live session's first step does not stall the stream while they compile (several seconds
    on a fresh install)."""
    if _LOADED:
        return
    m, g = 3, 9.80665
    acc, gyr = np.tile([0.0, 0.0, g], (m, 1)), np.zeros((m, 3))
    x, P = np.zeros(16), np.eye(eskf.N_STATE) * 1e-4
    x[6] = 1.0
    par = (
        eskf.FilterParams(*[0.0] * len(eskf.FilterParams._fields))
        ._replace(sig_acc=0.01, sig_gyr=0.01, zupt=0.01, zaru=0.01, zaru_gate_sig=0.01)
        ._replace(g=g, dt_max=1.0, zaru_gate=7.8, zupt_gate=100.0)
    )
    buffers = _buffers(m)
    dt, still, ratio = np.full(m, 0.001), np.ones(m, dtype=np.bool_), np.zeros(m)
    inputs = (acc, gyr, np.zeros((m, 3)), dt, still, ratio)
    store_span(x, P, 0, m, inputs, par, [], [], 1e-4, buffers, np.empty((2, eskf.N_STATE)), eskf.new_filter_state())
    xf, Pf, xp, Pp, fn, Rm = buffers
    out = np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 4))
    ds, Ps, xs = np.zeros(eskf.N_STATE), Pf[-1].copy(), xf[-1].copy()
    _backward_pass(xf, Pf, xp, Pp, fn, Rm, dt, m - 1, True, ds, Ps, xs, *out, np.empty((m, 4, 4)))
    _LOADED.append(True)


def _split(
    pieces: list[tuple[int, tuple[NDArray[np.generic], ...]]], a: int, b: int
) -> tuple[tuple[NDArray[np.generic], ...], list[tuple[int, tuple[NDArray[np.generic], ...]]]]:
    """The inputs of samples a..b (contiguous arrays) and the pieces left after b. A piece's
    clipped-rate variance (input 2) has no rows when none of its samples is clipped; the window's has
    none when none of its pieces has any."""
    parts: list[list[NDArray[np.generic]]] = [[] for _ in range(_N_INPUTS)]
    rest = []
    for first, arrays in pieces:
        n = arrays[0].shape[0]
        lo, hi = max(a, first) - first, min(b + 1, first + n) - first
        if hi > lo:
            for i, arr in enumerate(arrays):
                parts[i].append(arr[lo:hi])  # (a clipped-rate variance without rows stays without)
        if first + n > b + 1:
            cut = max(b + 1 - first, 0)
            rest.append((first + cut, tuple(arr[cut:] for arr in arrays)))
    if any(v.shape[0] for v in parts[2]):
        lengths = [p.shape[0] for p in parts[0]]
        parts[2] = [v if v.shape[0] else np.zeros((m, 3)) for v, m in zip(parts[2], lengths, strict=True)]
    window = tuple(np.ascontiguousarray(p[0] if len(p) == 1 else np.concatenate(p)) for p in parts)
    return window, rest


def step_smooth_recording(
    t_s: F64,
    acc_b_mps2: F64,
    gyr_b_radps: F64,
    rate_hz: float,
    config: NavConfig | None = None,
    *,
    gyr_clipped_b: NDArray[np.bool_] | None = None,
) -> tuple[NavBatch | None, NavStats]:
    """The step-smoothed solution of a whole recording: what a live session shows once each step has
    ended (the last window closed at the end). Same samples, stance flags and statistics as
    ``navigator.navigate`` on the same arrays; positions, velocities, attitude, ``cov_pos_yaw``,
    ``pos_cov_n_m2`` and ``clearance_m`` are the step-smoothed ones."""
    nav = StepSmoothingNavigator(config or NavConfig(), rate_hz, with_covariance=True)
    nav.whole_recording = True
    n = t_s.shape[0]
    out = nav.process(
        ImuBatch(t_s, acc_b_mps2, gyr_b_radps, np.arange(n, dtype=np.int64), np.zeros(n, dtype=np.int64), gyr_clipped_b)
    )
    if out is None:
        return None, nav.stats
    last = nav.finish()
    spans = [s for s in (out.smoothed, last) if s is not None]
    span = SmoothedSpan.concat(spans)
    assert span is not None and span.first_sample == 0 and len(span) == len(out)
    cov = span.cov_pos_yaw
    assert cov is not None
    return (
        dataclasses.replace(
            out,
            pos_n_m=span.pos_n_m,
            vel_n_mps=span.vel_n_mps,
            quat_nb_wxyz=span.quat_nb_wxyz,
            pos_cov_n_m2=cov[:, :3, :3],
            cov_pos_yaw=cov,
            clearance_m=span.clearance_m,
            smoothed=None,
        ),
        nav.stats,
    )
