"""The units footnav knows by model: base sample rate, command set, IMUs and the outputs they offer.

Used only to choose what to ask a unit for (its output mode, the rate divider's range) and to say
what rate that should give; the rate navigated at is always the one the unit's clock gives
(``footnav.device.protocol.imu.clock_rate_hz``), and a session warns when the two disagree.

Rates (protocol-openshoe.md 3.4, 7.1–7.4): the MIMU-era boards sample at 1 kHz (64 MHz clock, timer
divider 8000 with a ÷8 prescaler), output every 2**K-th sample, K = d − 1 from the mode byte's 4-bit
field d (3 bits for the raw output 0x28); OpenShoe's ADIS16367 at 819.2 Hz (dt = 2**-10 / 0.8 s).
A MIMU4444 asked for raw output with d = 4 sent packets 2 048 000 ticks (32 ms) apart: 31.25 Hz, a
250 Hz base.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

from footnav.device.protocol.commands import MAX_RATE_DIVIDER_LOG2, MAX_RAW_RATE_DIVIDER_LOG2, CommandSet

OUTPUTS: Final = ("imu", "raw", "ins", "steps")
"""The outputs footnav streams: calibrated IMU 0x40, raw IMUs 0x28, INS states, stepwise dead reckoning."""


@dataclass(frozen=True, slots=True)
class UnitModel:
    """One unit model.

    Attributes
    ----------
    name
        its key in :data:`UNIT_MODELS` (``--unit NAME``).
    title
        for messages.
    base_rate_hz
        the sample rate before the rate divider, Hz.
    command_set
        the firmware's command set (protocol-openshoe.md 3.3).
    imus
        IMUs on the board (the raw output's mask has this many bits).
    outputs
        what its firmware streams, of :data:`OUTPUTS`, best first (the default is the first).
    imu
        its IMU: the navigation profile (``footnav.pipeline.navigation.profiles``) and the emulated
        sensor grade of that name.
    """

    name: str
    title: str
    base_rate_hz: float
    command_set: CommandSet
    imus: int
    outputs: tuple[str, ...]
    imu: str = "mpu6500x4"

    @property
    def default_output(self) -> str:
        return self.outputs[0]

    def rate_hz(self, rate_divider_log2: int) -> float:
        """The output rate asked for with divider K, Hz."""
        return self.base_rate_hz / 2**rate_divider_log2

    def max_rate_divider(self, output: str) -> int:
        """The largest K the output's mode byte holds (the raw output's field is a bit shorter)."""
        return MAX_RAW_RATE_DIVIDER_LOG2 if output == "raw" else MAX_RATE_DIVIDER_LOG2


UNIT_MODELS: Final[dict[str, UnitModel]] = {
    m.name: m
    for m in (
        UnitModel("oblu", "Oblu", 1000.0, CommandSet.V2015, 4, OUTPUTS),
        UnitModel("mimu22bl", "GT Silicon MIMU22BL", 1000.0, CommandSet.V2015, 4, OUTPUTS),
        UnitModel("mimu4444", "GT Silicon MIMU4444", 250.0, CommandSet.V2015, 4, OUTPUTS),
        UnitModel("mimu22bt", "GT Silicon MIMU22BT (2014 firmware)", 1000.0, CommandSet.V2014, 4, ("steps",)),
        UnitModel("openshoe", "OpenShoe (ADIS16367)", 819.2, CommandSet.V2015, 1, ("imu", "ins", "steps"), "adis16367"),
    )
}
"""The known models by name."""
DEFAULT_MODEL: Final = UNIT_MODELS["oblu"]
"""What an unnamed unit is taken for: a 1 kHz board on the 2015 command set (the firmware is probed,
and 2014 firmware's stepwise output is taken instead)."""


def unit_model(name: str) -> UnitModel:
    """The model called ``name``.

    Raises
    ------
    KeyError
        an unknown name; the message lists the known ones.
    """
    try:
        return UNIT_MODELS[name]
    except KeyError:
        raise KeyError(f"unknown unit model {name!r}; known: {', '.join(UNIT_MODELS)}") from None
