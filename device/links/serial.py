"""USB-CDC serial link on asyncio: pyserial through ``serial_asyncio_fast``, errors as ``DeviceError``.

The port is opened exclusively (``flock``), so a second footnav (or a terminal program that also
locks) cannot read the same unit. Baud rate is meaningless on USB-CDC; 115200 is what the vendor
scripts use (protocol-openshoe.md section 2). Pitfalls of ptys and pyserial: transports-and-emulation.md
section 1.2.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
from types import TracebackType
from typing import Final, Self

import serial
import serial_asyncio_fast
from footnav.device.errors import DeviceError

DEFAULT_BAUDRATE: Final = 115200
READ_SIZE: Final = 1 << 16


class SerialLink:
    """A byte stream to a unit on a serial port.

    Use as ``async with SerialLink(port) as link:`` or call :meth:`open` and :meth:`close`.
    """

    def __init__(self, port: str, *, baudrate: int = DEFAULT_BAUDRATE) -> None:
        self.port = port
        self.baudrate = baudrate
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None
        self._closed = False

    @property
    def name(self) -> str:
        """The port, for messages."""
        return self.port

    async def open(self) -> None:
        """Open the port exclusively.

        Raises
        ------
        DeviceError
            the port does not exist, is busy (locked by another program), or cannot be opened for another reason
            (permissions, not a tty).
        """
        try:
            self._reader, self._writer = await serial_asyncio_fast.open_serial_connection(
                url=self.port, baudrate=self.baudrate, exclusive=True
            )
        except serial.SerialException as exc:
            raise _open_error(self.port, exc) from exc
        except OSError as exc:  # pragma: no cover - pyserial wraps most OSErrors already
            raise DeviceError(f"cannot open {self.port}: {exc.strerror or exc}") from exc
        self._closed = False

    async def read(self, max_bytes: int = READ_SIZE) -> bytes:
        """Return the next bytes received (at least one), or ``b""`` once :meth:`close` was called.

        The port is polled only while a read waits: between reads the bytes wait in the kernel's
        tty buffer (kilobytes; 10 ms of a unit at 1 kHz is about 300 bytes), so a caller that
        reads every few ms (``OpenShoeUnit(read_interval_s=...)``) takes one wake-up per read
        instead of one per packet.

        Raises
        ------
        DeviceError
            the unit was disconnected (or the port failed) during the read.
        """
        if self._reader is None:
            if self._closed:
                return b""
            raise DeviceError(f"{self.port} is not open")
        transport = self._writer.transport if self._writer is not None else None
        if isinstance(transport, asyncio.ReadTransport):
            transport.resume_reading()
        try:
            data = await self._reader.read(max_bytes)
        except serial.SerialException as exc:
            raise DeviceError(f"the unit on {self.port} was disconnected ({exc})") from exc
        except OSError as exc:
            raise DeviceError(f"the unit on {self.port} was disconnected ({exc})") from exc
        if not data and not self._closed:
            raise DeviceError(f"the unit on {self.port} was disconnected (end of stream)")
        if isinstance(transport, asyncio.ReadTransport) and not transport.is_closing():
            transport.pause_reading()
        return data

    async def write(self, data: bytes) -> None:
        """Send ``data`` and wait until the transport has taken it.

        Raises
        ------
        DeviceError
            the port is not open or the write failed.
        """
        if self._writer is None or self._writer.is_closing():
            raise DeviceError(f"cannot write to {self.port}: the port is not open (unit disconnected?)")
        try:
            self._writer.write(data)
            await self._writer.drain()
        except (serial.SerialException, OSError) as exc:
            raise DeviceError(f"cannot write to {self.port}: {exc}") from exc

    async def close(self) -> None:
        """Close the port (idempotent); a pending :meth:`read` then returns ``b""``."""
        self._closed = True
        writer, self._writer, self._reader = self._writer, None, None
        if writer is None:
            return
        writer.close()
        with contextlib.suppress(serial.SerialException, OSError):  # already gone (unplugged)
            await writer.wait_closed()

    async def __aenter__(self) -> Self:
        await self.open()
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        await self.close()


def _open_error(port: str, exc: serial.SerialException) -> DeviceError:
    """Translate pyserial's open failure into a one-line message a person can act on."""
    code = getattr(exc, "errno", None)
    if code == errno.ENOENT:
        return DeviceError(f"no such port {port} — is the unit plugged in? `ls /dev/ttyACM*`")
    if code in (errno.EAGAIN, errno.EWOULDBLOCK) or "exclusively lock" in str(exc):
        return DeviceError(f"{port} is busy: another program has it open (close it, or check `fuser {port}`)")
    if code == errno.EBUSY:
        return DeviceError(f"{port} is busy: another program has it open (check `fuser {port}`)")
    if code == errno.EACCES:
        return DeviceError(f"permission denied on {port}: add yourself to the dialout group and log in again")
    if _is_not_a_tty(exc):
        return DeviceError(
            f"{port} is not a serial port (it does not take serial settings); give the unit's port, "
            "e.g. /dev/ttyACM0 (`footnav scan` lists them)"
        )
    return DeviceError(f"cannot open {port}: {exc}")


def _is_not_a_tty(exc: BaseException) -> bool:
    """pyserial's open failed because the device takes no terminal settings (``ENOTTY``: a file,
    ``/dev/null``): pyserial wraps the ``termios.error`` in a message, so its cause is looked at too."""
    seen: BaseException | None = exc
    for _ in range(4):
        if seen is None:
            return False
        if getattr(seen, "errno", None) == errno.ENOTTY or (seen.args and seen.args[0] == errno.ENOTTY):
            return True
        if "Inappropriate ioctl" in str(seen):
            return True
        seen = seen.__cause__ or seen.__context__
    return False
