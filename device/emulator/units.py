"""Emulated units by model (:data:`footnav.device.models.UNIT_MODELS`): base rate, command set, IMUs
and the on-board solutions their firmware streams, served on a pseudo-terminal.

The on-board INS states are the true ones with a plausible covariance that grows with the distance
walked (:func:`ins_from_truth`: position σ 1 cm + 0.5 % of the distance horizontally, 5 mm + 0.2 %
vertically, heading σ 0.2° + 0.05° per metre; OpenShoe's published figures are 0.2–1 % of the
distance, Nilsson et al. 2014); the stepwise packets are the true steps between the firmware's
filter resets (:func:`footnav.device.emulator.scripts.steps_from_truth`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from footnav.device.emulator.motion.gait import GaitTruth
from footnav.device.emulator.scripts import InsTruth, steps_from_truth, yaw_from_quat_wxyz
from footnav.device.emulator.serving.pty import PtyShoeServer
from footnav.device.models import UnitModel, unit_model
from numpy.typing import NDArray

F64 = NDArray[np.float64]


def ins_from_truth(truth: GaitTruth) -> InsTruth:
    """The on-board INS states of a walk: the true states and a covariance (n, 9, 9) of
    (δpos, δvel, δatt) growing with the distance walked (see the module docstring)."""
    step_m = np.linalg.norm(np.diff(truth.pos_n_m[:, :2], axis=0), axis=1)
    walked_m = np.concatenate([[0.0], np.cumsum(step_m)])
    n = walked_m.size
    sigma = np.empty((n, 9))
    sigma[:, 0:2] = (0.01 + 0.005 * walked_m)[:, None]
    sigma[:, 2] = 0.005 + 0.002 * walked_m
    sigma[:, 3:6] = 0.01
    sigma[:, 6:8] = np.radians(0.5)
    sigma[:, 8] = np.radians(0.2 + 0.05 * walked_m)
    cov = np.zeros((n, 9, 9))
    cov[:, np.arange(9), np.arange(9)] = sigma**2
    return InsTruth(truth.pos_n_m, truth.vel_n_mps, truth.quat_nb_wxyz, cov)


def emulated_unit(
    model: UnitModel | str, truth: GaitTruth, acc_b_mps2: F64, gyr_b_radps: F64, **server: Any
) -> PtyShoeServer:
    """A unit of ``model`` walking ``truth`` (sampled at the model's base rate), its IMU(s) reading
    ``acc_b_mps2``, ``gyr_b_radps`` (n, 3), or (n, k, 3) for k IMUs; ``server``: more
    :class:`~footnav.device.emulator.serving.pty.PtyShoeServer` options (speed, faults...).

    Raises
    ------
    ValueError
        the walk is not sampled at the model's base rate.
    """
    m = unit_model(model) if isinstance(model, str) else model
    if abs(truth.rate_hz / m.base_rate_hz - 1.0) > 1e-9:
        raise ValueError(f"{m.title} samples at {m.base_rate_hz:g} Hz; the walk is at {truth.rate_hz:g} Hz")
    acc, gyr = np.asarray(acc_b_mps2, dtype=np.float64), np.asarray(gyr_b_radps, dtype=np.float64)
    if acc.ndim == 2:
        acc, gyr = np.repeat(acc[:, None], m.imus, axis=1), np.repeat(gyr[:, None], m.imus, axis=1)
    steps = steps_from_truth(truth.t_s, truth.pos_n_m, yaw_from_quat_wxyz(truth.quat_nb_wxyz), truth.stance)
    return PtyShoeServer(
        truth.t_s,
        acc.mean(axis=1),
        gyr.mean(axis=1),
        imu_acc_b_mps2=acc,
        imu_gyr_b_radps=gyr,
        ins=ins_from_truth(truth) if "ins" in m.outputs else None,
        steps=steps if "steps" in m.outputs else None,
        command_set=m.command_set,
        **server,
    )
