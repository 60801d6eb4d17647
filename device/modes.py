"""The output modes a unit can be started in (protocol-openshoe.md sections 5, 6, 10)."""

from __future__ import annotations

from dataclasses import dataclass

from footnav.device.protocol import ins_states


@dataclass(frozen=True, slots=True)
class NormalImuMode:
    """Calibrated IMU (0x40, or 0x41 with on-board gyro-bias estimation), 34-byte packets."""

    rate_divider_log2: int = 0
    bias_estimation: bool = False
    lossless: bool = False


@dataclass(frozen=True, slots=True)
class RawImuMode:
    """Raw int16 registers of the IMUs in ``imu_mask`` (0x28); ``raw_imu.DUAL_IMU_MASK``: the dual board."""

    imu_mask: int = 0x0F
    rate_divider_log2: int = 0
    lossless: bool = False
    temperature: bool = False
    magnetometer: bool = False


@dataclass(frozen=True, slots=True)
class InsMode:
    """On-board ZUPT-aided INS states (0x33, then OUTPUT_STATE(S)); keep the unit still at the start."""

    state_ids: tuple[int, ...] = ins_states.DEFAULT_INS_STATES
    rate_divider_log2: int = 2
    lossless: bool = False


@dataclass(frozen=True, slots=True)
class StepwiseMode:
    """Stepwise dead reckoning (0x34; 0x14 on 2014 firmware): one lossless 64-byte packet per step."""


Mode = NormalImuMode | RawImuMode | InsMode | StepwiseMode
