"""Sample batches that flow from the device layer into the estimators (struct of arrays, SI units)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]
_Steps = TypeVar("_Steps", NDArray[np.float64], NDArray[np.int64])


def diff_after(previous: float, values: _Steps) -> _Steps:
    """``np.diff(values, prepend=previous)`` (n,): each value's step from the one before it, the first
    from ``previous`` (the last of the previous batch). Without ``np.diff``'s concatenation, which
    costs several µs per call: more than the difference itself for the few samples of a live batch."""
    steps = np.empty_like(values)
    if steps.shape[0]:
        steps[0] = values[0] - previous
        np.subtract(values[1:], values[:-1], out=steps[1:])
    return steps


@dataclass(frozen=True, slots=True)
class ImuBatch:
    """A run of IMU samples in the unit's body frame.

    Attributes
    ----------
    t_s
        (n,) device time in seconds, unwrapped from the unit's tick counter, increasing.
    acc_b_mps2
        (n, 3) specific force in the body frame, m/s².
    gyr_b_radps
        (n, 3) angular rate in the body frame, rad/s.
    counter
        (n,) packet counter as sent by the unit (for gap accounting).
    host_ns
        (n,) host receive time, ``time.monotonic_ns()`` of the read that completed the packet.
    gyr_clipped_b
        (n, 3) which rates were cut off at the sensor's range (reconstructed where they could be), or None (not known:
        live streams; found in whole recordings by ``footnav.pipeline.navigation.saturation``).
    """

    t_s: F64
    acc_b_mps2: F64
    gyr_b_radps: F64
    counter: NDArray[np.int64]
    host_ns: NDArray[np.int64]
    gyr_clipped_b: NDArray[np.bool_] | None = None

    def __len__(self) -> int:
        return int(self.t_s.shape[0])

    def select(self, index: slice | NDArray[np.bool_]) -> ImuBatch:
        """The samples at ``index`` (a slice or a boolean mask), as a batch."""
        return ImuBatch(
            t_s=self.t_s[index],
            acc_b_mps2=self.acc_b_mps2[index],
            gyr_b_radps=self.gyr_b_radps[index],
            counter=self.counter[index],
            host_ns=self.host_ns[index],
            gyr_clipped_b=None if self.gyr_clipped_b is None else self.gyr_clipped_b[index],
        )

    @staticmethod
    def concat(batches: list[ImuBatch]) -> ImuBatch:
        """Join batches in order into one (clipped flags where any batch has them)."""
        if len(batches) == 1:
            return batches[0]
        clipped = None
        if any(b.gyr_clipped_b is not None for b in batches):
            clipped = np.concatenate(
                [np.zeros((len(b), 3), dtype=bool) if b.gyr_clipped_b is None else b.gyr_clipped_b for b in batches]
            )
        return ImuBatch(
            t_s=np.concatenate([b.t_s for b in batches]),
            acc_b_mps2=np.concatenate([b.acc_b_mps2 for b in batches]),
            gyr_b_radps=np.concatenate([b.gyr_b_radps for b in batches]),
            counter=np.concatenate([b.counter for b in batches]),
            host_ns=np.concatenate([b.host_ns for b in batches]),
            gyr_clipped_b=clipped,
        )
