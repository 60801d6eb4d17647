"""Find shoe units: serial ports by USB id and description, BLE units by advertised service.

:func:`scan` is the logic behind ``footnav scan``. Serial ports come from
``serial.tools.list_ports.comports()`` (a seam: pass ``list_ports=`` to test with fake ``ListPortInfo``
objects; ptys are never listed there, transports-and-emulation.md section 1.1). Matching rules:

* **likely**: Atmel's USB vendor id 0x03EB with a CDC product id (the OpenShoe/MIMU/Oblu firmware is
  an AVR32 UC3 with Atmel's ASF CDC stack: ``conf_usb.h`` uses ``USB_VID_ATMEL`` /
  ``USB_PID_ATMEL_AVR_CDC``, product string "CDC Virtual Com"), or a description / manufacturer /
  product naming the unit (MIMU, Oblu, OpenShoe, GT Silicon, Inertial Elements);
* **possible**: a generic USB-UART bridge (FTDI 0x0403, Silicon Labs CP210x 0x10C4, WCH CH34x 0x1A86)
  as found on development boards and Bluetooth-module adapters.

BLE units are those advertising a known UART service (MIMU22BL CDD0, Nordic UART, HM-10 FFE0) or a
name like the above. Without a Bluetooth stack the BLE part is one line in :attr:`ScanReport.ble_error`
and serial ports are still listed.
"""

from __future__ import annotations

import asyncio
import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final, Literal

from footnav.device.links.ble import (
    KNOWN_SERVICES,
    BleBackend,
    advertises_known_service,
    is_bluetooth_unavailable,
    no_bluetooth_message,
    scanner_kwargs,
)

if TYPE_CHECKING:
    from serial.tools.list_ports_common import ListPortInfo

VID_ATMEL: Final = 0x03EB
ATMEL_CDC_PIDS: Final[dict[int, str]] = {
    0x2307: "Atmel AVR32 UC3 CDC (ASF 'AVR CDC')",
    0x2310: "Atmel AVR32 UC3 CDC (debug virtual COM)",
    0x2404: "Atmel ASF CDC",
}
"""Atmel CDC product ids used by ASF examples, which the OpenShoe firmware's USB stack derives from."""
USB_UART_BRIDGES: Final[dict[int, str]] = {
    0x0403: "FTDI USB-UART bridge",
    0x10C4: "Silicon Labs CP210x USB-UART bridge",
    0x1A86: "WCH CH34x USB-UART bridge",
}
UNIT_NAME_RE: Final = re.compile(r"mimu|oblu|openshoe|open shoe|gt silicon|inertial ?elements|osmium", re.IGNORECASE)
"""Words in a USB description or a BLE name that point at a shoe unit."""

Confidence = Literal["likely", "possible"]


@dataclass(frozen=True, slots=True)
class SerialCandidate:
    """A serial port that may be a shoe unit."""

    device: str
    """Port path to pass to ``footnav live --port`` (e.g. ``/dev/ttyACM0``, ``COM3``)."""
    description: str
    vid: int | None
    pid: int | None
    serial_number: str | None
    confidence: Confidence
    why: str
    """The rule that matched, for the listing."""

    @property
    def usb_id(self) -> str:
        """``VID:PID`` in hex, or "-"."""
        return "-" if self.vid is None or self.pid is None else f"{self.vid:04X}:{self.pid:04X}"


@dataclass(frozen=True, slots=True)
class BleCandidate:
    """A BLE device that looks like a shoe unit."""

    address: str
    """Bluetooth address (a UUID on macOS): pass it to ``footnav live --ble``."""
    name: str | None
    rssi: int | None
    """Signal strength, dBm."""
    service: str | None
    """Known UART service UUID advertised, if any."""

    @property
    def profile(self) -> str:
        """Human name of the advertised service (or why it matched)."""
        return KNOWN_SERVICES[self.service] if self.service is not None else "name matches a shoe unit"


@dataclass(frozen=True, slots=True)
class ScanReport:
    """What ``footnav scan`` found."""

    serial: tuple[SerialCandidate, ...]
    ble: tuple[BleCandidate, ...]
    ble_error: str | None
    """One line when BLE could not be scanned (e.g. no Bluetooth stack), else None."""

    def lines(self) -> list[str]:
        """The report for the terminal, one item per line."""
        out: list[str] = []
        if self.serial:
            for p in self.serial:
                desc = f"  {p.description}" if p.description and p.description != "n/a" else ""
                out.append(f"serial  {p.device}  {p.usb_id}{desc}  [{p.confidence}: {p.why}]")
        else:
            out.append("serial  no ports that look like a shoe unit (is it plugged in? `ls /dev/ttyACM*`)")
        if self.ble_error is not None:
            out.append(f"ble     {self.ble_error}")
        elif self.ble:
            for b in self.ble:
                rssi = "" if b.rssi is None else f"  {b.rssi} dBm"
                out.append(f"ble     {b.address}  {b.name or '(no name)'}{rssi}  [{b.profile}]")
        else:
            out.append("ble     no units advertising a MIMU22BL, Nordic UART or HM-10 service")
        return out


def classify_port(port: ListPortInfo) -> SerialCandidate | None:
    """A candidate if ``port`` looks like a shoe unit (or a USB-UART bridge one may sit behind)."""
    vid, pid = port.vid, port.pid
    text = " ".join(str(s) for s in (port.description, port.manufacturer, port.product) if s)
    confidence: Confidence | None = None
    why = ""
    if vid == VID_ATMEL and pid in ATMEL_CDC_PIDS:
        confidence, why = "likely", ATMEL_CDC_PIDS[pid]
    elif UNIT_NAME_RE.search(text):
        confidence, why = "likely", "description names a shoe unit"
    elif vid == VID_ATMEL and "cdc" in text.lower():
        confidence, why = "likely", "Atmel CDC virtual COM port"
    elif vid in USB_UART_BRIDGES:
        confidence, why = "possible", USB_UART_BRIDGES[vid]
    if confidence is None:
        return None
    return SerialCandidate(
        device=port.device,
        description=str(port.description or ""),
        vid=vid,
        pid=pid,
        serial_number=port.serial_number,
        confidence=confidence,
        why=why,
    )


def serial_candidates(ports: Iterable[ListPortInfo]) -> list[SerialCandidate]:
    """The ports that look like shoe units, "likely" first, then by path."""
    found = [c for c in map(classify_port, ports) if c is not None]
    return sorted(found, key=lambda c: (c.confidence != "likely", c.device))


def _comports() -> list[ListPortInfo]:
    from serial.tools import list_ports

    return list(list_ports.comports())


async def ble_candidates(timeout_s: float, backend: BleBackend | None = None) -> list[BleCandidate]:
    """Scan for ``timeout_s`` and return the devices that look like shoe units, strongest first.

    Raises
    ------
    DeviceError
        no Bluetooth stack (one-line message), or the scan failed.
    """
    from bleak import BleakScanner
    from bleak.exc import BleakError
    from footnav.device.errors import DeviceError

    try:
        found = await BleakScanner.discover(timeout_s, return_adv=True, **scanner_kwargs(backend))
    except (BleakError, OSError) as exc:
        if is_bluetooth_unavailable(exc):
            raise DeviceError(no_bluetooth_message(exc)) from exc
        raise DeviceError(f"BLE scan failed: {type(exc).__name__}: {exc}") from exc
    out: list[BleCandidate] = []
    for device, ad in found.values():
        service = advertises_known_service(ad)
        name = ad.local_name or device.name
        if service is None and not (name and UNIT_NAME_RE.search(name)):
            continue
        out.append(BleCandidate(address=device.address, name=name, rssi=ad.rssi, service=service))
    return sorted(out, key=lambda c: -(c.rssi if c.rssi is not None else -999))


async def scan(
    timeout_s: float = 5.0,
    ble_backend: BleBackend | None = None,
    *,
    list_ports: Callable[[], Iterable[ListPortInfo]] | None = None,
    ble: bool = True,
) -> ScanReport:
    """Serial ports and BLE devices that look like shoe units (``footnav scan``).

    Never raises for a missing Bluetooth stack: :attr:`ScanReport.ble_error` says so in one line.

    Parameters
    ----------
    timeout_s
        how long to scan BLE.
    ble_backend
        bleak backend classes (None: the platform's).
    list_ports
        returns the serial ports (default ``serial.tools.list_ports.comports``); the seam for tests.
    ble
        False skips the BLE scan.
    """
    from footnav.device.errors import DeviceError

    ports = await asyncio.to_thread(lambda: list((list_ports or _comports)()))
    serial = tuple(serial_candidates(ports))
    ble_found: list[BleCandidate] = []
    error: str | None = None
    if ble:
        try:
            ble_found = await ble_candidates(timeout_s, ble_backend)
        except DeviceError as exc:
            error = str(exc)
    return ScanReport(serial=serial, ble=tuple(ble_found), ble_error=error)
