"""Stepwise dead reckoning (SWDR, command 0x34; 0x14 on 2014 firmware): 64-byte packets and the track.

Packet (protocol-openshoe.md 5.1), big-endian, payload 58 = 0x3A bytes::

    AA pkt_hi pkt_lo 3A | dx dy dz dθ  float32×4 | dP float32×10 | step counter uint16 | chk uint16

- dx, dy, dz: displacement since the previous filter reset, in the frame whose heading was zeroed at
  that reset, z down; dθ: heading change (atan2(R21, R11) just before the reset), about z down.
- dP: upper triangle of the 4×4 covariance of (x, y, z, ψ), row-major: Pxx Pxy Pxz Pxψ Pyy Pyz Pyψ
  Pzz Pzψ Pψψ.
- The unit queues packets losslessly: the host must ACK **every** packet, resends included, with
  ``01 pp pp chk`` (``Commands2015.ack``); unACKed, the same packet comes again about every 128 ms.

**Frame conversion at this boundary** (as in :mod:`footnav.device.protocol.ins_states`, rotation by π about x):
(dx, dy, dz, dθ) -> (dx, −dy, −dz, −dθ) and dP -> T dP Tᵀ, T = diag(1, −1, −1, −1). The track is
then accumulated in footnav's right-handed z-up frame, which gives exactly the GT host apps'
(``OpenDaRe`` ``stepwise_dr_tu``, ``ObluIoT.py`` ``calc_disp``) result rotated by R.

**Accumulation** (:class:`StepwiseTracker`), once per package number:
rotate the step by the heading ψ accumulated *before* it, add it, then ψ += dψ::

    s = (x, y, z, ψ);  s' = f(s, d) = (x + c·dx − σ·dy, y + σ·dx + c·dy, z + dz, ψ + dψ),  c, σ = cos ψ, sin ψ
    P' = F P Fᵀ + G Q Gᵀ,   F = ∂f/∂s = I except F[0, 3] = −σ dx − c dy, F[1, 3] = c dx − σ dy,
                            G = ∂f/∂d = blockdiag([[c, −σ], [σ, c]], 1, 1),  Q = the step's dP

so the accumulated track carries a first-order covariance. While the wearer stands still the unit
still sends a packet about every second with ≈0 displacement: such packets (|Δ| < 5 cm, the GT apps'
threshold) are applied (their heading change may be a turn on the spot) but not counted as steps.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Final

import numpy as np
from footnav.device.protocol.sequence import CounterTracker
from numpy.typing import NDArray

PAYLOAD_LEN: Final = 58
PACKET_LEN: Final = PAYLOAD_LEN + 6
PAYLOAD_DTYPE: Final = np.dtype([("dx", ">f4", (4,)), ("dp", ">f4", (10,)), ("step", ">u2")])
MIN_STEP_M: Final = 0.05
"""Displacements shorter than this are standing-still resets, not steps (GT apps: 5 cm)."""
STEP_SIGNS: Final = np.array([1.0, -1.0, -1.0, -1.0])
"""Diagonal of T: (dx, dy, dz, dθ) z-down <-> z-up (self-inverse)."""
_TRIU4: Final = np.triu_indices(4)


@dataclass(frozen=True, slots=True)
class StepArrays:
    """Decoded SWDR payloads, in footnav's frame (z up).

    Attributes
    ----------
    dx_m
        (n, 3) displacement in the heading frame of the previous reset, m.
    dheading_rad
        (n,) heading change, rad (positive = counter-clockwise seen from above).
    cov_4x4
        (n, 4, 4) covariance of (dx, dy, dz, dψ).
    step_counter
        (n,) the unit's uint16 step counter.
    """

    dx_m: NDArray[np.float64]
    dheading_rad: NDArray[np.float64]
    cov_4x4: NDArray[np.float64]
    step_counter: NDArray[np.int64]


def unpack_cov4(packed: NDArray[np.floating]) -> NDArray[np.float64]:
    """(n, 10) upper triangles, row-major -> (n, 4, 4)."""
    packed = np.asarray(packed, dtype=np.float64)
    full = np.zeros((packed.shape[0], 4, 4))
    full[:, _TRIU4[0], _TRIU4[1]] = packed
    full[:, _TRIU4[1], _TRIU4[0]] = packed
    return full


def pack_cov4(cov: NDArray[np.floating]) -> NDArray[np.float64]:
    """(n, 4, 4) -> (n, 10) upper triangles, row-major."""
    return np.asarray(cov, dtype=np.float64)[:, _TRIU4[0], _TRIU4[1]]


def decode_payloads(payloads: bytes | bytearray | memoryview) -> StepArrays:
    """Decode n concatenated 58-byte payloads and convert them to footnav's frame.

    Raises
    ------
    ValueError
        the length is not a multiple of 58.
    """
    if len(payloads) % PAYLOAD_LEN:
        raise ValueError(f"stepwise payloads are {PAYLOAD_LEN} bytes each; got {len(payloads)} bytes")
    rec = np.frombuffer(payloads, dtype=PAYLOAD_DTYPE)
    dx = rec["dx"].astype(np.float64) * STEP_SIGNS
    cov = unpack_cov4(rec["dp"]) * np.outer(STEP_SIGNS, STEP_SIGNS)
    return StepArrays(dx[:, :3], dx[:, 3], cov, rec["step"].astype(np.int64))


def encode_payloads(
    dx_m: NDArray[np.floating],
    dheading_rad: NDArray[np.floating],
    cov_4x4: NDArray[np.floating],
    step_counter: NDArray[np.integer],
) -> NDArray[np.uint8]:
    """Encode n steps given in footnav's frame as an (n, 58) byte matrix (for the emulator)."""
    n = len(dheading_rad)
    rec = np.zeros(n, dtype=PAYLOAD_DTYPE)
    rec["dx"] = np.column_stack([np.asarray(dx_m, dtype=np.float64), dheading_rad]) * STEP_SIGNS
    rec["dp"] = pack_cov4(np.asarray(cov_4x4, dtype=np.float64) * np.outer(STEP_SIGNS, STEP_SIGNS))
    rec["step"] = np.asarray(step_counter, dtype=np.int64) % (1 << 16)
    return rec.view(np.uint8).reshape(n, PAYLOAD_LEN)


@dataclass(frozen=True, slots=True)
class StepBatch:
    """SWDR packets applied to the track (each package number once), in footnav's frame.

    Attributes
    ----------
    counter
        (n,) unwrapped package numbers.
    step_counter
        (n,) the unit's step counter.
    dx_m
        (n, 3) each step in the heading frame of the previous reset, m.
    dheading_rad
        (n,) heading change of each step, rad.
    step_cov_4x4
        (n, 4, 4) covariance of (dx, dy, dz, dψ) of each step.
    pos_n_m
        (n, 3) accumulated position after each step, m (start = origin).
    heading_rad
        (n,) accumulated heading after each step, rad (start = 0, not wrapped).
    cov_4x4
        (n, 4, 4) covariance of the accumulated (x, y, z, ψ).
    is_step
        (n,) False for standing-still resets (|Δ| < :data:`MIN_STEP_M`).
    host_ns
        (n,) host receive time of the read.
    """

    counter: NDArray[np.int64]
    step_counter: NDArray[np.int64]
    dx_m: NDArray[np.float64]
    dheading_rad: NDArray[np.float64]
    step_cov_4x4: NDArray[np.float64]
    pos_n_m: NDArray[np.float64]
    heading_rad: NDArray[np.float64]
    cov_4x4: NDArray[np.float64]
    is_step: NDArray[np.bool_]
    host_ns: NDArray[np.int64]

    def __len__(self) -> int:
        return int(self.counter.shape[0])


@dataclass
class StepwiseTracker:
    """Accumulates SWDR packets into a track with covariance; resends are applied once.

    Call :meth:`update` with every packet received (resends too: the caller ACKs all of them);
    a package number at or behind the last applied one (modulo 2**16) is ignored. A number is
    believed only in its run (:class:`footnav.device.protocol.sequence.CounterTracker`, lossless: the
    unit sends in order): one that jumps is held until the next packets continue from it, and
    rejected, in :attr:`corrupt_numbers`, when they continue the run instead, so a corrupt number
    that passed the checksum neither applies a step out of place nor makes the next steps look
    like resends (the unit resends the real packet, which it was not ACKed for).
    """

    min_step_m: float = MIN_STEP_M
    pos_n_m: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    heading_rad: float = 0.0
    cov_4x4: NDArray[np.float64] = field(default_factory=lambda: np.zeros((4, 4)))
    steps: int = 0
    """Packets with |Δ| >= ``min_step_m``."""
    stationary: int = 0
    """Standing-still resets (applied, not counted as steps)."""
    repeats_ignored: int = 0
    """Packets whose number was already applied (resends)."""
    _last: int | None = None
    _numbers: CounterTracker = field(default_factory=lambda: CounterTracker(far_ahead=1))
    _held: list[bytes] = field(default_factory=list)

    @property
    def corrupt_numbers(self) -> int:
        """Packets rejected because their number left the run."""
        return self._numbers.corrupt_numbers

    def update(self, numbers: NDArray[np.integer] | list[int], payloads: bytes, host_ns: int = 0) -> StepBatch | None:
        """Apply the new packets among ``numbers`` (n,) / ``payloads`` (n × 58 bytes), in order.

        Returns
        -------
        StepBatch | None
            The applied packets, or None if all were repeats.
        """
        raw = np.asarray(numbers, dtype=np.int64)
        decode_payloads(payloads)  # validates the length
        rows = self._held + [bytes(payloads[k * PAYLOAD_LEN : (k + 1) * PAYLOAD_LEN]) for k in range(raw.size)]
        repeats = self._numbers.duplicates
        tracked = self._numbers.track(raw)
        self._held = [rows[i] for i in tracked.held.tolist()]
        self.repeats_ignored += self._numbers.duplicates - repeats
        keep: list[bytes] = []
        counters: list[int] = []
        for i, total in zip(tracked.positions.tolist(), tracked.counter.tolist(), strict=True):
            if self._last is not None and total <= self._last:  # late: the track went on past it
                self.repeats_ignored += 1
                continue
            keep.append(rows[i])
            counters.append(total)
            self._last = total
        if not keep:
            return None
        arrays = decode_payloads(b"".join(keep))
        idx = np.arange(len(keep))
        dx, dpsi, q = arrays.dx_m[idx], arrays.dheading_rad[idx], arrays.cov_4x4[idx]
        n = idx.size
        pos = np.empty((n, 3))
        heading = np.empty(n)
        cov = np.empty((n, 4, 4))
        p, psi, P = self.pos_n_m.copy(), self.heading_rad, self.cov_4x4.copy()
        for k in range(n):
            c, s = np.cos(psi), np.sin(psi)
            d = dx[k]
            F = np.eye(4)
            F[0, 3] = -s * d[0] - c * d[1]
            F[1, 3] = c * d[0] - s * d[1]
            G = np.eye(4)
            G[:2, :2] = [[c, -s], [s, c]]
            P = F @ P @ F.T + G @ q[k] @ G.T
            p = p + np.array([c * d[0] - s * d[1], s * d[0] + c * d[1], d[2]])
            psi += float(dpsi[k])
            pos[k], heading[k], cov[k] = p, psi, P
        self.pos_n_m, self.heading_rad, self.cov_4x4 = p, psi, P
        is_step = np.linalg.norm(dx, axis=1) >= self.min_step_m
        self.steps += int(np.count_nonzero(is_step))
        self.stationary += int(n - np.count_nonzero(is_step))
        return StepBatch(
            counter=np.asarray(counters, dtype=np.int64),
            step_counter=arrays.step_counter[idx],
            dx_m=dx,
            dheading_rad=dpsi,
            step_cov_4x4=q,
            pos_n_m=pos,
            heading_rad=heading,
            cov_4x4=cov,
            is_step=is_step,
            host_ns=np.full(n, host_ns, dtype=np.int64),
        )
