"""A virtual OpenShoe unit as a BLE GATT peripheral on bumble's virtual radio (``LocalLink``).

The unit's BLE module is modelled as a UART bridge with a FIFO: the firmware
(:class:`footnav.device.emulator.firmware.ShoeFirmware`, the same sans-I/O model the pty server runs: every
output mode, ACKs, lossless resends) writes its byte stream into the module's FIFO, and once per BLE
connection event the module sends what the link allows as notifications of at most ``ATT_MTU - 3``
bytes. So a 34-byte packet spans two notifications at MTU 23 (20 + 14, and the cut drifts), one
notification carries several packets at MTU 247, and a stream faster than the link overflows the FIFO
and loses whole packets, which the host sees as package-number gaps. bumble's LocalLink has no radio
timing (transports-and-emulation.md section 2.5), so the connection interval and the link budget are
modelled here, in *emulated* time; ``speed`` only maps emulated time to wall time, so loss depends on
the budget, never on how fast the test machine is.

Served profiles (protocol-openshoe.md section 8): ``"mimu"`` (USR-IoT 0003CDD0: CDD1 notify, CDD2
write without response), ``"nus"`` (Nordic UART), ``"hm10"`` (FFE0/FFE1, one characteristic both
ways). Host writes longer than ``ATT_MTU - 3`` are rejected and counted (:attr:`Stats.oversize_writes`):
bumble would accept them, a real module would not.

Needs bumble (a test dependency); nothing in footnav's runtime path imports this module.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from dataclasses import dataclass, field
from typing import Any, Final, Literal

import numpy as np
from bumble.core import UUID, AdvertisingData
from bumble.device import Connection
from bumble.gatt import Characteristic, CharacteristicValue, Service
from bumble.link import LocalLink
from footnav.device.emulator.firmware import ShoeFirmware
from footnav.device.emulator.serving.ble_backend import device_on_link
from footnav.device.links import ble as ble_link
from footnav.device.protocol import commands as protocol
from footnav.device.protocol.imu import PACKET_LEN
from numpy.typing import NDArray

log = logging.getLogger(__name__)

Profile = Literal["mimu", "nus", "hm10"]

DEFAULT_CONN_INTERVAL_S: Final = 0.0075
"""The shortest BLE connection interval (7.5 ms); hosts often grant 15–50 ms."""
DEFAULT_NOTIFICATIONS_PER_EVENT: Final = 6
"""Notifications per connection event a typical central accepts (vendor FAQ figure; section 3.2)."""
DEFAULT_FIFO_BYTES: Final = 4096
"""The BLE module's UART FIFO; when full, whole packets are dropped."""
MAX_CATCH_UP_EVENTS: Final = 64
"""Connection events processed in one go when the event loop was late (then it yields)."""

_ADV_FLAGS: Final = bytes((2, AdvertisingData.FLAGS, 0x06))  # LE General Discoverable, BR/EDR not supported


def _split_frames(data: bytes) -> list[bytes]:
    """Cut the firmware's output into frames: data packets (``AA hi lo N ... chk chk``) and 4-byte ACKs."""
    out: list[bytes] = []
    i, n = 0, len(data)
    while i < n:
        size = data[i + 3] + 6 if data[i] == 0xAA and i + 3 < n else 4
        out.append(data[i : i + size])
        i += size
    return out


def link_budget_bps(
    mtu: int,
    conn_interval_s: float = DEFAULT_CONN_INTERVAL_S,
    notifications_per_event: int = DEFAULT_NOTIFICATIONS_PER_EVENT,
) -> float:
    """Notification payload bytes per second a link carries: ``n × (MTU − 3) / interval``.

    At MTU 23 and 6 per 7.5 ms: 16 kB/s, less than the 34 kB/s of 1 kHz normal-IMU packets
    (impossible) and more than the 8.5 kB/s of 250 Hz (possible).
    """
    return notifications_per_event * (mtu - 3) / conn_interval_s


@dataclass(slots=True)
class Stats:
    """What the peripheral did (all counts since :meth:`BleShoePeripheral.start`)."""

    packets_produced: int = 0
    """Data packets the firmware output (each took a package number)."""
    packets_queued: int = 0
    """...of which entered the module FIFO (and reach the host unless a disconnect clears the FIFO)."""
    packets_dropped_overflow: int = 0
    """...dropped because the FIFO was full (link budget too small for the rate)."""
    packets_dropped_disconnected: int = 0
    """...dropped because no host was connected and subscribed."""
    fifo_bytes_cleared: int = 0
    """Bytes still in the FIFO when a connection dropped (lost, possibly mid-packet)."""
    notifications: int = 0
    notified_bytes: int = 0
    min_notification: int = 0
    max_notification: int = 0
    connections: int = 0
    oversize_writes: int = 0
    """Host writes longer than ATT_MTU − 3 (rejected; the host must chunk)."""
    mtus: list[int] = field(default_factory=list)
    """ATT MTU of each connection, as it was when the host subscribed."""


class BleShoePeripheral:
    """Stream IMU sample arrays as a shoe unit's BLE UART.

    Parameters
    ----------
    link
        the virtual radio (the host's :class:`footnav.device.emulator.serving.ble_backend.BumbleAdapter` is on it too).
    t_s
        (n,) sample times at the unit's 1 kHz base rate, s, increasing.
    acc_b_mps2
        (n, 3) specific force, body frame, m/s².
    gyr_b_radps
        (n, 3) angular rate, body frame, rad/s.
    name
        advertised local name.
    address
        the peripheral's static random address.
    profile
        which UART service to serve and advertise.
    speed
        emulated seconds per wall second (``math.inf``: one connection event per event-loop turn while busy).
    conn_interval_s
        emulated BLE connection interval.
    notifications_per_event
        notifications per connection event (the budget when ``budget_Bps`` is None).
    budget_Bps
        notification payload bytes per emulated second, overriding the per-event count.
    fifo_bytes
        the module's FIFO size.
    max_mtu
        the largest ATT MTU the server accepts (the host requests one).
    firmware_kwargs
        passed to :class:`~footnav.device.emulator.firmware.ShoeFirmware` (``steps=``, ``ins=``, ``tof=``, ``baro=``,
        ``command_set=``, ``tick0=``, ``first_packet_number=``, ...).
    """

    def __init__(
        self,
        link: LocalLink,
        t_s: NDArray[np.float64],
        acc_b_mps2: NDArray[np.float64],
        gyr_b_radps: NDArray[np.float64],
        *,
        name: str = "FOOTNAV-EMU",
        address: str = "C0:11:22:33:44:01",
        profile: Profile = "mimu",
        speed: float = 1.0,
        conn_interval_s: float = DEFAULT_CONN_INTERVAL_S,
        notifications_per_event: int = DEFAULT_NOTIFICATIONS_PER_EVENT,
        budget_Bps: float | None = None,
        fifo_bytes: int = DEFAULT_FIFO_BYTES,
        max_mtu: int = 517,
        **firmware_kwargs: Any,
    ) -> None:
        if not speed > 0:
            raise ValueError(f"speed must be > 0 (math.inf for as fast as possible), got {speed}")
        if not conn_interval_s > 0 or notifications_per_event < 1 or fifo_bytes < PACKET_LEN:
            raise ValueError("need conn_interval_s > 0, notifications_per_event >= 1, fifo_bytes >= 34")
        self.firmware = ShoeFirmware(t_s, acc_b_mps2, gyr_b_radps, speed=1.0, **firmware_kwargs)
        """The unit's firmware; it runs on this peripheral's emulated clock (1 emulated s per s)."""
        self.name = name
        self.address = address
        self.profile: Profile = profile
        self.speed = speed
        self.conn_interval_s = conn_interval_s
        self.notifications_per_event = notifications_per_event
        self.budget_Bps = budget_Bps
        self.fifo_bytes = fifo_bytes
        self.stats = Stats()

        self.device = device_on_link(link, name, address)
        self.device.gatt_server.max_mtu = max_mtu
        self._notify_char, service, service_uuid = self._make_service(profile)
        self.service_uuid: str = service_uuid
        """The advertised service (bleak's lower-case 128-bit form)."""
        self.device.add_service(service)
        self.device.on(self.device.EVENT_CONNECTION, self._on_connection)

        self._conn: Connection | None = None
        self._subscribed = False
        self._fifo = bytearray()
        self._emu_t = 0.0
        self._activity = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self.finished = asyncio.Event()
        """Set once the firmware has nothing left to output and the FIFO is empty."""

    # --- set-up -----------------------------------------------------------------------------------

    def _make_service(self, profile: Profile) -> tuple[Characteristic[bytes], Service, str]:
        props = Characteristic.Properties
        writes: CharacteristicValue[bytes] = CharacteristicValue(write=self._on_write)
        tx: Characteristic[bytes]
        rx: Characteristic[bytes]
        if profile == "mimu":
            tx = Characteristic(ble_link.MIMU_NOTIFY, props.NOTIFY, Characteristic.READABLE, b"")
            rx = Characteristic(ble_link.MIMU_WRITE, props.WRITE_WITHOUT_RESPONSE, Characteristic.WRITEABLE, writes)
            return tx, Service(ble_link.MIMU_SERVICE, [tx, rx]), ble_link.MIMU_SERVICE
        if profile == "nus":
            rx = Characteristic(
                ble_link.NUS_RX, props.WRITE | props.WRITE_WITHOUT_RESPONSE, Characteristic.WRITEABLE, writes
            )
            tx = Characteristic(ble_link.NUS_TX, props.NOTIFY, Characteristic.READABLE, b"")
            return tx, Service(ble_link.NUS_SERVICE, [rx, tx]), ble_link.NUS_SERVICE
        if profile == "hm10":
            both: Characteristic[bytes] = Characteristic(
                "FFE1",
                props.READ | props.WRITE_WITHOUT_RESPONSE | props.NOTIFY,
                Characteristic.READABLE | Characteristic.WRITEABLE,
                CharacteristicValue(read=lambda _c: b"", write=self._on_write),
            )
            return both, Service("FFE0", [both]), ble_link.HM10_SERVICE
        raise ValueError(f"unknown profile {profile!r}; use 'mimu', 'nus' or 'hm10'")

    def _advertising_data(self) -> bytes:
        """Flags, the service UUID and the name, in the 31 bytes of a legacy advertisement.

        Everything goes in the advertisement itself: bumble's virtual controller answers a scan request
        with the advertising data again, not the scan response. A name that does not fit is sent
        shortened (AD type 0x08), as real modules do.
        """
        raw = UUID(self.service_uuid).to_bytes()
        kind = (
            AdvertisingData.COMPLETE_LIST_OF_16_BIT_SERVICE_CLASS_UUIDS
            if len(raw) == 2
            else AdvertisingData.COMPLETE_LIST_OF_128_BIT_SERVICE_CLASS_UUIDS
        )
        adv = _ADV_FLAGS + bytes((len(raw) + 1, kind)) + raw
        name = self.name.encode()
        room = 31 - len(adv) - 2
        name_kind = AdvertisingData.COMPLETE_LOCAL_NAME if len(name) <= room else AdvertisingData.SHORTENED_LOCAL_NAME
        name = name[:room]
        return adv + bytes((len(name) + 1, name_kind)) + name

    async def start(self) -> None:
        """Power on, advertise (every 20 ms, restarted after each disconnect) and run the unit's clock."""
        self.device.advertising_data = self._advertising_data()
        await self.device.power_on()
        await self.device.start_advertising(auto_restart=True, advertising_interval_min=20, advertising_interval_max=20)
        self._task = asyncio.create_task(self._run(), name=f"ble-shoe {self.name}")

    async def stop(self) -> None:
        """Stop the clock, drop the connection and power off (idempotent)."""
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
        with contextlib.suppress(Exception):
            await self.device.stop_advertising()
        await self.disconnect()
        with contextlib.suppress(Exception):
            await self.device.power_off()

    async def disconnect(self, *, reset: bool = False) -> None:
        """Drop the connection from the unit's side (a BLE fault). Advertising restarts by itself.

        Parameters
        ----------
        reset
            also stop streaming, as a unit that rebooted: the host must send the start command again. Without it the
            firmware keeps streaming into the module, which discards the bytes until a host subscribes again (package
            numbers keep counting: the host sees the gap).
        """
        if reset:  # what a reboot leaves: no outputs, no processing (the ACKs die with the link)
            self.firmware.receive(protocol.processing_off_command() + protocol.outputs_off_command(), self._emu_t)
            self.firmware.out.clear()
            del self.firmware.commands[-2:]  # not host commands
        conn = self._conn
        if conn is not None:
            with contextlib.suppress(Exception):
                await conn.disconnect()

    @property
    def commands(self) -> list[protocol.Command]:
        """Valid host commands the firmware received, in order (host ACKs included)."""
        return self.firmware.commands

    @property
    def mtu(self) -> int:
        """The current connection's ATT MTU (23 when not connected)."""
        return self._conn.att_mtu if self._conn is not None else 23

    @property
    def is_connected(self) -> bool:
        return self._conn is not None

    # --- the radio side ---------------------------------------------------------------------------

    def _on_connection(self, conn: Connection) -> None:
        self._conn = conn
        self._subscribed = False
        self.stats.connections += 1
        conn.on(conn.EVENT_DISCONNECTION, self._on_disconnection)
        self._notify_char.on(Characteristic.EVENT_SUBSCRIPTION, self._on_subscription)

    def _on_subscription(self, _bearer: object, notify_enabled: bool, _indicate_enabled: bool) -> None:
        self._subscribed = notify_enabled
        if notify_enabled:
            self.stats.mtus.append(self.mtu)
        self._activity.set()

    def _on_disconnection(self, _reason: int) -> None:
        self._conn = None
        self._subscribed = False
        self.stats.fifo_bytes_cleared += len(self._fifo)
        self._fifo.clear()  # the module's buffer dies with the connection
        with contextlib.suppress(ValueError):
            self._notify_char.remove_listener(Characteristic.EVENT_SUBSCRIPTION, self._on_subscription)

    def _on_write(self, conn: Connection, value: bytes) -> None:
        if len(value) > conn.att_mtu - 3:
            self.stats.oversize_writes += 1
            log.warning(
                "host wrote %d bytes at ATT MTU %d (max %d): rejected",
                len(value),
                conn.att_mtu,
                conn.att_mtu - 3,
            )
            return
        self.firmware.receive(bytes(value), self._emu_t)
        self._activity.set()

    # --- the firmware -----------------------------------------------------------------------------

    def _busy(self) -> bool:
        fw = self.firmware
        return fw.next_wakeup(self._emu_t) is not None or bool(fw.out) or (bool(self._fifo) and self._subscribed)

    async def _run(self) -> None:
        loop = asyncio.get_running_loop()
        ci = self.conn_interval_s
        wall0 = loop.time()
        while True:
            if not self._busy():
                if self.firmware.exhausted and not self._fifo:
                    self.finished.set()
                self._activity.clear()
                await self._activity.wait()
                wall0 = loop.time() - self._emu_t / self.speed  # idle time does not count
            if math.isinf(self.speed):
                await asyncio.sleep(0)
                events = 1
            else:
                behind = (loop.time() - wall0) * self.speed - self._emu_t
                if behind < ci:
                    await asyncio.sleep((ci - behind) / self.speed)
                    behind = (loop.time() - wall0) * self.speed - self._emu_t
                events = min(MAX_CATCH_UP_EVENTS, max(1, int(behind / ci)))
                if events == MAX_CATCH_UP_EVENTS:
                    wall0 = loop.time() - (self._emu_t + events * ci) / self.speed  # don't spiral
            for _ in range(events):
                self._emu_t += ci
                self._produce()
                await self._transmit()

    def _produce(self) -> None:
        """Run the firmware up to the emulated clock; move its output into the FIFO (or drop it)."""
        fw = self.firmware
        fw.produce(self._emu_t)
        stats = self.stats
        while fw.out:
            data, count = fw.out.popleft()
            stats.packets_produced += count
            if not self._subscribed:
                stats.packets_dropped_disconnected += count
                continue
            if count == 0 or len(self._fifo) + len(data) <= self.fifo_bytes:
                self._fifo += data  # command ACKs always fit: the firmware waits for room
                stats.packets_queued += count
                continue
            for frame in _split_frames(data):  # tail drop of whole packets
                if len(self._fifo) + len(frame) <= self.fifo_bytes:
                    self._fifo += frame
                    stats.packets_queued += 1
                else:
                    stats.packets_dropped_overflow += 1

    async def _transmit(self) -> None:
        """One connection event: send what the budget allows, in notifications of <= MTU − 3 bytes."""
        conn = self._conn
        if conn is None or not self._subscribed or not self._fifo:
            return
        size = conn.att_mtu - 3
        if self.budget_Bps is None:
            allowance = self.notifications_per_event * size
        else:
            allowance = int(self.budget_Bps * self.conn_interval_s)
        fifo = self._fifo
        take = min(len(fifo), allowance)
        data = bytes(fifo[:take])
        del fifo[:take]
        stats = self.stats
        for k in range(0, take, size):
            chunk = data[k : k + size]
            await self.device.notify_subscriber(conn, self._notify_char, chunk)
            stats.notifications += 1
            stats.notified_bytes += len(chunk)
            if stats.notifications == 1 or len(chunk) < stats.min_notification:
                stats.min_notification = len(chunk)
            stats.max_notification = max(stats.max_notification, len(chunk))
