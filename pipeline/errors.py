"""footnav's exception tree: one root, a few typed subclasses, messages a person can act on."""

from __future__ import annotations


class FootnavError(Exception):
    """Root of every error footnav raises on purpose. ``str(err)`` is one line for the terminal."""


class DeviceError(FootnavError):
    """A unit or its link failed: port missing or busy, no answer, unplugged."""


class ProtocolError(FootnavError):
    """Bytes that do not fit the unit's protocol where the session cannot go on without them."""


class InputFormatError(FootnavError):
    """A file is not in the format that was expected; the message names the expected format."""
