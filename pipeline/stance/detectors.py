"""Zero-velocity detectors on sample batches, causal and independent of how the stream is batched.

Test statistics (Skog, Händel, Nilsson, Rantakokko, "Zero-velocity detection — an algorithm
evaluation", IEEE Trans. Biomed. Eng. 57(11), 2010, eqs. 11-14), each over a window of W samples
ending at sample k, small when the foot is still:

- ``shoe`` (SHOE / GLRT): 1/W Σ ( |a_j − g ā/|ā||² / σa² + |ω_j|² / σg² )
- ``amv`` (acceleration moving variance): 1/W Σ |a_j − ā|² / σa²
- ``amag`` (acceleration magnitude): 1/W Σ (|a_j| − g)² / σa²
- ``are`` (angular rate energy): 1/W Σ |ω_j|² / σg²

with ā the window's mean specific force. Each window is summed on its own samples, so a stream gives
bit-identical results however it is cut into batches.

Thresholds: a fixed γ, or (the default) **adaptive**: every ``update_s`` the threshold is set from
the distribution of log10 T over the last ``history_s`` — its upper tail (the 95th percentile, the
level of the swing) minus ``margin_decades``. The statistic of a walking foot is bimodal over about
four decades (stance near the sensor noise, swing near 10⁴·⁵ with the default scales), and the level
of both modes moves with the unit, its mounting, the gait and the speed; the gap between the swing
level and the best threshold moves much less. When the history shows no motion (the spread between
its 5th and 95th percentiles is under ``motion_decades``) the threshold keeps its last value. It is
clamped to [``min_threshold``, ``max_threshold``]. Updates happen at fixed sample counts since the
start of the stream, so live, replay and batch runs detect identically.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from footnav.pipeline.jit import njit
from footnav.pipeline.navigation._kernels_linalg import INTERNAL
from numpy.typing import NDArray

F64 = NDArray[np.float64]
DetectorKind = Literal["shoe", "amv", "amag", "are"]
DETECTOR_KINDS: tuple[DetectorKind, ...] = ("shoe", "amv", "amag", "are")


@dataclass(frozen=True, slots=True)
class DetectorParams:
    """Zero-velocity detector settings.

    Attributes
    ----------
    kind
        which statistic (see the module docstring).
    window_s
        window length in seconds (W = max(2, round(window_s · rate))).
    sigma_acc_mps2
        accelerometer scale σa in the statistic, m/s².
    sigma_gyr_radps
        gyroscope scale σg, rad/s.
    gravity_mps2
        g in the statistic.
    adaptive
        adapt the threshold to the stream (module docstring); else use ``threshold``.
    threshold
        γ when fixed, and the starting value of the adaptive threshold. With the default scales, 25 admits |ω| up to
        0.1 rad/s or a specific-force deviation of 0.5 m/s² alone; sensor noise of MEMS foot units gives T ≈ 0.1-1 at
        rest.
    history_s, update_s, margin_decades, motion_decades
        the adaptive rule.
    min_threshold, max_threshold
        bounds of the adaptive threshold (T units).
    min_stance_s
        the statistic must stay near the threshold this long before a sample below it counts as stance (causal; see
        ``StreamingDetector._debounce``).
    stance_hysteresis_decades
        "near" for that debounce: below the threshold times 10^stance_hysteresis_decades (a factor 1.26 by default).
    """

    kind: DetectorKind = "shoe"
    window_s: float = 0.01
    sigma_acc_mps2: float = 0.1
    sigma_gyr_radps: float = 0.02
    gravity_mps2: float = 9.80665
    adaptive: bool = True
    threshold: float = 25.0
    history_s: float = 5.0
    update_s: float = 0.1
    margin_decades: float = 2.0
    motion_decades: float = 2.0
    min_threshold: float = 10.0
    max_threshold: float = 3e4
    min_stance_s: float = 0.02
    stance_hysteresis_decades: float = 0.1


_KIND_CODE: dict[str, int] = {"shoe": 0, "amv": 1, "amag": 2, "are": 3}
_ZERO = np.int64(0)
"""0 as an int64 for compiled calls: a literal 0 would compile the callee a second time, for that literal."""


@njit(cache=True, nogil=True, **INTERNAL)
def _pairwise_block(a: F64, lo: int, n: int) -> float:  # pragma: no cover - compiled
    """Σ a[lo:lo+n], n ≤ 128, in the order of numpy's pairwise summation (8 accumulators)."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[lo + i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    while i < n - (n % 8):
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@njit(cache=True, nogil=True, **INTERNAL)
def _pairwise_sum(a: F64, lo: int, n: int) -> float:  # pragma: no cover - compiled
    """Σ a[lo:lo+n] in the order of ``numpy.add.reduce`` over a contiguous axis (pairwise: blocks of
    at most 128 terms, halved at multiples of 8 above), so the compiled statistic reproduces the
    vectorised numpy formulas to the last bit. Iterative: numba's cache mishandles recursion."""
    if n <= 128:
        return _pairwise_block(a, lo, n)
    # post-order walk of numpy's recursion tree with explicit stacks
    st_lo = np.empty(64, dtype=np.int64)
    st_n = np.empty(64, dtype=np.int64)
    st_stage = np.empty(64, dtype=np.int64)
    vals = np.empty(64)
    top, nv = 0, 0
    st_lo[0], st_n[0], st_stage[0] = lo, n, 0
    while top >= 0:
        f_lo, f_n = st_lo[top], st_n[top]
        if f_n <= 128:
            vals[nv] = _pairwise_block(a, f_lo, f_n)
            nv += 1
            top -= 1
            continue
        n2 = f_n // 2
        n2 -= n2 % 8
        if st_stage[top] == 0:
            st_stage[top] = 1
            top += 1
            st_lo[top], st_n[top], st_stage[top] = f_lo, n2, 0
        elif st_stage[top] == 1:
            st_stage[top] = 2
            top += 1
            st_lo[top], st_n[top], st_stage[top] = f_lo + n2, f_n - n2, 0
        else:
            vals[nv - 2] = vals[nv - 2] + vals[nv - 1]
            nv -= 1
            top -= 1
    return vals[0]


@njit(cache=True, nogil=True, inline="always")
def _sum_terms(a: F64, lo: int | np.int64, n: int) -> float:  # pragma: no cover - compiled
    """:func:`_pairwise_sum` of a window's terms, whose ≤ 128 terms (every window of the default
    W) are one block of numpy's pairwise sum: :func:`_pairwise_block` called directly, one call
    fewer per window."""
    return _pairwise_block(a, lo, n) if n <= 128 else _pairwise_sum(a, lo, n)


@njit(cache=True, nogil=True)
def _statistic_kernel(
    acc: F64,
    gyr: F64,
    first: int,
    window: int,
    kind: int,
    sa2: float,
    sg2: float,
    g: float,
    out: F64,
) -> None:  # pragma: no cover - compiled
    """out[i] = statistic of the window ending at sample ``first + i`` of ``acc``/``gyr``.

    The window holds the ``window`` samples up to and including that one, or all samples from the
    first one when there are fewer. Every window is summed on its own samples in a fixed order, so
    a result depends on its window's samples only (never on where a stream was cut into batches).
    """
    tmp = np.empty(3 * window)
    # |ω_j|² terms in window order are the squares of gyr's values in memory order: computed once
    gyr_sq = np.empty(3 * acc.shape[0] if kind in (0, 3) else 0)
    for j in range(gyr_sq.shape[0] // 3):
        for c in range(3):
            gyr_sq[3 * j + c] = gyr[j, c] * gyr[j, c]
    for i in range(out.shape[0]):
        e = first + i
        s = max(0, e - window + 1)
        w = e - s + 1
        acc_term = 0.0
        gyr_term = 0.0
        if kind <= 1:  # shoe, amv: Σ|a_j − ā|² (+ W (|ā| − g)² for shoe)
            m0, m1, m2 = 0.0, 0.0, 0.0
            for j in range(s, e + 1):
                m0 += acc[j, 0]
                m1 += acc[j, 1]
                m2 += acc[j, 2]
            m0, m1, m2 = m0 / w, m1 / w, m2 / w
            for j in range(w):
                d0 = acc[s + j, 0] - m0
                d1 = acc[s + j, 1] - m1
                d2 = acc[s + j, 2] - m2
                tmp[3 * j] = d0 * d0
                tmp[3 * j + 1] = d1 * d1
                tmp[3 * j + 2] = d2 * d2
            acc_term = _sum_terms(tmp, _ZERO, 3 * w)
            if kind == 0:
                dn = math.sqrt(0.0 + m0 * m0 + m1 * m1 + m2 * m2) - g
                acc_term = acc_term + w * (dn * dn)
        elif kind == 2:  # amag: Σ(|a_j| − g)²
            for j in range(w):
                a0, a1, a2 = acc[s + j, 0], acc[s + j, 1], acc[s + j, 2]
                dn = math.sqrt(0.0 + a0 * a0 + a1 * a1 + a2 * a2) - g
                tmp[j] = dn * dn
            acc_term = _sum_terms(tmp, _ZERO, w)
        if kind in (0, 3):  # shoe, are: Σ|ω_j|²
            gyr_term = _sum_terms(gyr_sq, 3 * s, 3 * w)
        stat = (acc_term / sa2 + gyr_term / sg2) / w
        out[i] = stat if math.isfinite(stat) else math.inf


def statistic(acc_b_mps2: F64, gyr_b_radps: F64, window: int, p: DetectorParams) -> F64:
    """The detector statistic for every full window of a batch.

    Parameters
    ----------
    acc_b_mps2
        (n, 3) specific force.
    gyr_b_radps
        (n, 3) angular rate.
    window
        W samples.
    p
        which statistic, its noise scales and gravity.

    Returns
    -------
    F64
        (n − W + 1,) statistic; element i belongs to the window ending at sample i + W − 1. A window holding a
        non-finite sample gets +inf (never still).
    """
    n = acc_b_mps2.shape[0]
    if n < window:
        return np.empty(0)
    out = np.empty(n - window + 1)
    _statistic_kernel(
        np.ascontiguousarray(acc_b_mps2, dtype=np.float64),
        np.ascontiguousarray(gyr_b_radps, dtype=np.float64),
        window - 1,
        window,
        _KIND_CODE[p.kind],
        p.sigma_acc_mps2**2,
        p.sigma_gyr_radps**2,
        p.gravity_mps2,
        out,
    )
    return out


@njit(cache=True, nogil=True, **INTERNAL)
def _quantile_sorted(v: F64, n: int, q: float) -> float:  # pragma: no cover - compiled
    """``numpy.quantile(v[:n], q)`` (method "linear") of sorted finite values, to the last bit."""
    virtual = (n - 1) * q
    if virtual >= n - 1:
        return v[n - 1]
    prev = math.floor(virtual)
    gamma = virtual - prev
    a = v[int(prev)]
    b = v[int(prev) + 1]
    diff = b - a
    if gamma >= 0.5:
        return b - diff * (1.0 - gamma)
    return a + diff * gamma


@njit(cache=True, nogil=True, **INTERNAL)
def _sort_in_place(a: F64) -> None:  # pragma: no cover - compiled
    """Shell sort (Ciura's gaps) of a short array: as fast as ``np.sort`` at ~100 values and much
    quicker for numba to compile."""
    n = a.shape[0]
    for gap in (701, 301, 132, 57, 23, 10, 4, 1):
        for i in range(gap, n):
            v = a[i]
            j = i
            while j >= gap and a[j - gap] > v:
                a[j] = a[j - gap]
                j -= gap
            a[j] = v


@njit(cache=True, nogil=True, **INTERNAL)
def _merge_sorted(vals: F64, n: int, rem: F64, add: F64, out: F64) -> int:  # pragma: no cover - compiled
    """out[:m] = vals[:n] − rem + add, sorted, for sorted finite ``vals``, ``rem`` (a sub-multiset of
    vals[:n]) and ``add``; returns m. One pass whose rare branches (a removal, an insertion) predict
    well, which beats bisection plus block copies here."""
    m_r, m_a = rem.shape[0], add.shape[0]
    ir, ia, no = 0, 0, 0
    rem_next = rem[0] if m_r > 0 else math.inf
    add_next = add[0] if m_a > 0 else math.inf
    for i in range(n):
        v = vals[i]
        if v == rem_next:
            ir += 1
            rem_next = rem[ir] if ir < m_r else math.inf
            continue
        while add_next < v:
            out[no] = add_next
            no += 1
            ia += 1
            add_next = add[ia] if ia < m_a else math.inf
        out[no] = v
        no += 1
    for t in range(ia, m_a):
        out[no] = add[t]
        no += 1
    return no


@njit(cache=True, nogil=True)
def _adaptive_threshold_kernel(
    log_stat: F64,
    seen: int,
    update_every: int,
    history_len: int,
    ring: F64,
    sorted_bufs: F64,
    state: NDArray[np.int64],
    log_threshold: float,
    rule: F64,
    out_log_th: F64,
    blocks: F64,
    block_n: NDArray[np.int64],
) -> float:  # pragma: no cover - compiled
    """The adaptive rule of the module docstring over one batch; returns the log10 threshold.

    ``ring`` (history_len + update_every,) holds the latest log10 T by absolute sample index modulo
    its length; ``sorted_bufs[state[0], :state[1]]`` (of a (2, history_len + update_every) pair used in
    turn) the finite values of the history as of the last update point, sorted, which each update
    point moves on by removing the samples that left the history and merging those that entered it
    (a copy of the history instead of a sort). ``rule`` is
    [percentile_lo, percentile_hi, motion_decades, margin_decades, log_min, log_max].

    When ``update_every`` divides ``history_len``, the samples that leave the history at an update
    point are those that entered it ``history_len`` samples before: ``blocks`` (shaped as ``ring``)
    keeps each entering block's sorted finite values at the block's ring position, and
    ``block_n`` (ring length // update_every,) their number, so each is sorted once.
    """
    cap = ring.shape[0]
    q_lo, q_hi = rule[0] / 100.0, rule[1] / 100.0
    motion, margin, log_min, log_max = rule[2], rule[3], rule[4], rule[5]
    cur, n_sorted = state[0], state[1]
    reuse = history_len % update_every == 0
    for i in range(log_stat.shape[0]):
        k = seen + i
        if k > 0 and k % update_every == 0:
            # history before the last update point: [lo1, hi1); now: [lo2, k)
            lo1, hi1 = max(0, k - update_every - history_len), k - update_every
            lo2 = max(0, k - history_len)
            n_rem = max(0, min(hi1, lo2) - lo1)
            if reuse and n_rem == update_every:  # the block that entered at update point lo1 + update_every
                b0 = lo1 % cap
                rem = blocks[b0 : b0 + block_n[b0 // update_every]]
            else:
                rem = np.empty(n_rem)
                m = 0
                for a in range(lo1, lo1 + n_rem):
                    val = ring[a % cap]
                    if math.isfinite(val):
                        rem[m] = val
                        m += 1
                rem = rem[:m]
                _sort_in_place(rem)
            lo_add = max(lo2, hi1)
            add = np.empty(k - lo_add)
            m = 0
            for a in range(lo_add, k):
                val = ring[a % cap]
                if math.isfinite(val):
                    add[m] = val
                    m += 1
            add = add[:m]
            _sort_in_place(add)
            if reuse and k - lo_add == update_every:
                b0 = lo_add % cap
                for j in range(m):  # a loop: numba compiles a slice assignment slowly
                    blocks[b0 + j] = add[j]
                block_n[b0 // update_every] = m
            n_sorted = _merge_sorted(sorted_bufs[cur], n_sorted, rem, add, sorted_bufs[1 - cur])
            cur = 1 - cur
            if k - lo2 >= update_every and n_sorted > 0:
                lo = _quantile_sorted(sorted_bufs[cur], n_sorted, q_lo)
                hi = _quantile_sorted(sorted_bufs[cur], n_sorted, q_hi)
                if hi - lo >= motion:
                    log_threshold = min(max(hi - margin, log_min), log_max)
        out_log_th[i] = log_threshold
        ring[k % cap] = log_stat[i]
    state[0], state[1] = cur, n_sorted
    return log_threshold


class StreamingDetector:
    """A zero-velocity detector over a stream of batches; one output per input sample.

    The first W−1 samples of a stream use the samples seen so far as their window.
    """

    def __init__(self, params: DetectorParams, rate_hz: float) -> None:
        self.params = params
        self.window = max(2, round(params.window_s * rate_hz))
        self._tail_acc = np.empty((0, 3))
        self._tail_gyr = np.empty((0, 3))
        self._log_threshold = math.log10(params.threshold)
        self._history_len = max(2, round(params.history_s * rate_hz))
        self._update_every = max(1, round(params.update_s * rate_hz))
        self._seen = 0
        self._run = 0  # consecutive samples near the threshold (see _debounce), carried across batches
        self._min_run = max(1, round(params.min_stance_s * rate_hz))
        # the adaptive rule's state (see _adaptive_threshold_kernel)
        self._ring = np.full(self._history_len + self._update_every, math.nan)
        self._sorted = np.empty((2, self._history_len + self._update_every))
        self._sorted_state = np.zeros(2, dtype=np.int64)  # which of the pair is current, its length
        self._blocks = np.empty(self._history_len + self._update_every)  # sorted blocks, for their removal
        self._block_n = np.zeros((self._history_len + self._update_every) // self._update_every, dtype=np.int64)
        self._rule = np.array(
            [
                5.0,
                95.0,
                params.motion_decades,
                params.margin_decades,
                math.log10(params.min_threshold),
                math.log10(params.max_threshold),
            ]
        )

    @property
    def threshold(self) -> float:
        """The threshold in force after the last sample."""
        return float(10.0**self._log_threshold)

    def update(self, acc_b_mps2: F64, gyr_b_radps: F64) -> tuple[F64, F64, NDArray[np.bool_]]:
        """Statistic, threshold and stance flag, each (n,), for the batch's samples."""
        n = acc_b_mps2.shape[0]
        stat = self._statistic(acc_b_mps2, gyr_b_radps)
        log_stat = np.log10(np.maximum(stat, 1e-12))
        log_th = np.empty(n)
        if not self.params.adaptive:
            log_th[:] = self._log_threshold
        else:
            # the threshold is re-set at every multiple of update_every samples since the stream
            # began, from the history of the samples before that point
            self._log_threshold = _adaptive_threshold_kernel(
                log_stat,
                self._seen,
                self._update_every,
                self._history_len,
                self._ring,
                self._sorted,
                self._sorted_state,
                self._log_threshold,
                self._rule,
                log_th,
                self._blocks,
                self._block_n,
            )
        self._seen += n
        # γ changes only at update points: 10^x once per run of equal values, the same 10^x per element
        change = np.ones(n, dtype=np.bool_)
        np.not_equal(log_th[1:], log_th[:-1], out=change[1:])
        starts = np.flatnonzero(change)
        threshold: F64 = np.repeat(10.0 ** log_th[starts], np.diff(np.append(starts, n)))
        near = log_stat < log_th + self.params.stance_hysteresis_decades
        return stat, threshold, self._debounce(log_stat < log_th, near)

    def _debounce(self, below: NDArray[np.bool_], near: NDArray[np.bool_]) -> NDArray[np.bool_]:
        """Stance where the statistic is below the threshold and has stayed near it (``near``: within
        ``stance_hysteresis_decades`` above it) for ``min_stance_s``.

        A swinging foot passes through moments where specific force ≈ g and rotation is small (the
        ballistic middle of a swing, most of all on stairs); no inertial statistic tells them from
        rest, but they last a few milliseconds, while a stance lasts a tenth of a second or more.
        The statistic of a running foot's stance (impacts, rolling over the forefoot) hovers around
        the threshold instead, crossing it every few samples, so a debounce on "below" alone drops
        whole stances there (a third of them in the PyShoe running trial); a swing's ballistic dip
        comes from decades above the threshold and is still rejected. Counting the run on the wider
        "near" band while flagging only samples below the threshold is hysteresis thresholding
        (Canny, "A computational approach to edge detection", IEEE PAMI 8(6), 1986, §6), applied to
        the debounce.
        """
        n = near.shape[0]
        if n == 0:
            return below.copy()
        # each run of near samples, continuing the previous batch's run when it starts the batch
        starts, ends, before, self._run = carried_runs(near, self._run)
        # a run's samples from its min_run-th on (counting the samples before the batch)
        first = np.maximum(starts, starts + (self._min_run - 1) - before)
        keep = first < ends
        edges = np.zeros(n + 1, dtype=np.int8)
        edges[first[keep]] = 1
        edges[ends[keep]] = -1  # runs are apart: no index is both
        still: NDArray[np.bool_] = below & (np.cumsum(edges[:n], dtype=np.int8) > 0)
        return still

    def _statistic(self, acc_b_mps2: F64, gyr_b_radps: F64) -> F64:
        n = acc_b_mps2.shape[0]
        seen = self._tail_acc.shape[0]
        if seen:
            acc = np.concatenate([self._tail_acc, np.asarray(acc_b_mps2, dtype=np.float64)])
            gyr = np.concatenate([self._tail_gyr, np.asarray(gyr_b_radps, dtype=np.float64)])
        else:  # the first batch of a stream: its own samples, without a copy
            acc = np.ascontiguousarray(acc_b_mps2, dtype=np.float64)
            gyr = np.ascontiguousarray(gyr_b_radps, dtype=np.float64)
        stat = np.empty(n)
        p = self.params
        _statistic_kernel(
            acc,
            gyr,
            seen,
            self.window,
            _KIND_CODE[p.kind],
            p.sigma_acc_mps2**2,
            p.sigma_gyr_radps**2,
            p.gravity_mps2,
            stat,
        )
        keep = self.window - 1
        self._tail_acc = acc[-keep:].copy()
        self._tail_gyr = gyr[-keep:].copy()
        return stat


def true_runs(flags: NDArray[np.bool_]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The runs of True in ``flags`` (n,), n ≥ 1: their first indices and the indices after their last ones,
    (k,) each, in order (stances, near-threshold runs)."""
    edges = np.flatnonzero(flags[1:] != flags[:-1]) + 1
    bounds = np.concatenate([[0], edges, [flags.shape[0]]])
    first = 0 if flags[0] else 1  # runs alternate with the runs of False
    return bounds[first:-1:2].astype(np.int64), bounds[first + 1 :: 2].astype(np.int64)


def carried_runs(
    flags: NDArray[np.bool_], carried: int
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64], int]:
    """:func:`true_runs` of a batch's ``flags`` (n,), n ≥ 1, continuing a run of ``carried`` samples
    from the previous batch: the runs' first indices and ends (k,), the samples of each run before
    its first one in the batch (k,: ``carried`` for a run that starts the batch, else 0), and the
    length of the run in progress at the batch's end, to carry on (0: the batch ends in False)."""
    starts, ends = true_runs(flags)
    before = np.zeros(starts.shape[0], dtype=np.int64)
    if flags[0]:
        before[0] = carried
    last = int(ends[-1] - starts[-1] + before[-1]) if flags[-1] else 0
    return starts, ends, before, last
