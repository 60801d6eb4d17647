"""What the terminal shows: the one-line status (rate, loss, stance, distance per foot), updated in place
on a terminal, and the progress bars of a fast replay and of an evaluation."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Sequence
from typing import TextIO

import numpy as np
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.navigation.navigator import NavStats

RATE_WINDOW_S = 2.0
"""The sample rate shown is averaged over about this much wall time."""


class FootStatus:
    """Running figures of one foot; a ``NavSink`` (call it with each NavBatch)."""

    def __init__(self, name: str, owner: StatusLine | None = None) -> None:
        self.name = name
        self.samples = 0
        self.distance_m = 0.0
        self.stance = False
        self.t_s = 0.0
        self._last_pos: np.ndarray | None = None
        self._owner = owner
        self._rate_marks: list[tuple[float, int]] = [(time.monotonic(), 0)]
        self.lost_packets: Callable[[], int] | None = None
        """Where the link's lost-packet count comes from, once a link exists."""
        self.reconnects: Callable[[], int] | None = None
        """Where the link's reconnect count comes from, if the link reconnects."""
        self.clock_rate_hz: Callable[[], float | None] | None = None
        """Where the sample rate by the unit's clock comes from, once the session measures it."""

    def __call__(self, nav: NavBatch) -> None:
        pos = nav.pos_n_m
        if self._last_pos is not None:
            pos = np.vstack([self._last_pos, pos])
        self.distance_m += float(np.linalg.norm(np.diff(pos, axis=0), axis=1).sum())
        self._last_pos = nav.pos_n_m[-1].copy()
        self.samples += len(nav)
        self.stance = bool(nav.stance[-1])
        self.t_s = float(nav.t_s[-1])
        if self._owner is not None:
            self._owner.maybe_draw()

    def lead_in(self, nav: NavBatch) -> None:
        """A lead-in filled in (``footnav.pipeline.navigation.lead_in.LiveLeadIn``): its distance added;
        the time, the stance and the rate stay those of the latest samples."""
        self.distance_m += float(np.linalg.norm(np.diff(nav.pos_n_m, axis=0), axis=1).sum())

    def phase(self) -> str:
        """``stance`` or ``swing``, of the latest estimate; ``aligning`` before the first (the navigator
        waits for the unit's first still period)."""
        return "aligning" if not self.samples else ("stance" if self.stance else "swing ")

    def rate_hz(self) -> float:
        """Samples per second of wall time over the last :data:`RATE_WINDOW_S` or so."""
        now = time.monotonic()
        marks = self._rate_marks
        marks.append((now, self.samples))
        while len(marks) > 2 and now - marks[1][0] >= RATE_WINDOW_S:
            marks.pop(0)
        t0, n0 = marks[0]
        return (self.samples - n0) / max(1e-9, now - t0)

    def text(self, *, with_name: bool) -> str:
        lost = "?" if self.lost_packets is None else str(self.lost_packets())
        extra = ""
        if self.reconnects is not None and (n := self.reconnects()):
            extra = f" reconnects {n}"
        name = f"{self.name}: " if with_name else ""
        clock = None if self.clock_rate_hz is None else self.clock_rate_hz()
        clock_text = "" if clock is None else f"clock {clock:g} Hz, "
        return f"{name}{clock_text}{self.rate_hz():5.0f}/s lost {lost}{extra} {self.phase()} {self.distance_m:7.2f} m"


class StatusLine:
    """Keeps running figures per foot and redraws one status line at most every ``period_s``.

    On a terminal the line is rewritten in place; otherwise a line is printed every ``log_period_s``.
    One foot: call the StatusLine itself with each NavBatch; several: use :meth:`foot`.
    """

    def __init__(
        self,
        stream: TextIO = sys.stderr,
        period_s: float = 0.25,
        log_period_s: float = 10.0,
        *,
        feet: Sequence[str] = ("foot",),
    ) -> None:
        self.stream = stream
        self.tty = stream.isatty()
        self.period_s = period_s if self.tty else log_period_s
        self.feet = {name: FootStatus(name, self) for name in feet}
        self._first = next(iter(self.feet.values()))
        self._last_draw = 0.0
        self._drawn = False

    def foot(self, name: str) -> FootStatus:
        """The NavSink and figures of one foot."""
        return self.feet[name]

    def __call__(self, nav: NavBatch) -> None:
        self._first(nav)

    @property
    def samples(self) -> int:
        return sum(f.samples for f in self.feet.values())

    @property
    def distance_m(self) -> float:
        return self._first.distance_m

    @property
    def lost_packets(self) -> Callable[[], int] | None:
        return self._first.lost_packets

    @lost_packets.setter
    def lost_packets(self, source: Callable[[], int] | None) -> None:
        self._first.lost_packets = source

    @property
    def reconnects(self) -> Callable[[], int] | None:
        return self._first.reconnects

    @reconnects.setter
    def reconnects(self, source: Callable[[], int] | None) -> None:
        self._first.reconnects = source

    def maybe_draw(self) -> None:
        now = time.monotonic()
        if now - self._last_draw >= self.period_s:
            self._last_draw = now
            self.draw()

    def line(self) -> str:
        t_s = max(f.t_s for f in self.feet.values())
        several = len(self.feet) > 1
        parts = [f.text(with_name=several) for f in self.feet.values()]
        return f"t {t_s:7.1f} s | " + " | ".join(parts)

    def draw(self) -> None:
        if self.tty:
            self.stream.write("\r\x1b[2K" + self.line())
        else:
            self.stream.write(self.line() + "\n")
        self.stream.flush()
        self._drawn = True

    def finish(self) -> None:
        """Draw the final figures; on a terminal, end the in-place line so later output starts on a
        fresh line."""
        if not self.samples:
            return
        self.draw()
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()


class Progress:
    """A progress bar for replays faster than real time: ``[#####.....]  45 %``, in place on a terminal,
    every 10 % otherwise."""

    def __init__(self, label: str, stream: TextIO = sys.stderr, period_s: float = 0.2) -> None:
        self.label = label
        self.stream = stream
        self.tty = stream.isatty()
        self.period_s = period_s
        self._last = 0.0
        self._last_decile = -1
        self.fraction = 0.0

    def update(self, done: int, total: int) -> None:
        self.fraction = min(1.0, done / total) if total > 0 else 0.0
        now = time.monotonic()
        if self.tty:
            if now - self._last >= self.period_s:
                self._last = now
                self.stream.write("\r\x1b[2K" + self.text())
                self.stream.flush()
        elif (decile := int(self.fraction * 10)) > self._last_decile:
            self._last_decile = decile
            self.stream.write(self.text() + "\n")
            self.stream.flush()

    def text(self, width: int = 30) -> str:
        filled = round(self.fraction * width)
        return f"{self.label} [{'#' * filled}{'.' * (width - filled)}] {100 * self.fraction:3.0f} %"

    def finish(self) -> None:
        if self.tty:
            self.stream.write("\r\x1b[2K" + self.text() + "\n")
            self.stream.flush()


class ProgressBar:
    """``ProgressBar(total, label)``; call :meth:`step` with a note per item, :meth:`close` at the end."""

    def __init__(self, total: int, label: str, stream: TextIO = sys.stderr, width: int = 30) -> None:
        self.total, self.label, self.stream, self.width = max(1, total), label, stream, width
        self.done = 0
        self.tty = stream.isatty()

    def step(self, note: str = "") -> None:
        self.done += 1
        if not self.tty:
            return
        filled = round(self.width * self.done / self.total)
        bar = "#" * filled + "-" * (self.width - filled)
        self.stream.write(f"\r\x1b[2K{self.label} [{bar}] {self.done}/{self.total} {note}")
        self.stream.flush()

    def close(self) -> None:
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()


def lead_in_note(stats: NavStats) -> str:
    """What became of the samples before the first still period, as ", ..." for a summary (empty: none)."""
    backwards = stats.samples_navigated_backwards
    dropped = stats.samples_before_alignment - backwards
    notes = [f"{backwards} samples before the first still period navigated backwards from it"] if backwards else []
    notes += [f"{dropped} samples before the first still period not navigated"] if dropped else []
    return "".join(f", {n}" for n in notes)


def input_handling(stats: NavStats) -> str:
    """What was done with bad or doubtful input, as a phrase (empty when nothing was)."""
    parts = [
        (stats.bad_samples, "samples not finite or impossible (not integrated)"),
        (stats.bad_dt, "non-positive time steps (not integrated)"),
        (stats.gaps, "gaps in the stream"),
        (
            stats.rates_clipped,
            f"gyroscope values taken as clipped at the sensor's range ({stats.rates_reconstructed} raised by "
            "the reconstruction; all navigated as uncertain)",
        ),
        (stats.zero_velocity_rejected, "zero-velocity samples skipped (the filter saw the foot moving)"),
    ]
    return ", ".join(f"{n} {what}" for n, what in parts if n)
