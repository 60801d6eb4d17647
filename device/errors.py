"""The device layer's errors: a unit or its link failed, or its bytes do not fit the protocol."""

from __future__ import annotations

from footnav.pipeline.errors import FootnavError


class DeviceError(FootnavError):
    """A unit or its link failed: port missing or busy, no answer, unplugged."""


class ProtocolError(FootnavError):
    """Bytes that do not fit the unit's protocol where the session cannot go on without them."""


class UnsupportedModeError(DeviceError):
    """The unit's firmware lacks the output mode asked for (2014 MIMU22BT firmware: stepwise only)."""
