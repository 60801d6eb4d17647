"""The one-line terminal status: rate, loss, stance, distance; updated in place on a terminal."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import TextIO

import numpy as np

from pipeline.nav_types import NavBatch


class StatusLine:
    """A ``NavSink`` that keeps running figures and redraws one status line at most ``period_s``.

    On a terminal the line is rewritten in place; otherwise a line is printed every ``log_period_s``.
    """

    def __init__(
        self, stream: TextIO = sys.stderr, period_s: float = 0.25, log_period_s: float = 10.0
    ) -> None:
        self.stream = stream
        self.tty = stream.isatty()
        self.period_s = period_s if self.tty else log_period_s
        self.samples = 0
        self.distance_m = 0.0
        self.stance = False
        self.t_s = 0.0
        self._last_pos: np.ndarray | None = None
        self._last_draw = 0.0
        self._wall0 = time.monotonic()
        self.lost_packets: Callable[[], int] | None = None
        """Where the link's lost-packet count comes from, once a link exists."""

    def __call__(self, nav: NavBatch) -> None:
        pos = nav.pos_n_m
        if self._last_pos is not None:
            pos = np.vstack([self._last_pos, pos])
        self.distance_m += float(np.linalg.norm(np.diff(pos, axis=0), axis=1).sum())
        self._last_pos = nav.pos_n_m[-1].copy()
        self.samples += len(nav)
        self.stance = bool(nav.stance[-1])
        self.t_s = float(nav.t_s[-1])
        now = time.monotonic()
        if now - self._last_draw >= self.period_s:
            self._last_draw = now
            self.draw()

    def line(self) -> str:
        rate = self.samples / max(1e-9, time.monotonic() - self._wall0)
        lost = "?" if self.lost_packets is None else str(self.lost_packets())
        return (
            f"t {self.t_s:7.1f} s | {rate:6.0f} samples/s | lost {lost} | "
            f"{'stance' if self.stance else 'swing '} | distance {self.distance_m:7.2f} m"
        )

    def draw(self) -> None:
        if self.tty:
            self.stream.write("\r\x1b[2K" + self.line())
        else:
            self.stream.write(self.line() + "\n")
        self.stream.flush()

    def finish(self) -> None:
        """End the in-place line so later output starts on a fresh line."""
        if self.tty and self.samples:
            self.draw()
            self.stream.write("\n")
            self.stream.flush()
