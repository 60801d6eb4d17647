"""Full INS-state packets (states 0x01, 0x02, 0x20–0x23 requested with 0x20/0x21), vectorised.

After ``33 00 33`` (reset ZUPT-aided INS) a host requests states with OUTPUT_STATE(S); the unit packs
the requested states into one payload **in ascending state-ID order** (protocol-openshoe.md 4.2, 5.2):

    ID    bytes  content (big-endian)
    0x01  4      ts, uint32 64 MHz ticks
    0x02  4      interrupt counter, uint32
    0x20  12     position, float32×3, m           (nav frame, z down)
    0x21  12     velocity, float32×3, m/s         (nav frame, z down)
    0x22  16     quaternion, float32×4, x y z w   (vector part first, scalar LAST), body -> nav
    0x23  180    P, float32×45: upper triangle of the 9×9 error covariance, row-major,
                 error states (δpos, δvel, δatt) in the nav frame (section 7.2)

e.g. ts|pos|vel|quat = 44 bytes (50-byte packet); with P, 224 bytes.

**Frame conversion at this boundary.** OpenShoe's navigation frame has z pointing down (gravity is
added to the z acceleration) and x along the heading at alignment. footnav's frame is right-handed
with z up and the start heading along +x, so the conversion is the rotation by π about x,

    R = diag(1, −1, −1):   pos_n = R pos_ned,  vel_n = R vel_ned,  C_nb = R C_ned_b,
    quat_nb_wxyz = q_R ⊗ q_ned_b with q_R = (0, 1, 0, 0),  i.e. (w, x, y, z) -> (−x, w, −z, y),
    P_n = T P_ned Tᵀ with T = blockdiag(R, R, R)  (every 3-block of the error state rotates by R).

The body frame (the unit's sensor axes) is left as it is. Yaw therefore changes sign (a turn to the
right is negative in footnav). The quaternion is read as body-to-nav, as nav_eq's mechanisation uses it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Final

import numpy as np
from footnav.device.protocol import commands as protocol
from numpy.typing import NDArray

INS_STATE_IDS: Final = (
    protocol.STATE_IMU_TS,
    protocol.STATE_INTERRUPT_COUNTER,
    protocol.STATE_POSITION,
    protocol.STATE_VELOCITY,
    protocol.STATE_QUATERNION,
    protocol.STATE_P,
)
"""States this module decodes, in wire order."""
DEFAULT_INS_STATES: Final = (
    protocol.STATE_IMU_TS,
    protocol.STATE_POSITION,
    protocol.STATE_VELOCITY,
    protocol.STATE_QUATERNION,
)
_FIELDS: Final[dict[int, tuple[str, str, tuple[int, ...]]]] = {
    protocol.STATE_IMU_TS: ("ts", ">u4", ()),
    protocol.STATE_INTERRUPT_COUNTER: ("icount", ">u4", ()),
    protocol.STATE_POSITION: ("pos", ">f4", (3,)),
    protocol.STATE_VELOCITY: ("vel", ">f4", (3,)),
    protocol.STATE_QUATERNION: ("quat", ">f4", (4,)),
    protocol.STATE_P: ("cov", ">f4", (45,)),
}
NED_TO_UP: Final = np.array([1.0, -1.0, -1.0])
"""Diagonal of R, the rotation by π about x from OpenShoe's z-down nav frame to footnav's (self-inverse)."""
_COV_SIGNS: Final = np.outer(np.tile(NED_TO_UP, 3), np.tile(NED_TO_UP, 3))
_TRIU: Final = np.triu_indices(9)


@dataclass(frozen=True, slots=True)
class InsLayout:
    """The states of one INS payload, in wire (ascending ID) order.

    Raises
    ------
    ValueError
        a state this module does not decode, or none.
    """

    state_ids: tuple[int, ...] = DEFAULT_INS_STATES

    def __post_init__(self) -> None:
        unknown = [f"0x{s:02X}" for s in self.state_ids if s not in _FIELDS]
        if unknown or not self.state_ids:
            raise ValueError(f"INS payloads hold states {[f'0x{s:02X}' for s in INS_STATE_IDS]}; got {unknown}")
        object.__setattr__(self, "state_ids", tuple(sorted(set(self.state_ids))))

    @property
    def dtype(self) -> np.dtype[np.void]:
        """Structured big-endian dtype of one payload."""
        return np.dtype([_FIELDS[s] for s in self.state_ids])

    @property
    def payload_len(self) -> int:
        """Payload bytes."""
        return int(self.dtype.itemsize)

    def has(self, state_id: int) -> bool:
        """True if the payload holds ``state_id``."""
        return state_id in self.state_ids


@dataclass(frozen=True, slots=True)
class InsStateBatch:
    """On-board INS estimates, in footnav's navigation frame (z up), duplicates dropped.

    Attributes
    ----------
    t_s
        (n,) device time, s (NaN if the time stamp state 0x01 was not requested).
    pos_n_m
        (n, 3) position, m, or None if not requested.
    vel_n_mps
        (n, 3) velocity, m/s, or None.
    quat_nb_wxyz
        (n, 4) attitude body -> nav, scalar first, or None.
    cov_9x9
        (n, 9, 9) error covariance of (δpos, δvel, δatt), nav frame, or None.
    interrupt_counter
        (n,) the unit's sample counter, or None.
    counter
        (n,) unwrapped package numbers.
    host_ns
        (n,) host receive time of the read.
    """

    t_s: NDArray[np.float64]
    pos_n_m: NDArray[np.float64] | None
    vel_n_mps: NDArray[np.float64] | None
    quat_nb_wxyz: NDArray[np.float64] | None
    cov_9x9: NDArray[np.float64] | None
    interrupt_counter: NDArray[np.int64] | None
    counter: NDArray[np.int64]
    host_ns: NDArray[np.int64]

    def __len__(self) -> int:
        return int(self.counter.shape[0])

    def select(self, keep: NDArray[np.bool_]) -> InsStateBatch:
        """The samples where ``keep`` (n,) is True."""

        def part(a: NDArray[Any] | None) -> Any:
            return None if a is None else a[keep]

        return InsStateBatch(
            self.t_s[keep],
            part(self.pos_n_m),
            part(self.vel_n_mps),
            part(self.quat_nb_wxyz),
            part(self.cov_9x9),
            part(self.interrupt_counter),
            self.counter[keep],
            self.host_ns[keep],
        )


@dataclass(frozen=True, slots=True)
class InsArrays:
    """Decoded payloads, converted to footnav's frame (see the module docstring); None = not present."""

    ticks: NDArray[np.uint32] | None
    interrupt_counter: NDArray[np.int64] | None
    pos_n_m: NDArray[np.float64] | None
    vel_n_mps: NDArray[np.float64] | None
    quat_nb_wxyz: NDArray[np.float64] | None
    cov_9x9: NDArray[np.float64] | None


def quat_xyzw_ned_to_wxyz_up(quat_xyzw: NDArray[np.floating]) -> NDArray[np.float64]:
    """(n, 4) wire quaternions (x y z w, body -> z-down nav) -> (n, 4) ``quat_nb_wxyz`` in footnav's frame."""
    q = np.asarray(quat_xyzw, dtype=np.float64)
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.column_stack([-x, w, -z, y])


def quat_wxyz_up_to_xyzw_ned(quat_nb_wxyz: NDArray[np.floating]) -> NDArray[np.float64]:
    """Inverse of :func:`quat_xyzw_ned_to_wxyz_up` (for the emulator)."""
    q = np.asarray(quat_nb_wxyz, dtype=np.float64)
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.column_stack([-w, z, -y, x])  # q_ned = conj(q_R) ⊗ q_up = (x, −w, z, −y), as x y z w


def unpack_cov9(packed: NDArray[np.floating]) -> NDArray[np.float64]:
    """(n, 45) upper triangles, row-major -> (n, 9, 9) symmetric matrices (same frame)."""
    packed = np.asarray(packed, dtype=np.float64)
    full = np.zeros((packed.shape[0], 9, 9))
    full[:, _TRIU[0], _TRIU[1]] = packed
    full[:, _TRIU[1], _TRIU[0]] = packed
    return full


def pack_cov9(cov: NDArray[np.floating]) -> NDArray[np.float64]:
    """(n, 9, 9) -> (n, 45) upper triangles, row-major (offsets 0, 9, 17, 24, 30, 35, 39, 42, 44)."""
    return np.asarray(cov, dtype=np.float64)[:, _TRIU[0], _TRIU[1]]


def cov9_ned_to_up(cov: NDArray[np.floating]) -> NDArray[np.float64]:
    """T P Tᵀ with T = blockdiag(R, R, R); self-inverse, so it converts both ways."""
    return np.asarray(cov, dtype=np.float64) * _COV_SIGNS


def decode_payloads(payloads: bytes | bytearray | memoryview, layout: InsLayout) -> InsArrays:
    """Decode n concatenated payloads of ``layout`` and convert them to footnav's frame.

    Raises
    ------
    ValueError
        the length is not a multiple of the payload length.
    """
    size = layout.payload_len
    if len(payloads) % size:
        raise ValueError(f"INS payloads of states {layout.state_ids} are {size} bytes each; got {len(payloads)}")
    rec = np.frombuffer(payloads, dtype=layout.dtype)
    names = rec.dtype.names or ()
    return InsArrays(
        ticks=rec["ts"].astype(np.uint32) if "ts" in names else None,
        interrupt_counter=rec["icount"].astype(np.int64) if "icount" in names else None,
        pos_n_m=rec["pos"].astype(np.float64) * NED_TO_UP if "pos" in names else None,
        vel_n_mps=rec["vel"].astype(np.float64) * NED_TO_UP if "vel" in names else None,
        quat_nb_wxyz=quat_xyzw_ned_to_wxyz_up(rec["quat"]) if "quat" in names else None,
        cov_9x9=cov9_ned_to_up(unpack_cov9(rec["cov"])) if "cov" in names else None,
    )


def encode_payloads(
    layout: InsLayout,
    *,
    ticks: NDArray[np.integer] | None = None,
    interrupt_counter: NDArray[np.integer] | None = None,
    pos_n_m: NDArray[np.floating] | None = None,
    vel_n_mps: NDArray[np.floating] | None = None,
    quat_nb_wxyz: NDArray[np.floating] | None = None,
    cov_9x9: NDArray[np.floating] | None = None,
) -> NDArray[np.uint8]:
    """Encode n payloads from footnav-frame values as an (n, L) byte matrix (for the emulator).

    Arrays are (n,), (n, 3), (n, 4) or (n, 9, 9); states in ``layout`` whose array is None are zeros.

    Raises
    ------
    ValueError
        no array given to take n from.
    """
    given = [a for a in (ticks, interrupt_counter, pos_n_m, vel_n_mps, quat_nb_wxyz, cov_9x9) if a is not None]
    if not given:
        raise ValueError("encode_payloads needs at least one state array")
    n = len(given[0])
    rec = np.zeros(n, dtype=layout.dtype)
    names = rec.dtype.names or ()
    if "ts" in names and ticks is not None:
        rec["ts"] = np.asarray(ticks, dtype=np.int64) % (1 << 32)
    if "icount" in names and interrupt_counter is not None:
        rec["icount"] = np.asarray(interrupt_counter, dtype=np.int64) % (1 << 32)
    if "pos" in names and pos_n_m is not None:
        rec["pos"] = np.asarray(pos_n_m) * NED_TO_UP
    if "vel" in names and vel_n_mps is not None:
        rec["vel"] = np.asarray(vel_n_mps) * NED_TO_UP
    if "quat" in names and quat_nb_wxyz is not None:
        rec["quat"] = quat_wxyz_up_to_xyzw_ned(quat_nb_wxyz)
    if "cov" in names and cov_9x9 is not None:
        rec["cov"] = pack_cov9(cov9_ned_to_up(cov_9x9))
    return rec.view(np.uint8).reshape(n, layout.payload_len)
