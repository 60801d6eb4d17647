"""BLE byte link over bleak's public API (``BleakScanner``, ``BleakClient``), errors as ``DeviceError``.

A shoe unit's BLE module is a UART bridge: one characteristic notifies device -> host bytes, one takes
host -> device writes (protocol-openshoe.md section 8, transports-and-emulation.md section 3):

=========================  ========================================  ==================================
profile                    service                                   notify / write
=========================  ========================================  ==================================
MIMU22BL (USR-IoT UART)    ``0003CDD0-0000-1000-8000-00805F9B0131``  CDD1 notify / CDD2 write w/o resp.
Nordic UART (NUS)          ``6E400001-B5A3-F393-E0A9-E50E24DCCA9E``  6E400003 notify / 6E400002 write
HM-10 / CC2541             ``0000FFE0-0000-1000-8000-00805F9B34FB``  FFE1 both ways
=========================  ========================================  ==================================

Characteristics are chosen **by their properties**, not by name (micro:bit swaps NUS's roles): within
the known services, the notify (else indicate) characteristic and the write-without-response (else
write) characteristic; failing that, the only notify and the only write characteristic of the whole
device. Notifications are a byte stream: one may hold part of a packet or several, and the framer
re-frames (:mod:`footnav.device.protocol.framer`). Writes are cut to ``max_write_without_response_size`` (write
without response) or ``mtu_size - 3`` (write with response).

The bleak backend is injectable (:class:`BleBackend`, default: the platform's), which is how the
tests run this exact code against an emulated unit on bumble's virtual radio
(:mod:`footnav.device.emulator.serving.ble_backend`). Without a Bluetooth stack (no BlueZ/D-Bus, no adapter) bleak
raises ``FileNotFoundError``/``OSError``/``BleakError``; :class:`BleLink` turns that into one-line
``DeviceError`` (:func:`no_bluetooth_message`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import re
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import TracebackType
from typing import TYPE_CHECKING, Any, Final, Self

from footnav.device.errors import DeviceError

if TYPE_CHECKING:
    from bleak.backends.characteristic import BleakGATTCharacteristic
    from bleak.backends.client import BaseBleakClient
    from bleak.backends.device import BLEDevice
    from bleak.backends.scanner import AdvertisementData, BaseBleakScanner
    from bleak.backends.service import BleakGATTServiceCollection

log = logging.getLogger(__name__)

MIMU_SERVICE: Final = "0003cdd0-0000-1000-8000-00805f9b0131"
MIMU_NOTIFY: Final = "0003cdd1-0000-1000-8000-00805f9b0131"
MIMU_WRITE: Final = "0003cdd2-0000-1000-8000-00805f9b0131"
NUS_SERVICE: Final = "6e400001-b5a3-f393-e0a9-e50e24dcca9e"
NUS_RX: Final = "6e400002-b5a3-f393-e0a9-e50e24dcca9e"
"""Host -> device (write), named from the peripheral's view."""
NUS_TX: Final = "6e400003-b5a3-f393-e0a9-e50e24dcca9e"
"""Device -> host (notify)."""
HM10_SERVICE: Final = "0000ffe0-0000-1000-8000-00805f9b34fb"
HM10_CHAR: Final = "0000ffe1-0000-1000-8000-00805f9b34fb"

KNOWN_SERVICES: Final[Mapping[str, str]] = {
    MIMU_SERVICE: "MIMU22BL/Oblu UART (CDD0)",
    NUS_SERVICE: "Nordic UART",
    HM10_SERVICE: "HM-10 UART (FFE0)",
}
"""Service UUID (lower case, 128-bit) -> profile name, in order of preference."""

_STANDARD_SERVICES: Final = frozenset(
    f"0000{short}-0000-1000-8000-00805f9b34fb" for short in ("1800", "1801", "180a", "180f")
)
"""GAP, GATT, Device Information, Battery: never the data stream."""

DEFAULT_SCAN_TIMEOUT_S: Final = 10.0
DEFAULT_CONNECT_TIMEOUT_S: Final = 10.0
MAX_BUFFERED_BYTES: Final = 16 << 20
"""Notifications held for a reader that is not reading; beyond this they are dropped and counted."""

_ADDRESS_RE: Final = re.compile(
    r"^([0-9A-Fa-f]{2}(:[0-9A-Fa-f]{2}){5}|[0-9A-Fa-f]{8}-[0-9A-Fa-f]{4}-[0-9A-Fa-f]{4}-[0-9A-Fa-f]{4}-[0-9A-Fa-f]{12})$"
)
"""A Bluetooth address, or the per-host UUID macOS uses instead."""


@dataclass(frozen=True)
class BleBackend:
    """The bleak backend classes to use, with backend-specific keyword arguments.

    bleak takes ``backend=`` (a class) on ``BleakScanner`` and ``BleakClient`` separately; this pairs
    them. ``None`` wherever a backend is accepted means the platform's (BlueZ, WinRT, CoreBluetooth).
    """

    scanner: type[BaseBleakScanner]
    client: type[BaseBleakClient]
    scanner_kwargs: Mapping[str, Any] = field(default_factory=dict)
    """Extra keyword arguments for ``BleakScanner(...)`` (passed on to the backend)."""
    client_kwargs: Mapping[str, Any] = field(default_factory=dict)
    """Extra keyword arguments for ``BleakClient(...)`` (passed on to the backend)."""


def scanner_kwargs(backend: BleBackend | None) -> dict[str, Any]:
    """Keyword arguments selecting ``backend`` for ``BleakScanner`` and its classmethods."""
    if backend is None:
        return {}
    return {"backend": backend.scanner, **backend.scanner_kwargs}


def client_kwargs(backend: BleBackend | None) -> dict[str, Any]:
    """Keyword arguments selecting ``backend`` for ``BleakClient``."""
    if backend is None:
        return {}
    return {"backend": backend.client, **backend.client_kwargs}


def is_bluetooth_unavailable(exc: BaseException) -> bool:
    """True if ``exc`` means "no usable Bluetooth stack here" rather than "this unit failed"."""
    from bleak.exc import BleakBluetoothNotAvailableError, BleakDBusError, BleakError

    if isinstance(exc, TimeoutError):
        return False
    if isinstance(exc, BleakBluetoothNotAvailableError | OSError):
        return True  # FileNotFoundError: no /run/dbus/system_bus_socket; ConnectionRefused: no daemon
    if isinstance(exc, BleakDBusError):
        return "ServiceUnknown" in exc.dbus_error or "NoReply" in exc.dbus_error
    if isinstance(exc, BleakError):
        text = str(exc).lower()
        return "bluetooth device is turned off" in text or ("adapter" in text and "not found" in text)
    return False


def no_bluetooth_message(exc: BaseException) -> str:
    """One line for the terminal when bleak finds no Bluetooth stack."""
    detail = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
    return (
        f"no Bluetooth stack available ({detail}); on Linux BLE needs BlueZ running on the system "
        "D-Bus (`systemctl status bluetooth`) and an adapter"
    )


def is_address(target: str) -> bool:
    """True if ``target`` looks like a Bluetooth address (or a macOS device UUID), not a name."""
    return bool(_ADDRESS_RE.match(target))


def advertises_known_service(ad: AdvertisementData) -> str | None:
    """The first known UART service UUID in an advertisement, or None."""
    advertised = {u.lower() for u in ad.service_uuids}
    for service in KNOWN_SERVICES:
        if service in advertised:
            return service
    return None


@dataclass(frozen=True, slots=True)
class UartCharacteristics:
    """The characteristic pair chosen for the byte stream."""

    notify: BleakGATTCharacteristic
    write: BleakGATTCharacteristic
    write_with_response: bool
    """False when the write characteristic has write-without-response (preferred)."""
    service: str
    """Profile name (from :data:`KNOWN_SERVICES`) or "fallback"."""


def _can_notify(char: BleakGATTCharacteristic) -> bool:
    return "notify" in char.properties or "indicate" in char.properties


def _can_write(char: BleakGATTCharacteristic) -> bool:
    return "write-without-response" in char.properties or "write" in char.properties


def _pick(chars: list[BleakGATTCharacteristic], preferred_uuid: str | None) -> BleakGATTCharacteristic | None:
    """The one candidate, or the one with the preferred UUID among several."""
    if len(chars) == 1:
        return chars[0]
    matches = [c for c in chars if c.uuid == preferred_uuid]
    return matches[0] if len(matches) == 1 else None


def choose_characteristics(services: BleakGATTServiceCollection, where: str = "the unit") -> UartCharacteristics:
    """Choose the notify and write characteristics of a UART-style service by their properties.

    Raises
    ------
    DeviceError
        no (or no unambiguous) notify + write pair.
    """
    preferred = {
        MIMU_SERVICE: (MIMU_NOTIFY, MIMU_WRITE),
        NUS_SERVICE: (NUS_TX, NUS_RX),
        HM10_SERVICE: (HM10_CHAR, HM10_CHAR),
    }
    for service_uuid, profile in KNOWN_SERVICES.items():
        service = services.get_service(service_uuid)
        if service is None:
            continue
        chars = service.characteristics
        notify_uuid, write_uuid = preferred[service_uuid]
        notify = _pick([c for c in chars if _can_notify(c)], notify_uuid)
        wwr = [c for c in chars if "write-without-response" in c.properties]
        write = _pick(wwr, write_uuid) if wwr else _pick([c for c in chars if "write" in c.properties], write_uuid)
        if notify is not None and write is not None:
            return UartCharacteristics(notify, write, "write-without-response" not in write.properties, profile)
    candidates = [c for s in services if s.uuid not in _STANDARD_SERVICES for c in s.characteristics]
    notifiers = [c for c in candidates if _can_notify(c)]
    writers = [c for c in candidates if _can_write(c)]
    if len(notifiers) == 1 and len(writers) == 1:
        write = writers[0]
        return UartCharacteristics(notifiers[0], write, "write-without-response" not in write.properties, "fallback")
    found = ", ".join(f"{c.uuid} [{','.join(c.properties)}]" for c in candidates) or "none"
    raise DeviceError(
        f"{where} has no UART-style service (MIMU22BL CDD0, Nordic UART or HM-10 FFE0) and no single "
        f"notify + write characteristic pair; characteristics found: {found}"
    )


@dataclass(slots=True)
class BleLinkStats:
    """Counts since the link was created (over all its connections)."""

    notifications: int = 0
    bytes_received: int = 0
    min_notification: int = 0
    max_notification: int = 0
    bytes_dropped: int = 0
    """Notification bytes dropped because the reader fell more than ``MAX_BUFFERED_BYTES`` behind."""
    writes: int = 0
    """Write operations sent (after chunking)."""


class BleLink:
    """A byte stream to a shoe unit over BLE (a :class:`footnav.device.links.base.ByteLink`).

    Use as ``async with BleLink("MIMU22BL") as link:`` or :meth:`open` / :meth:`close`.

    Parameters
    ----------
    target
        a Bluetooth address (or macOS UUID), an advertised local name, a ``BLEDevice`` from a scan, or None for the
        first unit advertising a known UART service.
    backend
        bleak backend classes; None = the platform's.
    scan_timeout_s
        how long to look for the unit.
    connect_timeout_s
        bleak's connect timeout.
    """

    def __init__(
        self,
        target: str | BLEDevice | None = None,
        *,
        backend: BleBackend | None = None,
        scan_timeout_s: float = DEFAULT_SCAN_TIMEOUT_S,
        connect_timeout_s: float = DEFAULT_CONNECT_TIMEOUT_S,
    ) -> None:
        self.target = target
        self.backend = backend
        self.scan_timeout_s = scan_timeout_s
        self.connect_timeout_s = connect_timeout_s
        self._client: Any = None  # bleak.BleakClient, imported lazily
        self._uart: UartCharacteristics | None = None
        self._chunks: deque[bytes] = deque()
        self._buffered = 0
        self._wakeup = asyncio.Event()
        self._closed = False
        self._lost: str | None = None
        self._address: str | None = None
        self._name = self._describe_target()
        self.stats = BleLinkStats()

    def _describe_target(self) -> str:
        target = self.target
        if target is None:
            return "the first BLE shoe unit"
        if isinstance(target, str):
            return f"BLE unit {target}"
        return f"BLE unit {target.name or target.address} ({target.address})"

    @property
    def name(self) -> str:
        """The unit (name and address once connected), for messages."""
        return self._name

    @property
    def address(self) -> str | None:
        """The connected unit's address (None before the first connection)."""
        return self._address

    @property
    def mtu(self) -> int:
        """The negotiated ATT MTU (23 when unknown; bleak on BlueZ often reports 23)."""
        client = self._client
        if client is None:
            return 23
        with contextlib.suppress(Exception):
            return int(client.mtu_size)
        return 23  # pragma: no cover

    @property
    def uart(self) -> UartCharacteristics | None:
        """The characteristics in use (None before connecting)."""
        return self._uart

    @property
    def max_write_size(self) -> int:
        """Bytes per write operation (at least 20)."""
        uart = self._uart
        if uart is None:
            return 20
        if uart.write_with_response:
            return max(20, self.mtu - 3)
        return max(20, int(uart.write.max_write_without_response_size))

    @property
    def is_connected(self) -> bool:
        client = self._client
        return client is not None and bool(client.is_connected) and self._lost is None

    async def open(self) -> None:
        """Scan for the unit, connect, pick the characteristics and subscribe to notifications.

        Raises
        ------
        DeviceError
            no Bluetooth stack, unit not found, connection failed, or no UART service.
        """
        from bleak import BleakClient
        from bleak.exc import BleakError

        self._closed = False
        self._lost = None
        client = None
        try:
            device = await self._find()
            client = BleakClient(
                device,
                disconnected_callback=self._on_disconnect,
                timeout=self.connect_timeout_s,
                **client_kwargs(self.backend),
            )
            await client.connect()
            self._client = client
            self._address = client.address
            self._name = f"BLE unit {device.name or client.address} ({client.address})"
            self._uart = choose_characteristics(client.services, self._name)
            await client.start_notify(self._uart.notify, self._on_notify)
        except (BleakError, OSError, TimeoutError) as exc:
            await self._drop_client(client)
            if is_bluetooth_unavailable(exc):
                raise DeviceError(no_bluetooth_message(exc)) from exc
            raise DeviceError(f"cannot connect to {self._name}: {type(exc).__name__}: {exc}") from exc
        except BaseException:  # DeviceError, cancellation: don't leave a half-open connection
            await asyncio.shield(self._drop_client(client))
            raise
        log.info(
            "connected to %s: %s, MTU %d, write %s of <= %d bytes",
            self._name, self._uart.service, self.mtu,
            "with response" if self._uart.write_with_response else "without response", self.max_write_size,
        )  # fmt: skip

    async def _find(self) -> BLEDevice:
        from bleak import BleakScanner
        from bleak.backends.device import BLEDevice

        target = self.target
        if isinstance(target, BLEDevice):
            return target
        kwargs = scanner_kwargs(self.backend)
        if target is None:
            device = await BleakScanner.find_device_by_filter(
                lambda _d, ad: advertises_known_service(ad) is not None,
                timeout=self.scan_timeout_s,
                service_uuids=list(KNOWN_SERVICES),
                **kwargs,
            )
            what = "no BLE unit advertising a MIMU22BL, Nordic UART or HM-10 service"
        elif is_address(target):
            device = await BleakScanner.find_device_by_address(target, timeout=self.scan_timeout_s, **kwargs)
            what = f"no BLE device with address {target}"
        else:
            device = await BleakScanner.find_device_by_filter(
                lambda d, ad: target in (ad.local_name, d.name), timeout=self.scan_timeout_s, **kwargs
            )
            what = f"no BLE device named {target!r}"
        if device is None:
            raise DeviceError(
                f"{what} within {self.scan_timeout_s:g} s — is it on, charged and not connected to "
                "another host? (`footnav scan` lists what is advertising)"
            )
        return device

    async def _drop_client(self, client: Any) -> None:
        self._client = None
        if client is not None:
            with contextlib.suppress(Exception):
                await client.disconnect()

    def _on_notify(self, _char: BleakGATTCharacteristic, data: bytearray) -> None:
        n = len(data)
        stats = self.stats
        if self._buffered + n > MAX_BUFFERED_BYTES:
            stats.bytes_dropped += n
            return
        stats.notifications += 1
        stats.bytes_received += n
        if stats.notifications == 1 or n < stats.min_notification:
            stats.min_notification = n
        stats.max_notification = max(n, stats.max_notification)
        self._chunks.append(bytes(data))
        self._buffered += n
        self._wakeup.set()

    def _on_disconnect(self, _client: Any) -> None:
        if not self._closed:
            self._lost = "the unit disconnected"
            log.info("%s disconnected", self._name)  # read() raises it (DeviceError) to the caller
        self._wakeup.set()

    async def read(self) -> bytes:
        """Return all bytes notified since the last read (at least one), or ``b""`` after :meth:`close`.

        Bytes that arrived before a disconnect are returned first.

        Raises
        ------
        DeviceError
            the unit disconnected (or was never connected).
        """
        while not self._chunks:
            if self._closed:
                return b""
            if self._lost is not None:
                raise DeviceError(f"{self._name} was disconnected ({self._lost})")
            if self._client is None:
                raise DeviceError(f"{self._name} is not connected")
            self._wakeup.clear()
            await self._wakeup.wait()
        chunks = self._chunks
        data = chunks.popleft() if len(chunks) == 1 else b"".join([chunks.popleft() for _ in range(len(chunks))])
        self._buffered -= len(data)
        return data

    async def write(self, data: bytes) -> None:
        """Send ``data`` in chunks of at most :attr:`max_write_size` bytes.

        Raises
        ------
        DeviceError
            not connected, or the write failed.
        """
        from bleak.exc import BleakError

        client, uart = self._client, self._uart
        if client is None or uart is None or self._lost is not None or not client.is_connected:
            raise DeviceError(f"cannot write to {self._name}: not connected")
        size = self.max_write_size
        response = uart.write_with_response
        try:
            for k in range(0, len(data), size):
                await client.write_gatt_char(uart.write, data[k : k + size], response=response)
                self.stats.writes += 1
        except (BleakError, OSError) as exc:
            raise DeviceError(f"cannot write to {self._name}: {exc}") from exc

    async def close(self) -> None:
        """Disconnect (idempotent); a pending :meth:`read` then returns ``b""``."""
        self._closed = True
        self._wakeup.set()
        client, uart = self._client, self._uart
        self._client = None
        if client is None:
            return
        if uart is not None and client.is_connected:
            with contextlib.suppress(Exception):
                await client.stop_notify(uart.notify)
        with contextlib.suppress(Exception):
            await client.disconnect()

    async def __aenter__(self) -> Self:
        await self.open()
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        await self.close()
