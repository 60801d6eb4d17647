"""Package-number tracking that one corrupt packet cannot derail: gaps, repeats, late packets, corrupt numbers.

The unit numbers every data packet of an interface with one uint16 counter (protocol-openshoe.md
section 4.1), so the numbers of a healthy stream form one run: consecutive, with gaps where packets
were lost, repeats (lossless resends, wire duplicates) and, rarely, a packet a few places late. The
16-bit additive checksum misses two bit flips that cancel, so now and then a packet with a valid
checksum carries a wrong number, e.g. 1000 + 16 384 in a run at 999. Taken at its word it would
make the next 16 384 good packets look like repeats.

:class:`CounterTracker` therefore believes a number only in its run:

- a number at most ``far_ahead`` after the highest one received, or at most :data:`NEAR_BEHIND`
  before it, belongs to the run (a gap, a repeat or a late packet, accounted as always);
- any other number, and any packet whose 64 MHz time stamp contradicts its number, is held as a
  **suspect**. It is delivered once :data:`CONFIRM_FOLLOWERS` later packets continue from it (the unit
  really jumped: a replug, a restarted output) and rejected, counted in
  :attr:`CounterTracker.corrupt_numbers`, once :data:`REJECT_AFTER` later packets continue the run
  instead. A rejected packet that arrived where a number of the run is missing stands for that
  number: it is not counted lost as well;
- with time stamps (every mode with the unit's tick counter, one output on the interface), a packet
  agrees with the run when its tick is where its number puts it: the previous packet's tick plus the
  number step times the sample period (learnt from the stream, in whole ticks), within a quarter of
  a period. Such a packet is believed at once however far it jumps (a real gap, confirmed by time);
  one whose tick contradicts its number is a suspect however near its number is.

Held packets are returned by a later call (:class:`Tracked` indexes the held packets first, then the
call's own), so a suspect at the end of a read waits for the next read, and nothing good is lost.
A read that continues the run exactly takes a few comparisons, no per-packet bookkeeping; one whose
numbers only go forward, each stamp where its number puts it, a few array operations, gaps included.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Final, NamedTuple

import numpy as np
from numpy.typing import NDArray

COUNTER_WRAP: Final = 1 << 16
TICK_WRAP: Final = 1 << 32
FAR_AHEAD: Final = 64
"""Default: a number up to this far after the highest one opens a gap at once (lossy outputs)."""
NEAR_BEHIND: Final = 64
"""A number up to this far behind the highest one is a repeat or a late packet; further back, a suspect."""
CONFIRM_FOLLOWERS: Final = 3
"""Later packets that must continue from a suspect before its jump is believed."""
REJECT_AFTER: Final = 2
"""Later packets of the run that reject a suspect."""
MAX_SUSPECTS: Final = 64
"""Suspects held at most at once (the oldest is rejected beyond)."""
PERIOD_INTERVALS: Final = 16
"""Intervals the sample period is learnt from (the lower quartile of tick steps per number step, over
steps of up to 8 numbers)."""
NO_TICK: Final = -1
"""The tick of a packet that has none (stepwise output, an MCU id): judged by its number alone."""
_PYTHON_BELOW: Final = 12
"""The time stamps of reads of up to this many packets are checked in Python, longer ones with numpy
(about 1 µs a packet against a few µs a read)."""


class Tracked(NamedTuple):
    """What one :meth:`CounterTracker.track` call decided.

    Positions index the packets held from before (in the order of the previous call's ``held``),
    followed by the packets of this call.
    """

    positions: NDArray[np.int64]
    """(m,) positions of the packets to deliver, in delivery order."""
    counter: NDArray[np.int64]
    """(m,) their unwrapped package numbers."""
    held: NDArray[np.int64]
    """(k,) positions of the packets still held as suspects, in arrival order."""


@dataclass(slots=True)
class _Suspect:
    """Packets that left the run and agree with each other."""

    members: list[int]
    """Positions in the pending list, arrival order."""
    numbers: list[int]
    """Their raw numbers."""
    high_raw: int
    tick_ref: tuple[int, int] | None
    """(offset from the first member's number, tick) of the latest member with a tick."""
    run_high: list[int] = field(default_factory=list)
    """The run's highest number when each member arrived (to find the number it stands for)."""
    followers: int = 0
    contra: int = 0


def _signed(step: int, wrap: int) -> int:
    return (step + wrap // 2) % wrap - wrap // 2


class CounterTracker:
    """Unwraps the uint16 package number and accounts for every packet: delivered, lost, repeated,
    late, or rejected for a corrupt number (see the module docstring).

    Parameters
    ----------
    window
        numbers missing further than this behind the highest one stay lost for good.
    far_ahead
        the largest forward jump believed at once without a time stamp; 1 for lossless outputs,
        whose packets come strictly in order.
    """

    def __init__(self, window: int = 4096, *, far_ahead: int = FAR_AHEAD) -> None:
        self._window = window
        self.far_ahead = far_ahead
        self._high: int | None = None
        self._high_raw = 0
        self._missing: set[int] = set()
        self._stand_ins: set[int] = set()
        self._expired = 0
        self._ref: tuple[int, int] | None = None  # (total, tick) of the latest believed packet with a tick
        self._intervals: list[int] = []
        self.period_ticks: int | None = None
        """The sample period in 64 MHz ticks, once learnt (or set); None: numbers only."""
        self._pending: list[tuple[int, int]] = []  # (raw, tick) of held packets
        self._suspects: list[_Suspect] = []
        self.lost = 0
        """Numbers below the highest one that have not arrived (yet), except those a rejected packet stands for."""
        self.duplicates = 0
        """Arrivals of a number already received."""
        self.out_of_order = 0
        """Numbers that arrived after a higher one (they filled a gap)."""
        self.corrupt_numbers = 0
        """Packets rejected because their number (or time stamp) contradicted the run."""
        self.delivered = 0
        """Packets delivered (each number once)."""

    @property
    def held(self) -> int:
        """Packets held as suspects."""
        return len(self._pending)

    @property
    def high_raw(self) -> int | None:
        """The highest number believed so far, uint16 as sent (None before the first)."""
        return None if self._high is None else self._high_raw

    def continues(self, numbers: NDArray[np.integer], ticks: NDArray[np.integer] | None = None) -> bool:
        """True if ``numbers`` (n,) continue the run exactly (nothing lost, repeated, late or held) and
        their ``ticks`` (n,), if given, agree with them."""
        if self._high is None or self._pending or len(numbers) == 0:
            return False
        nums = np.asarray(numbers, dtype=np.int64).tolist()
        first, m = nums[0], len(nums)
        if first != (self._high_raw + 1) % COUNTER_WRAP:
            return False
        # each step is 1 modulo 2**16: compared as lists, one pass in C
        if first + m <= COUNTER_WRAP:
            if nums != list(range(first, first + m)):
                return False
        elif nums != [(first + i) % COUNTER_WRAP for i in range(m)]:
            return False
        if ticks is None:
            return True
        return self._ticks_agree(np.asarray(ticks, dtype=np.int64))

    def _ticks_agree(self, tick: NDArray[np.int64]) -> bool:
        """Whether the time stamps ``tick`` (n,) of packets that continue the run by number agree with it:
        all :data:`NO_TICK`, or the first where the run's period puts it and every step one period."""
        period, ref = self.period_ticks, self._ref
        if len(tick) <= _PYTHON_BELOW:  # a live read of a few packets is quicker in Python
            t = tick.tolist()
            if NO_TICK in t:
                return all(v == NO_TICK for v in t)  # numbers only, or a kind without ticks among them
            if period is None or ref is None:
                return False  # the slow path learns the period
            tol = period // 4
            return self._first_agrees(t[0], period, ref) and all(
                abs((b - a) % TICK_WRAP - period) <= tol for a, b in itertools.pairwise(t)
            )
        steps = np.subtract(tick[1:], tick[:-1])
        if period is not None and ref is not None and int(tick[0]) >= 0:
            # |step mod 2**32 - period| <= tol for every step: where the tick counter does not wrap the
            # steps are the plain differences and their extremes decide; every tick then follows the
            # first, so none is NO_TICK
            tol = period // 4
            if period - tol <= int(steps.min()) and int(steps.max()) <= period + tol:
                return self._first_agrees(int(tick[0]), period, ref)
        if NO_TICK in tick:
            return bool((tick == NO_TICK).all())
        if period is None or ref is None:
            return False
        tol = period // 4
        if not self._first_agrees(int(tick[0]), period, ref):
            return False
        return bool((np.abs(steps % TICK_WRAP - period) <= tol).all())

    def _first_agrees(self, tick: int, period: int, ref: tuple[int, int]) -> bool:
        """Whether the next number's time stamp ``tick`` is where ``period`` puts it after ``ref``."""
        assert self._high is not None
        lead = self._high + 1 - ref[0]
        return abs(_signed(tick - ref[1] - lead * period, TICK_WRAP)) <= period // 4 + lead * period // 2000

    def take_run(
        self, numbers: NDArray[np.integer], ticks: NDArray[np.integer] | None = None
    ) -> NDArray[np.int64] | None:
        """Believe ``numbers`` (n,) and return their unwrapped counters if they :meth:`continues` the run
        (with ``ticks``); else None, and nothing changes (use :meth:`track`)."""
        if not self.continues(numbers, ticks):
            return None
        assert self._high is not None
        m = len(numbers)
        counters = np.arange(self._high + 1, self._high + m + 1, dtype=np.int64)
        self._high, self._high_raw = self._high + m, int(numbers[-1])
        if ticks is not None and ticks[-1] != NO_TICK:
            self._ref = (self._high, int(ticks[-1]))
        self.delivered += m
        if self._missing:
            self._expire()
        return counters

    def update(self, numbers: NDArray[np.integer]) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
        """Track the next package numbers (n,), in arrival order, numbers only.

        Returns
        -------
        counters : NDArray[np.int64]
            unwrapped counters (n,) int64.
        duplicate : NDArray[np.bool_]
            (n,) True where the packet is not delivered by this call: a repeat, a rejected number,
            or a suspect still held (a held packet delivered by a later call is counted in
            :attr:`delivered` only).
        """
        raw = np.asarray(numbers, dtype=np.int64)
        before = len(self._pending)
        base = self._high_raw if self._high is not None else (int(raw[0]) - 1 if raw.size else 0)
        high = self._high if self._high is not None else base
        counters = high + (raw - base + COUNTER_WRAP // 2) % COUNTER_WRAP - COUNTER_WRAP // 2
        out = self.track(raw)
        dup = np.ones(raw.size, dtype=np.bool_)
        mine = out.positions >= before
        dup[out.positions[mine] - before] = False
        counters[out.positions[mine] - before] = out.counter[mine]
        return counters, dup

    def track(self, numbers: NDArray[np.integer], ticks: NDArray[np.integer] | None = None) -> Tracked:
        """Track the next packets, in arrival order.

        Parameters
        ----------
        numbers
            (n,) package numbers, uint16 as sent.
        ticks
            (n,) their 64 MHz time stamps, uint32, or :data:`NO_TICK` where a packet has none; None:
            numbers only. Give them only when one output is on (else the numbers of one kind skip).

        Returns
        -------
        Tracked
            what to deliver now, and what is held (positions after the previously held packets).
        """
        raw = np.asarray(numbers, dtype=np.int64)
        tick = np.full(raw.size, NO_TICK, dtype=np.int64) if ticks is None else np.asarray(ticks, dtype=np.int64)
        before = len(self._pending)
        if self.continues(raw, None if ticks is None else tick):
            return self._take_run(raw, tick, before)
        forward = self._forward(raw, None if ticks is None else tick)
        if forward is not None:
            return forward
        self._pending.extend(zip(raw.tolist(), tick.tolist(), strict=True))
        index: list[int] = []
        counter: list[int] = []
        for pos in range(before, len(self._pending)):
            self._one(pos, index, counter)
        return self._finish(index, counter)

    # --- internals ------------------------------------------------------------------------------

    def _take_run(self, raw: NDArray[np.int64], tick: NDArray[np.int64] | None, before: int) -> Tracked:
        assert self._high is not None
        m = int(raw.size)
        counters = self._high + np.arange(1, m + 1, dtype=np.int64)
        self._high, self._high_raw = int(counters[-1]), int(raw[-1])
        if tick is not None and tick[-1] != NO_TICK:
            self._ref = (self._high, int(tick[-1]))
        self.delivered += m
        self._expire()
        return Tracked(np.arange(before, before + m, dtype=np.int64), counters, np.empty(0, dtype=np.int64))

    def _forward(self, raw: NDArray[np.int64], tick: NDArray[np.int64] | None) -> Tracked | None:
        """The packets, when each is believed at once as the next after the one before, gaps included
        (what :meth:`_one` decides for them, in a few vectorised steps): each number after the one before
        and, with time stamps, each stamp where its number puts it (without: each gap at most
        ``far_ahead``). Else None, and nothing changes."""
        high, ref, period = self._high, self._ref, self.period_ticks
        if high is None or self._pending or self._suspects or raw.size == 0:
            return None
        step = np.empty(raw.size, dtype=np.int64)
        step[0] = raw[0] - self._high_raw
        np.subtract(raw[1:], raw[:-1], out=step[1:])
        step = (step + COUNTER_WRAP // 2) % COUNTER_WRAP - COUNTER_WRAP // 2
        if int(step.min()) < 1:
            return None
        totals = high + np.add.accumulate(step)
        if tick is None:
            if int(step.max()) > self.far_ahead:
                return None
        else:
            if period is None or ref is None or int(tick.min()) < 0:  # learning the period, or NO_TICK
                return None
            # each against the one before (the first against ref): |signed(Δtick - Δtotal·period)| within
            # a quarter period and 1/2000 of the span
            span = np.empty_like(totals)
            span[0] = totals[0] - ref[0]
            span[1:] = step[1:]
            lag = np.empty_like(tick)
            lag[0] = tick[0] - ref[1]
            np.subtract(tick[1:], tick[:-1], out=lag[1:])
            err = np.abs((lag - span * period + TICK_WRAP // 2) % TICK_WRAP - TICK_WRAP // 2)
            if not bool((err <= period // 4 + span * period // 2000).all()):
                return None
            self._ref = (int(totals[-1]), int(tick[-1]))
        for i in np.flatnonzero(step > 1).tolist():  # the gaps: numbers missing
            total = int(totals[i])
            previous = int(totals[i - 1]) if i else high
            first_missing = max(previous + 1, total - self._window)
            self._expired += first_missing - (previous + 1)
            self._missing.update(range(first_missing, total))
        self._high, self._high_raw = int(totals[-1]), int(raw[-1])
        self.delivered += int(raw.size)
        self._expire()
        return Tracked(np.arange(raw.size, dtype=np.int64), totals, np.empty(0, dtype=np.int64))

    def _agrees(self, ref: tuple[int, int] | None, total: int, tick: int) -> bool | None:
        """Whether ``tick`` is where ``total`` puts it after ``ref``; None when that cannot be told."""
        period = self.period_ticks
        if tick == NO_TICK or ref is None or period is None:
            return None
        err = abs(_signed(tick - ref[1] - (total - ref[0]) * period, TICK_WRAP))
        return err <= period // 4 + abs(total - ref[0]) * period // 2000

    def _one(self, pos: int, index: list[int], counter: list[int]) -> None:
        raw, tick = self._pending[pos]
        if self._high is None:  # the first packet starts the run
            self._high, self._high_raw = raw - 1, (raw - 1) % COUNTER_WRAP
        d = _signed(raw - self._high_raw, COUNTER_WRAP)
        total = self._high + d
        agrees = self._agrees(self._ref, total, tick)
        if agrees is not False and (agrees or -NEAR_BEHIND <= d <= self.far_ahead):
            self._believe(pos, total, tick, index, counter)
            for s in self._suspects:
                s.contra += 1
            self._reject([s for s in self._suspects if s.contra >= REJECT_AFTER])
            return
        for s in reversed(self._suspects):
            if self._follows(s, raw, tick):
                s.members.append(pos)
                s.numbers.append(raw)
                s.run_high.append(self._high)
                if raw not in s.numbers[:-1]:
                    s.followers += 1
                ds = _signed(raw - s.high_raw, COUNTER_WRAP)
                if ds > 0:
                    s.high_raw = raw
                if tick != NO_TICK:
                    s.tick_ref = (_signed(raw - s.numbers[0], COUNTER_WRAP), tick)
                if s.followers >= CONFIRM_FOLLOWERS:
                    self._confirm(s, index, counter)
                return
        ref = None if tick == NO_TICK else (0, tick)
        self._suspects.append(_Suspect([pos], [raw], raw, ref, [self._high]))
        if len(self._suspects) > MAX_SUSPECTS:  # nothing continues the run: give up the oldest
            self._reject(self._suspects[:1])

    def _follows(self, s: _Suspect, raw: int, tick: int) -> bool:
        d = _signed(raw - s.high_raw, COUNTER_WRAP)
        if not -NEAR_BEHIND <= d <= self.far_ahead:
            return False
        agrees = self._agrees(s.tick_ref, _signed(raw - s.numbers[0], COUNTER_WRAP), tick)
        return agrees is not False

    def _believe(self, pos: int, total: int, tick: int, index: list[int], counter: list[int]) -> None:
        """Account for a packet of the run at unwrapped ``total``."""
        assert self._high is not None
        raw = self._pending[pos][0]
        if total > self._high:
            first_missing = max(self._high + 1, total - self._window)
            self._expired += first_missing - (self._high + 1)
            self._missing.update(range(first_missing, total))
            self._high, self._high_raw = total, raw
        elif total in self._missing:
            self._missing.remove(total)
            self._stand_ins.discard(total)
            self.out_of_order += 1
        else:
            self.duplicates += 1
            return
        index.append(pos)
        counter.append(total)
        self.delivered += 1
        if tick != NO_TICK:
            ref = self._ref
            if self.period_ticks is None and ref is not None and 1 <= total - ref[0] <= 8:
                step = _signed(tick - ref[1], TICK_WRAP)
                if step > 0:
                    self._intervals.append(round(step / (total - ref[0])))
                if len(self._intervals) >= PERIOD_INTERVALS:
                    self.period_ticks = max(1, round(float(np.percentile(self._intervals, 25))))
            if ref is None or total >= ref[0]:
                self._ref = (total, tick)

    def _confirm(self, s: _Suspect, index: list[int], counter: list[int]) -> None:
        """The unit really jumped: ``s`` becomes the run (a backward jump, a restart, is renumbered on)."""
        assert self._high is not None
        self._suspects.remove(s)
        others = [o for o in self._suspects if o.members[0] < s.members[0]]
        self._reject(others)
        if _signed(s.numbers[0] - self._high_raw, COUNTER_WRAP) <= 0:
            self._high_raw = (s.numbers[0] - 1) % COUNTER_WRAP
        self._ref = None
        for pos, raw in zip(s.members, s.numbers, strict=True):
            total = self._high + _signed(raw - self._high_raw, COUNTER_WRAP)
            self._believe(pos, total, self._pending[pos][1], index, counter)

    def _reject(self, suspects: list[_Suspect]) -> None:
        """Count ``suspects`` as corrupt numbers; each stands for a missing number where it arrived."""
        assert self._high is not None
        for s in suspects:
            self._suspects.remove(s)
            self.corrupt_numbers += len(s.members)
            for h0 in s.run_high:
                for m in range(h0 + 1, min(self._high, h0 + 1 + NEAR_BEHIND)):
                    if m in self._missing and m not in self._stand_ins:
                        self._stand_ins.add(m)
                        break

    def _finish(self, index: list[int], counter: list[int]) -> Tracked:
        held = sorted(p for s in self._suspects for p in s.members)
        remap = {p: k for k, p in enumerate(held)}
        self._pending = [self._pending[p] for p in held]
        for s in self._suspects:
            s.members = [remap[p] for p in s.members]
        self._expire()
        return Tracked(
            np.asarray(index, dtype=np.int64), np.asarray(counter, dtype=np.int64), np.asarray(held, dtype=np.int64)
        )

    def _expire(self) -> None:
        missing = self._missing
        if self._high is not None and missing and min(missing) < self._high - self._window:
            old = {m for m in missing if m < self._high - self._window}
            missing -= old
            self._expired += len(old - self._stand_ins)
            self._stand_ins -= old
        self.lost = self._expired + len(missing) - len(self._stand_ins)
