"""footnav's exception tree: one root, a few typed subclasses, messages a person can act on.

The device layer's errors (:class:`footnav.device.errors.DeviceError`,
:class:`footnav.device.errors.ProtocolError`) derive from the same root.
"""

from __future__ import annotations


class FootnavError(Exception):
    """Root of every error footnav raises on purpose. ``str(err)`` is one line for the terminal."""


class InputFormatError(FootnavError):
    """A file is not in the format that was expected; the message names the expected format."""


class MissingExtraError(FootnavError, ImportError):
    """An optional dependency is not installed; the message names the extra that installs it."""
