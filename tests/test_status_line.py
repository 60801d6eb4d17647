"""The status line of a session (``footnav.app.status``): each foot's phase as a user reads it."""

from __future__ import annotations

import io

import numpy as np
from footnav.app.session import unit_name
from footnav.app.status import StatusLine
from footnav.pipeline.nav_types import NavBatch


def _batch(n: int, stance: bool) -> NavBatch:
    z3, z = np.zeros((n, 3)), np.zeros(n)
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    flags = np.full(n, stance)
    return NavBatch(np.arange(n) / 100.0, z3, z3, quat, np.zeros((n, 3, 3)), flags, z, z, z, np.zeros(n, np.int64))


def test_a_foot_with_no_estimate_yet_is_aligning_not_in_swing() -> None:
    line = StatusLine(io.StringIO(), feet=("left", "right"))
    left, right = line.foot("left"), line.foot("right")
    left(_batch(50, stance=True))
    assert left.text(with_name=True).endswith("stance    0.00 m")
    assert right.text(with_name=True).endswith("aligning    0.00 m")  # was "swing": nothing navigated yet
    right(_batch(50, stance=False))
    assert right.text(with_name=True).endswith("swing     0.00 m")


def test_a_silent_unit_is_named_by_its_foot_only_when_there_are_two() -> None:
    two, one = StatusLine(io.StringIO(), feet=("left", "right")), StatusLine(io.StringIO())
    assert unit_name("/dev/pts/3", two.foot("right")) == "the right foot's unit (/dev/pts/3)"
    assert unit_name("/dev/ttyACM0", one.foot("foot")) == "/dev/ttyACM0"  # live --port: one foot, named "foot"
    assert unit_name("/dev/ttyACM0", one) == unit_name("/dev/ttyACM0", None) == "/dev/ttyACM0"
