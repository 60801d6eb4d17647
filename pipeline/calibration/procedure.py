"""The guided calibration procedure as a sans-I/O state machine: samples in, events out.

:class:`FaceCollector` is fed batches of samples (live, or from a capture: the same code) and tells
the caller what happened, as :class:`ProcedureEvent` s the terminal prints:

1. ``seeking``: wait until the unit has been still for ``settle_s`` (blocks of ``block_s``: still
   when the block's mean rate is under ``gyr_still_radps`` and its mean specific force moved less
   than ``acc_step_mps2`` since the previous block);
2. ``capturing``: average ``capture_s`` of still samples; motion before then rejects the capture
   ("moved"); a capture is reduced by :func:`footnav.pipeline.calibration.model.face_from_samples` (which may
   reject it for motion or saturation) and compared with the faces already captured: a face seen
   before is rejected ("seen"), a new one accepted ("captured", with its quality);
3. ``waiting``: wait for motion (the turn to the next face), then back to 1.

After each accepted face, once there are enough, the fit is tried; the procedure is ``done`` when the
fit is well determined (:meth:`footnav.pipeline.calibration.model.ImuCalibration.well_determined`), or fails
(``failed``, with what to redo) when ``max_faces`` faces did not determine it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final, Literal

import numpy as np
from footnav.pipeline.calibration.model import (
    MIN_FACES,
    MIN_FACES_NO_TEMPERATURE,
    STANDARD_GRAVITY_MPS2,
    CalibrationError,
    FaceCapture,
    ImuCalibration,
    face_from_samples,
    fit_calibration,
    matching_face,
)
from numpy.typing import NDArray

F64 = NDArray[np.float64]

BLOCK_S: Final = 0.05
SETTLE_S: Final = 0.5
CAPTURE_S: Final = 2.0
GYR_STILL_RADPS: Final = math.radians(5.0)
ACC_STEP_MPS2: Final = 0.1
MAX_FACES: Final = 20

EventKind = Literal["still", "captured", "moved", "seen", "rejected", "done", "failed"]


@dataclass(frozen=True, slots=True)
class ProcedureEvent:
    """Something the user should hear about.

    Attributes
    ----------
    kind
        ``still`` (capture started), ``captured`` (a new face), ``moved`` (motion during a capture), ``seen`` (a face
        captured before), ``rejected`` (saturation or motion found in the capture), ``done`` (the fit is well
        determined), ``failed`` (it cannot be).
    t_s
        device time of the event, s.
    message
        one line for the terminal.
    face
        the capture (``captured``), else None.
    calibration
        the fit (``done``), else None.
    """

    kind: EventKind
    t_s: float
    message: str
    face: FaceCapture | None = None
    calibration: ImuCalibration | None = None


class FaceCollector:
    """Collect still faces from a stream and fit when they determine the calibration.

    Parameters
    ----------
    rate_hz
        sample rate, Hz.
    capture_s
        still time averaged per face, s.
    settle_s
        still time required before a capture starts, s.
    max_faces
        stop (``failed``) after this many faces without a well-determined fit.
    allow_no_temperature
        fit the 9-parameter model if the temperature is unobservable.
    gravity_mps2
        local gravity for the fit.
    """

    def __init__(
        self,
        rate_hz: float,
        *,
        capture_s: float = CAPTURE_S,
        settle_s: float = SETTLE_S,
        max_faces: int = MAX_FACES,
        allow_no_temperature: bool = False,
        gravity_mps2: float = STANDARD_GRAVITY_MPS2,
    ) -> None:
        self.rate_hz = rate_hz
        self._block = max(1, round(BLOCK_S * rate_hz))
        self._settle_blocks = max(1, math.ceil(settle_s / BLOCK_S))
        self._capture_n = round(capture_s * rate_hz)
        self.max_faces = max_faces
        self.allow_no_temperature = allow_no_temperature
        self.gravity_mps2 = gravity_mps2
        self.state: Literal["seeking", "capturing", "waiting", "finished"] = "seeking"
        self.faces: list[FaceCapture] = []
        self.calibration: ImuCalibration | None = None
        self.last_error: CalibrationError | None = None
        self._still_blocks = 0
        self._prev_acc: F64 | None = None
        self._buf_acc: list[F64] = []
        self._buf_gyr: list[F64] = []
        self._buf_temp: list[F64] = []
        self._buf_t: list[F64] = []
        self._cap_acc: list[F64] = []
        self._cap_gyr: list[F64] = []
        self._cap_temp: list[F64] = []
        self._has_temp = True

    @property
    def min_faces(self) -> int:
        """Faces needed before a fit is tried."""
        return MIN_FACES_NO_TEMPERATURE if self.allow_no_temperature else MIN_FACES

    def feed(self, t_s: F64, acc_b_mps2: F64, gyr_b_radps: F64, temp_c: F64 | None) -> list[ProcedureEvent]:
        """Process (n,) times, (n, 3) specific force and rate, (n,) temperature or None; return the events."""
        if temp_c is None:
            self._has_temp = False
            temp_c = np.full(len(t_s), np.nan)
        self._buf_t.append(np.asarray(t_s, dtype=np.float64))
        self._buf_acc.append(np.asarray(acc_b_mps2, dtype=np.float64))
        self._buf_gyr.append(np.asarray(gyr_b_radps, dtype=np.float64))
        self._buf_temp.append(np.asarray(temp_c, dtype=np.float64))
        t = np.concatenate(self._buf_t)
        acc = np.concatenate(self._buf_acc)
        gyr = np.concatenate(self._buf_gyr)
        temp = np.concatenate(self._buf_temp)
        nb = len(t) // self._block
        used = nb * self._block
        self._buf_t, self._buf_acc = [t[used:]], [acc[used:]]
        self._buf_gyr, self._buf_temp = [gyr[used:]], [temp[used:]]
        events: list[ProcedureEvent] = []
        for i in range(nb):
            sl = slice(i * self._block, (i + 1) * self._block)
            if self.state == "finished":
                break
            ev = self._block_step(float(t[sl][-1]), acc[sl], gyr[sl], temp[sl])
            if ev is not None:
                events.extend(ev)
        return events

    def _is_still(self, acc: F64, gyr: F64) -> bool:
        mean_acc = acc.mean(axis=0)
        prev, self._prev_acc = self._prev_acc, mean_acc
        if float(np.linalg.norm(gyr.mean(axis=0))) >= GYR_STILL_RADPS:
            return False
        return prev is not None and float(np.max(np.abs(mean_acc - prev))) < ACC_STEP_MPS2

    def _block_step(self, t_end: float, acc: F64, gyr: F64, temp: F64) -> list[ProcedureEvent] | None:
        still = self._is_still(acc, gyr)
        if self.state == "waiting":
            if not still:
                self.state = "seeking"
                self._still_blocks = 0
            return None
        if self.state == "seeking":
            self._still_blocks = self._still_blocks + 1 if still else 0
            if self._still_blocks >= self._settle_blocks:
                self.state = "capturing"
                self._cap_acc, self._cap_gyr, self._cap_temp = [], [], []
                return [ProcedureEvent("still", t_end, "still: capturing this face, keep it still")]
            return None
        # capturing
        if not still:
            self.state = "seeking"
            self._still_blocks = 0
            return [ProcedureEvent("moved", t_end, "moved during the capture: hold the unit still on the face")]
        self._cap_acc.append(acc)
        self._cap_gyr.append(gyr)
        self._cap_temp.append(temp)
        if sum(len(a) for a in self._cap_acc) < self._capture_n:
            return None
        self.state = "waiting"
        return self._finish_capture(t_end)

    def _finish_capture(self, t_end: float) -> list[ProcedureEvent]:
        temp = np.concatenate(self._cap_temp)
        try:
            face = face_from_samples(
                np.concatenate(self._cap_acc),
                np.concatenate(self._cap_gyr),
                temp if self._has_temp else None,
                self.rate_hz,
            )
        except CalibrationError as exc:
            self.state = "seeking"
            self._still_blocks = 0
            return [ProcedureEvent("rejected", t_end, str(exc))]
        seen = matching_face(face.direction, [f.direction for f in self.faces])
        if seen is not None:
            return [ProcedureEvent("seen", t_end, f"face {seen + 1} was captured already: turn the unit to a new face")]
        self.faces.append(face)
        norm = float(np.linalg.norm(face.acc_mean_mps2))
        temp_txt = f", {float(np.nanmean(face.temp_win_c)):.1f} °C" if self._has_temp else ""
        events = [
            ProcedureEvent(
                "captured",
                t_end,
                f"face {len(self.faces)} captured: |a| = {norm:.3f} m/s², noise "
                f"{1e3 * face.acc_noise_mps2 / STANDARD_GRAVITY_MPS2:.1f} mg{temp_txt}; turn to a new face",
                face=face,
            )
        ]
        if len(self.faces) >= self.min_faces:
            events.extend(self._try_fit(t_end))
        return events

    def _try_fit(self, t_end: float) -> list[ProcedureEvent]:
        last = len(self.faces) >= self.max_faces
        try:
            cal = fit_calibration(
                self.faces, gravity_mps2=self.gravity_mps2, allow_no_temperature=self.allow_no_temperature
            )
        except CalibrationError as exc:  # not yet determined (IllDeterminedError) or not determinable
            self.last_error = exc
            if not last:
                return []
            self.state = "finished"
            return [ProcedureEvent("failed", t_end, str(exc))]
        self.calibration = cal
        self.state = "finished"
        return [
            ProcedureEvent(
                "done",
                t_end,
                f"calibration determined from {cal.n_faces} faces "
                f"(residual RMS {1e3 * cal.residual_rms_mps2:.2f} mm/s²)",
                calibration=cal,
            )
        ]

    def finish(self) -> ImuCalibration:
        """The fit from the faces so far (when the stream ends before ``done``).

        Raises
        ------
        CalibrationError
            what to redo (too few faces, temperature, not determined).
        """
        if self.calibration is not None:
            return self.calibration
        return fit_calibration(
            self.faces, gravity_mps2=self.gravity_mps2, allow_no_temperature=self.allow_no_temperature
        )
