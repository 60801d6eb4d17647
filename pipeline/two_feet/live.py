"""Two feet coupled while their samples stream in: the lockstep of ``navigate_feet`` for live sessions.

Each foot's samples reach its pipeline on their own (two units, two links, two asyncio tasks), while
the distance bound (``footnav.pipeline.two_feet.separation``) must see both navigators at one time.
:class:`FeetLockstep` holds each foot's arriving batches and runs both navigators on the cells
[t₀ + k·s, t₀ + (k+1)·s) of one time grid (s = ``FootSeparation.step_s``): cell k is navigated, for
both feet, once both have delivered a sample at or after its end (or ended), and the bound (with the
relative heading, if asked) is applied after it, exactly as ``navigate_feet`` does on two recordings.
Estimates then go to each foot's sinks (:meth:`LockstepPort.bind_sinks`, called by the stage runner),
at most a cell plus the other foot's lag after the samples arrived. The order of the two feet's
arrivals does not change a bit of the result, so a replay of a capture (its reads at any pace)
reproduces the live session unless the session released cells (below); ToF and barometer readings
keep their place between a foot's IMU batches.

Leaps: when both feet are aligned and have data for several cells (no other readings, no lead-in
being filled), both navigators are copied and navigate the cells in one call each; the leap stands if
the feet stayed ``LEAP_MARGIN_M`` inside R at every cell end and the relative heading (banded) had
nothing to correct, else the copies are put back and the cells go one by one: bit for bit.

Clocks. Each foot's ``t_s`` is its own session time. With ``clock="host"`` a foot's time on the grid
is τ = t + (h₀ − h_ref)/10⁹: h₀ the host receive time (ns) of its first IMU batch, h_ref the earliest
of the two (a replay carries the captured host times, so it finds the same offsets); as good as the
first reads' latency difference, about 10 ms, in which a swinging foot moves 4 cm. Unit clock drift
is not followed. ``clock="shared"`` takes the ``t_s`` as one clock (two recordings of one logger).

A foot whose data stops (a link stall) would hold the other's estimates back; with ``max_lead_s``
a cell is navigated for the foot that has data once it is that far ahead of the other, without the
bound (counted in ``released_cells``), and the late foot's samples are navigated alone until it is
back on the grid. Which cells are released depends on when the data arrived, which a capture does not
keep: its replay waits (``max_lead_s=None``) and couples them. The bound is not applied in a cell a foot
had ended before. All calls come from one thread (the stage runner's event loop): nothing is locked.

Lead-in. A foot whose walk starts in motion aligns on its first still period; with
:meth:`LockstepPort.fill_lead_in` its samples before it are kept and navigated backwards once that
period has ended, by the one-foot path's ``footnav.pipeline.navigation.lead_in.LiveLeadIn`` on the
foot's own samples: no coupling in the lead-in (the other foot's lead-in is a separate backward run
in a frame of its own, each moved onto its own foot's forward track at its first sample). The forward
estimates are those without it, bit for bit, and the lead-in is handed to the foot's lead-in sinks
among its forward batches, as one more batch earlier than those already given.
"""

from __future__ import annotations

import copy
import itertools
import math
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Literal, NamedTuple, TypeAlias

import numpy as np
from footnav.pipeline.aiding.baro import PressureBatch
from footnav.pipeline.aiding.tof_types import RangeBatch
from footnav.pipeline.nav_types import NavBatch, concat_batches
from footnav.pipeline.navigation.lead_in import LiveLeadIn
from footnav.pipeline.navigation.navigator import Navigator, NavStats
from footnav.pipeline.samples import ImuBatch
from footnav.pipeline.two_feet.heading import HeadingCoupler, RelativeHeading
from footnav.pipeline.two_feet.separation import FootSeparation, apply_separation
from numpy.typing import NDArray

F64 = NDArray[np.float64]
Item: TypeAlias = ImuBatch | RangeBatch | PressureBatch
NavSink = Callable[[NavBatch], object]
"""Where a foot's estimates go (``footnav.pipeline.runner.NavSink``, not imported: the runner knows asyncio)."""


FEET_COUPLINGS = ("distance", "distance+heading", "independent")
"""How a session's two feet are navigated: the distance bound alone (``--distance-only``), with the
relative heading (the default), or each on its own (``--independent-feet``); kept in the capture's
session record (``feet_coupling``) so that a replay does the same."""
DEFAULT_FEET_COUPLING = "distance+heading"
"""The coupling of two feet unless a flag says otherwise (design page "Estimator", "Two feet coupled")."""


def coupling_bound(coupling: str) -> FootSeparation | None:
    """The bound for a :data:`FEET_COUPLINGS` name (None: independent feet)."""
    if coupling not in FEET_COUPLINGS:
        raise ValueError(f"unknown feet coupling {coupling!r}; one of {', '.join(FEET_COUPLINGS)}")
    if coupling == "independent":
        return None
    return FootSeparation(heading=RelativeHeading() if coupling == "distance+heading" else None)


def coupling_refusal(navigators: Sequence[object]) -> str | None:
    """Why these feet cannot be coupled (None: they can): two feet, each navigated by footnav's causal
    single-IMU :class:`Navigator`. Not the step-smoothing navigator (its passes re-filter each step
    without the bound's updates), the dual-IMU board's, or a unit's own INS or steps."""
    if len(navigators) != 2:
        return "one foot"
    if any(type(n) is not Navigator for n in navigators):
        return (
            "the feet are coupled only with footnav's single-IMU filter: not with --step-smoothing, a dual-IMU "
            "board or --mode ins/steps"
        )
    return None


LOCKSTEP_MAX_LEAD_S = 1.0
"""A live session's ``max_lead_s``: a stalled foot holds the other's estimates back at most this much
of its data, s (a replay waits: the other foot's data is in the capture)."""
FEET = ("left", "right")
"""The feet a session couples, by the names its feet have."""
LEAP_MARGIN_M = 0.05
"""A leap over several cells stands when the feet's distance at each cell's end, from the estimates
of the cell's last samples, stayed this far inside R, m (module docstring): more than a stance level's
update at a cell's end moves a foot horizontally."""
LEAP_MAX_CELLS = 200
"""The most cells one leap takes (10 s at the default step): what a failed leap navigates twice."""


class _Step(NamedTuple):
    """A foot's estimates over one cell of a leap, as the relative heading reads them."""

    t_s: F64
    stance: NDArray[np.bool_]
    quat_nb_wxyz: F64


def _snapshot(nav: Navigator) -> dict[str, object]:
    """A copy of everything ``nav`` holds (its configuration, immutable, shared)."""
    return copy.deepcopy(nav.__dict__, {id(nav.config): nav.config})


def _restore(nav: Navigator, state: dict[str, object]) -> None:
    """Put ``nav`` back to a :func:`_snapshot` of it, in place (the session keeps the same object)."""
    nav.__dict__.clear()
    nav.__dict__.update(state)


def lockstep_for(
    navigators: dict[str, object],
    coupling: str,
    *,
    max_lead_s: float | None = None,
    log_event: Callable[..., object] | None = None,
    notice: Callable[[str], None] | None = None,
) -> FeetLockstep | None:
    """A session's lockstep for its feet's navigators (foot name -> navigator), host-time matched;
    None for one foot, ``coupling="independent"``, or navigators that cannot be coupled (``notice`` is
    told why). ``log_event(text, t_s=t_s)`` is told each correction (t_s on the left foot's clock; e.g.
    ``footnav.views.outputs.SessionViews.log_event``)."""
    bound = coupling_bound(coupling)
    if bound is None or tuple(navigators) != FEET:
        return None
    navs = [navigators[f] for f in FEET]
    if (why := coupling_refusal(navs)) is not None:
        if notice is not None:
            notice(f"the two feet are navigated independently: {why}")
        return None

    def told(t_s: float, d_m: float) -> None:
        if log_event is not None:
            log_event(f"feet {d_m:.2f} m apart, over the {bound.max_m:g} m bound: both tracks corrected", t_s=t_s)

    left, right = (n for n in navs if isinstance(n, Navigator))
    return FeetLockstep(left, right, bound, max_lead_s=max_lead_s, on_correction=told)


@dataclass
class _Foot:
    """One foot's side of the lockstep: its navigator, what arrived and is not navigated yet (in
    arrival order), its estimates not yet handed on (each with True for a lead-in), its lead-in
    filling, and where its clock sits on the grid."""

    nav: Navigator
    items: deque[Item] = field(default_factory=deque)
    sinks: Sequence[NavSink] = ()
    out: list[tuple[NavBatch, bool]] = field(default_factory=list)
    lead_in: LiveLeadIn | None = None
    lead_in_sinks: Sequence[NavSink] = ()
    host0_ns: int | None = None
    first_t_s: float = math.nan
    last_t_s: float = -math.inf
    offset_s: float | None = None
    ended: bool = False

    @property
    def reach(self) -> float:
        """τ of the latest sample received (−∞ before the first, or before the foot is placed)."""
        return -math.inf if self.offset_s is None else self.last_t_s + self.offset_s


class FeetLockstep:
    """Two navigators in lockstep on one time grid, coupled by the distance bound (module docstring).

    Parameters
    ----------
    left, right : Navigator
        The feet's navigators (each also used on its own by the session: stats, ToF counts).
    bound : FootSeparation
        R, its noise, the grid step and the start positions; ``bound.heading`` adds the relative heading.
    clock : {"host", "shared"}
        How the feet's times are matched (module docstring).
    max_lead_s : float, optional
        Navigate a foot alone once its data is this far ahead of the other's, s (None: wait, as a
        replay does).
    on_correction : callable, optional
        Told ``(τ, distance before)`` at each correction (τ on the left foot's clock, s; m).

    Attributes
    ----------
    corrections, distance_before_m
        when (end of the cell, τ s) the bound was violated and applied, and the distance before, m.
    released_cells
        cells navigated without the bound because a foot's data lagged by more than ``max_lead_s``.
    leaped_cells, undone_leaps
        cells navigated in leaps (module docstring), and leaps undone (the feet came near R, or a
        heading would have been corrected).
    heading : HeadingCoupler or None
        the relative heading's record (its ``times_s``), with ``bound.heading``.
    """

    def __init__(
        self,
        left: Navigator,
        right: Navigator,
        bound: FootSeparation,
        *,
        clock: Literal["host", "shared"] = "host",
        max_lead_s: float | None = None,
        on_correction: Callable[[float, float], None] | None = None,
    ) -> None:
        self.bound = bound
        self.clock = clock
        self.max_lead_s = max_lead_s
        self.on_correction = on_correction
        self._feet = (_Foot(left), _Foot(right))
        self._ports = (LockstepPort(self, 0), LockstepPort(self, 1))
        self.heading = None if bound.heading is None else HeadingCoupler(bound.heading)
        self._t0: float | None = None
        self._ref_ns = 0
        self._k = 0
        self._no_leap_before = 0
        self.leaped_cells = 0
        self.undone_leaps = 0
        self.corrections: list[float] = []
        self.distance_before_m: list[float] = []
        self.released_cells = 0

    def port(self, foot: int) -> LockstepPort:
        """What foot 0 (left) or 1 (right)'s pipeline drives in place of its navigator."""
        return self._ports[foot]

    def port_for(self, foot: str) -> LockstepPort:
        """:meth:`port` by the foot's name."""
        return self._ports[self.side(foot)]

    @staticmethod
    def side(foot: str) -> int:
        """0 for the ``left`` foot, 1 for the ``right``."""
        return FEET.index(foot)

    def end(self, foot: int) -> None:
        """Foot ``foot`` will deliver nothing more (its stream ended, failed or changed navigator): the
        other foot goes on alone after its last sample. Idempotent."""
        if not self._feet[foot].ended:
            self._feet[foot].ended = True
            self._advance()

    def summary(self) -> str:
        """One line for the end of a session: how often the bound acted."""
        released = f"; {self.released_cells * self.bound.step_s:.1f} s navigated apart (a foot's data late)"
        heading = "" if self.heading is None else f", {len(self.heading.times_s)} relative heading updates"
        return (
            f"feet coupled: {len(self.corrections)} corrections of the distance bound (R = {self.bound.max_m:g} m)"
            + heading
            + (released if self.released_cells else "")
        )

    def drained(self, foot: int) -> bool:
        """Whether everything foot ``foot`` delivered has been navigated and handed to its sinks."""
        f = self._feet[foot]
        return not f.items and not f.out

    def _receive(self, foot: int, item: Item) -> None:
        f = self._feet[foot]
        if f.ended:
            raise RuntimeError("a foot fed after its end")
        f.items.append(item)
        if isinstance(item, ImuBatch) and len(item):
            if f.host0_ns is None:
                f.host0_ns, f.first_t_s = int(item.host_ns[0]), float(item.t_s[0])
                self._offset(f)
            f.last_t_s = float(item.t_s[-1])
        self._advance()

    def _offset(self, f: _Foot) -> None:
        """Place a foot on the grid once the grid exists."""
        if self._t0 is not None and f.host0_ns is not None and f.offset_s is None:
            f.offset_s = 0.0 if self.clock == "shared" else (f.host0_ns - self._ref_ns) / 1e9

    def _place(self) -> bool:
        """Fix the grid (t₀ and the host-time reference) once both feet have data (or one has ended,
        or is ``max_lead_s`` into its data alone); False while it cannot be fixed."""
        if self._t0 is not None:
            return True
        started = [f for f in self._feet if f.host0_ns is not None]
        if not started:
            return False
        waiting = [f for f in self._feet if f.host0_ns is None and not f.ended]
        if waiting:
            lead = max(f.last_t_s - f.first_t_s for f in started)
            if self.max_lead_s is None or lead <= self.max_lead_s:
                return False
        self._ref_ns = min(f.host0_ns for f in started if f.host0_ns is not None)
        self._t0 = math.inf
        for f in started:
            self._offset(f)
            assert f.offset_s is not None
            self._t0 = min(self._t0, f.first_t_s + f.offset_s)
        return True

    def _edge(self, k: int) -> float:
        assert self._t0 is not None
        return self._t0 + self.bound.step_s * k  # as navigate_feet's t0 + step·arange

    def _advance(self) -> None:
        """Navigate every cell both feet allow, apply the bound after each, hand the estimates on."""
        if not self._place():
            return
        feet = self._feet
        while True:
            e0, e1 = self._edge(self._k), self._edge(self._k + 1)
            for f in feet:  # samples before the cell (a foot back from a lag, or placed late): alone
                self._feed(f, e0)
            if all(f.ended and not f.items for f in feet):
                break
            if self._leap():
                continue
            ready = [f.ended or f.reach >= e1 for f in feet]
            released = not all(ready)
            if released and not self._lead_release(ready):
                break
            latest = [self._feed(f, e1) for f in feet]
            if released:
                self.released_cells += 1
            elif all(f.reach >= e0 for f in feet):
                self._couple(latest, e1)
            self._k += 1
        for f in feet:
            self._finish_lead_in(f)
            if f.out:
                self._hand_on(f)

    def _leap(self) -> bool:
        """Navigate every whole cell both feet have data for in one call per foot, if the bound cannot
        have acted in any of them (module docstring, "Leaps"); False, with nothing changed, if not."""
        feet = self._feet
        if (
            (self.heading is not None and self.heading.config.band_rad <= 0.0)  # it acts at every stance
            or self._k < self._no_leap_before
            or any(
                f.ended
                or f.offset_s is None
                or f.nav.state is None  # each cell's estimates are then exactly its samples'
                or (f.lead_in is not None and not f.lead_in.done)
                or f.nav.tof.active
                or any(not isinstance(item, ImuBatch) for item in f.items)
                for f in feet
            )
        ):
            return False
        reach = min(f.reach for f in feet)
        m = 0  # cells k .. k + m − 1 are whole for both feet
        while m < LEAP_MAX_CELLS and self._edge(self._k + m + 1) <= reach:
            m += 1
        if m < 2:
            return False
        assert self._t0 is not None  # placed: every foot has an offset
        saved = [(_snapshot(f.nav), list(f.items), len(f.out)) for f in feet]
        heading = copy.deepcopy(self.heading)
        ends = self._t0 + self.bound.step_s * np.arange(self._k + 1, self._k + m + 1)  # as _edge
        made = [self._feed(f, float(ends[-1])) for f in feet]
        last = self._last_before(made, ends)
        if last is not None and self._inside_bound(made, last) and self._heading_idle(made, last):
            self._k += m
            self.leaped_cells += m
            return True
        self.heading = heading
        for f, (state, items, n_out) in zip(feet, saved, strict=True):
            _restore(f.nav, state)
            f.items = deque(items)
            del f.out[n_out:]
        self._no_leap_before = self._k + m  # the bound is near: these cells one by one
        self.undone_leaps += 1
        return False

    def _last_before(self, made: list[NavBatch | None], ends: np.ndarray) -> list[np.ndarray] | None:
        """Per foot, the index in its estimates ``made`` of the last sample before each cell end ``ends``
        (τ, s); None when a foot has none before the first end."""
        last = []
        for f, est in zip(self._feet, made, strict=True):
            if est is None or f.offset_s is None:
                return None
            i = np.searchsorted(est.t_s + f.offset_s, ends, side="left") - 1
            if i[0] < 0:
                return None
            last.append(i)
        return last

    def _inside_bound(self, made: list[NavBatch | None], last: list[np.ndarray]) -> bool:
        """Whether the feet's horizontal distance at each cell end, from the estimates ``made`` at the
        samples ``last`` (:meth:`_last_before`), stays ``LEAP_MARGIN_M`` inside R."""
        xy = []
        for est, i, origin in zip(made, last, (self.bound.left_origin_m, self.bound.right_origin_m), strict=True):
            assert est is not None
            xy.append(est.pos_n_m[i, :2] + np.asarray(origin[:2]))
        d = np.hypot(xy[0][:, 0] - xy[1][:, 0], xy[0][:, 1] - xy[1][:, 1])
        return bool(np.all(d < self.bound.max_m - LEAP_MARGIN_M))

    def _heading_idle(self, made: list[NavBatch | None], last: list[np.ndarray]) -> bool:
        """Follow the relative heading through each leaped cell's estimates, as cell by cell; False as
        soon as it would correct a heading (the leap is then undone)."""
        if self.heading is None:
            return True
        start = [0, 0]
        left, right = self._feet[0].nav, self._feet[1].nav
        for j in range(last[0].shape[0]):
            steps: list[_Step | None] = []
            for foot, (est, i) in enumerate(zip(made, last, strict=True)):
                assert est is not None
                a, b = start[foot], int(i[j]) + 1
                steps.append(_Step(est.t_s[a:b], est.stance[a:b], est.quat_nb_wxyz[a:b]) if b > a else None)
                start[foot] = max(a, b)
            if not self.heading.after_batch(left, steps[0], right, steps[1], dry=True):
                return False
        return True

    @staticmethod
    def _finish_lead_in(f: _Foot) -> None:
        """The lead-in of a foot whose still period lasted to its end, once all it delivered is navigated."""
        if f.lead_in is None or f.lead_in.done or not f.ended or f.items:
            return
        if (lead_in := f.lead_in.finish()) is not None:
            f.out.append((lead_in, True))

    @staticmethod
    def _hand_on(f: _Foot) -> None:
        """The foot's estimates to its sinks (consecutive forward batches joined) and each lead-in to its
        lead-in sinks, in the order they were made."""
        out, f.out = f.out, []
        for is_lead_in, group in itertools.groupby(out, key=lambda made: made[1]):
            navs = [nav for nav, _ in group]
            if is_lead_in:
                for nav in navs:
                    for sink in f.lead_in_sinks:
                        sink(nav)
                continue
            joined = concat_batches(navs)
            for sink in f.sinks:
                sink(joined)

    def _lead_release(self, ready: list[bool]) -> bool:
        """Whether the ready foot is ``max_lead_s`` ahead of the other (which then has no say in the cell)."""
        if self.max_lead_s is None or not any(ready):
            return False
        a, b = (self._feet[0], self._feet[1]) if ready[0] else (self._feet[1], self._feet[0])
        lag_from = b.reach if b.offset_s is not None else self._edge(0)
        return a.reach - lag_from > self.max_lead_s

    def _couple(self, latest: list[NavBatch | None], t_cell_end: float) -> None:
        left, right = self._feet[0].nav, self._feet[1].nav
        if self.heading is not None:
            self.heading.after_batch(left, latest[0], right, latest[1])
        d = apply_separation(left, right, self.bound)
        if math.isfinite(d):
            self.corrections.append(t_cell_end)
            self.distance_before_m.append(d)
            if self.on_correction is not None:
                self.on_correction(t_cell_end - (self._feet[0].offset_s or 0.0), d)

    def _feed(self, f: _Foot, until: float) -> NavBatch | None:
        """Navigate the foot's held samples with τ < ``until`` and the readings that arrived among them
        (its lead-in filling sees each batch, as ``LiveLeadIn`` asks); the estimates (joined), or None."""
        made: list[NavBatch] = []
        while f.items:
            item = f.items[0]
            if f.offset_s is None and not (f.ended and (not isinstance(item, ImuBatch) or len(item) == 0)):
                break  # not on the grid yet (an ended foot that never sent a sample: its readings go on)
            if not isinstance(item, ImuBatch):
                f.items.popleft()
                if isinstance(item, RangeBatch):
                    f.nav.add_ranges(item)
                else:
                    f.nav.add_pressure(item)
                continue
            if len(item) == 0:
                f.items.popleft()
                continue
            assert f.offset_s is not None  # a foot with samples is placed once the grid is
            n = int((item.t_s + f.offset_s < until).sum())  # time stamps ascend within a batch
            if n == 0:
                break
            if n == len(item):
                f.items.popleft()
                part = item
            else:
                part, f.items[0] = item.select(slice(0, n)), item.select(slice(n, len(item)))
            if f.lead_in is not None:
                f.lead_in.add(part)
            est = f.nav.process(part)
            if f.lead_in is not None and (lead_in := f.lead_in.after(est)) is not None:
                f.out.append((lead_in, True))  # before the batch that brought it, as for one foot
            if est is not None:
                made.append(est)
                f.out.append((est, False))
            if n < len(item):
                break
        return concat_batches(made) if made else None


class LockstepPort:
    """One foot's door into a :class:`FeetLockstep`: what the stage runner drives in place of the foot's
    navigator (``footnav.pipeline.runner.BatchNavigator``, ranges and pressure too). ``process`` returns
    None: the estimates go to the sinks given to :meth:`bind_sinks` when the lockstep has made them."""

    def __init__(self, lockstep: FeetLockstep, foot: int) -> None:
        self._lockstep = lockstep
        self._foot = foot

    @property
    def navigator(self) -> Navigator:
        return self._lockstep._feet[self._foot].nav

    @property
    def rate_hz(self) -> float:
        return self.navigator.rate_hz

    @property
    def stats(self) -> NavStats:
        return self.navigator.stats

    def retime(self, rate_hz: float) -> None:
        self.navigator.retime(rate_hz)

    def bind_sinks(self, sinks: Sequence[NavSink]) -> None:
        """Where this foot's estimates go (the runner's sinks)."""
        self._lockstep._feet[self._foot].sinks = list(sinks)

    def fill_lead_in(self, sink: NavSink) -> None:
        """Fill this foot's lead-in in (module docstring): its samples before the alignment, navigated
        backwards on their own once its still period has ended, go to ``sink`` (once, at most); call
        it before the foot's first batch.

        Raises
        ------
        RuntimeError
            the foot has received data already (its lead-in would miss it).
        """
        f = self._lockstep._feet[self._foot]
        if f.items or f.host0_ns is not None or f.ended:
            raise RuntimeError("a foot's lead-in is filled in only from its first batch")
        f.lead_in, f.lead_in_sinks = LiveLeadIn(f.nav), [sink]

    def process(self, batch: ImuBatch) -> NavBatch | None:
        self._lockstep._receive(self._foot, batch)
        return None

    def add_ranges(self, batch: RangeBatch) -> None:
        self._lockstep._receive(self._foot, batch)

    def add_pressure(self, batch: PressureBatch) -> None:
        self._lockstep._receive(self._foot, batch)
