"""A dependency-free progress bar on stderr (redrawn in place on a terminal, silent otherwise)."""

from __future__ import annotations

import sys
from typing import TextIO


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
