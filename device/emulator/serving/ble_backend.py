"""A bleak backend on bumble: unmodified bleak public-API code against bumble's virtual radio.

``BumbleScanner(BaseBleakScanner)`` and ``BumbleClient(BaseBleakClient)`` drive one bumble host and
virtual controller (a :class:`BumbleAdapter`, the "hci0" of this world) on a
:class:`bumble.link.LocalLink`, on which emulated peripherals
(:mod:`footnav.device.emulator.serving.ble_peripheral`) advertise. Every byte goes through bumble's real HCI, L2CAP,
ATT and GATT code, so scanning by service UUID, connecting, MTU exchange, GATT discovery, CCCD writes,
notifications and a device-side disconnect behave as on a radio, minus radio timing (the peripheral
models that). See transports-and-emulation.md section 2.4.

Needs bumble (a test dependency: ``pip install -e '.[test]'``). Nothing in footnav's runtime path
imports this module; import it lazily. Use it through :class:`footnav.device.links.ble.BleBackend`::

    link = LocalLink()
    backend = bumble_backend(BumbleAdapter(link), mtu=247)
    async with BleLink("FOOT-L", backend=backend) as ble: ...

bumble quirks worked around here (section 2.5): connecting to an absent address never returns, so
the connect runs under ``asyncio.wait_for``; only one LE connection may be pending per controller, so
connects are serialised per adapter.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import uuid
from collections.abc import Callable
from typing import Any, Final

from bleak.args import SizedBuffer
from bleak.assigned_numbers import CharacteristicPropertyName
from bleak.backends.characteristic import BleakGATTCharacteristic
from bleak.backends.client import BaseBleakClient, NotifyCallback
from bleak.backends.descriptor import BleakGATTDescriptor
from bleak.backends.device import BLEDevice
from bleak.backends.scanner import AdvertisementData, AdvertisementDataCallback, BaseBleakScanner
from bleak.backends.service import BleakGATTService, BleakGATTServiceCollection
from bleak.exc import BleakDeviceNotFoundError, BleakError
from bumble import core as bumble_core
from bumble.controller import Controller
from bumble.core import AdvertisingData, PhysicalTransport
from bumble.device import Advertisement, Connection, Device, Peer
from bumble.gatt import Characteristic
from bumble.gatt_client import CharacteristicProxy
from bumble.hci import Address
from bumble.host import Host
from bumble.link import LocalLink
from bumble.transport.common import AsyncPipeSink
from footnav.device.links.ble import BleBackend

log = logging.getLogger(__name__)

DEFAULT_HOST_ADDRESS: Final = "F0:F0:F0:F0:F0:01"
DEFAULT_MTU: Final = 247
"""ATT MTU the client requests after connecting (23 = no exchange)."""

_PROPERTY_NAMES: Final[dict[Characteristic.Properties, CharacteristicPropertyName]] = {
    Characteristic.Properties.BROADCAST: "broadcast",
    Characteristic.Properties.READ: "read",
    Characteristic.Properties.WRITE_WITHOUT_RESPONSE: "write-without-response",
    Characteristic.Properties.WRITE: "write",
    Characteristic.Properties.NOTIFY: "notify",
    Characteristic.Properties.INDICATE: "indicate",
    Characteristic.Properties.AUTHENTICATED_SIGNED_WRITES: "authenticated-signed-writes",
    Characteristic.Properties.EXTENDED_PROPERTIES: "extended-properties",
}


def device_on_link(link: LocalLink, name: str, address: str) -> Device:
    """A bumble device with its own virtual controller on ``link`` (not powered on yet).

    ``address`` is used as the controller's public address and the device's (static random) address.
    """
    controller = Controller(f"ctrl-{name}-{address}", link=link, public_address=address)
    return Device(name=name, address=Address(address), host=Host(controller, AsyncPipeSink(controller)))


def bleak_uuid(u: bumble_core.UUID) -> str:
    """bumble UUID -> bleak's lower-case 128-bit string (bumble keeps UUID bytes little-endian)."""
    return str(uuid.UUID(bytes=bytes(reversed(u.to_bytes(force_128=True)))))


class BumbleAdapter:
    """The host side of the virtual radio: one bumble device shared by scanners and clients.

    Parameters
    ----------
    link
        the virtual radio the emulated peripherals are on.
    address
        this host's (static random) address.
    """

    def __init__(self, link: LocalLink, address: str = DEFAULT_HOST_ADDRESS) -> None:
        self.link = link
        self.address = address
        self._device: Device | None = None
        self._power_lock = asyncio.Lock()
        self.connect_lock = asyncio.Lock()
        """One pending LE connection at a time (a real controller's rule too)."""
        self._scanners = 0

    async def device(self) -> Device:
        """The powered-on bumble device (created on first use)."""
        async with self._power_lock:
            if self._device is None:
                dev = device_on_link(self.link, "footnav-host", self.address)
                await dev.power_on()
                self._device = dev
            return self._device

    async def scan_started(self) -> Device:
        """Start scanning if no other scanner is running; return the device."""
        dev = await self.device()
        self._scanners += 1
        if self._scanners == 1:
            await dev.start_scanning(active=True, filter_duplicates=False)
        return dev

    async def scan_stopped(self) -> None:
        """Stop scanning when the last scanner stops."""
        self._scanners = max(0, self._scanners - 1)
        if self._scanners == 0 and self._device is not None and self._device.is_scanning:
            await self._device.stop_scanning()

    async def close(self) -> None:
        """Power the host device off (disconnecting its connections)."""
        dev, self._device = self._device, None
        if dev is not None:
            with contextlib.suppress(Exception):
                await dev.power_off()


def bumble_backend(adapter: BumbleAdapter, *, mtu: int = DEFAULT_MTU) -> BleBackend:
    """A :class:`footnav.device.links.ble.BleBackend` on ``adapter``; clients request ATT MTU ``mtu``."""
    return BleBackend(
        scanner=BumbleScanner,
        client=BumbleClient,
        scanner_kwargs={"bumble_adapter": adapter},
        client_kwargs={"bumble_adapter": adapter, "mtu": mtu},
    )


class BumbleScanner(BaseBleakScanner):
    """bleak scanner backend: bumble advertisement reports -> bleak ``AdvertisementData``.

    Keyword Args:
        bumble_adapter: the :class:`BumbleAdapter` to scan with (required).
    """

    def __init__(
        self,
        detection_callback: AdvertisementDataCallback | None,
        service_uuids: list[str] | None,
        scanning_mode: str = "active",
        *,
        bumble_adapter: BumbleAdapter | None = None,
        **kwargs: Any,
    ) -> None:
        super().__init__(detection_callback, service_uuids)
        if bumble_adapter is None:
            raise BleakError("BumbleScanner needs bumble_adapter=BumbleAdapter(link)")
        self._adapter = bumble_adapter
        self._device: Device | None = None

    async def start(self) -> None:
        self.seen_devices = {}
        dev = await self._adapter.scan_started()
        dev.on(Device.EVENT_ADVERTISEMENT, self._on_advertisement)
        self._device = dev

    async def stop(self) -> None:
        dev, self._device = self._device, None
        if dev is None:
            return
        dev.remove_listener(Device.EVENT_ADVERTISEMENT, self._on_advertisement)
        await self._adapter.scan_stopped()

    def _on_advertisement(self, adv: Advertisement) -> None:
        data = adv.data
        name = data.get(AdvertisingData.COMPLETE_LOCAL_NAME) or data.get(AdvertisingData.SHORTENED_LOCAL_NAME)
        uuids: list[str] = []
        for kind in (
            AdvertisingData.COMPLETE_LIST_OF_16_BIT_SERVICE_CLASS_UUIDS,
            AdvertisingData.INCOMPLETE_LIST_OF_16_BIT_SERVICE_CLASS_UUIDS,
            AdvertisingData.COMPLETE_LIST_OF_32_BIT_SERVICE_CLASS_UUIDS,
            AdvertisingData.INCOMPLETE_LIST_OF_32_BIT_SERVICE_CLASS_UUIDS,
            AdvertisingData.COMPLETE_LIST_OF_128_BIT_SERVICE_CLASS_UUIDS,
            AdvertisingData.INCOMPLETE_LIST_OF_128_BIT_SERVICE_CLASS_UUIDS,
        ):
            for found in data.get_all(kind):
                uuids.extend(u for u in map(bleak_uuid, found) if u not in uuids)
        manufacturer: dict[int, bytes] = {}
        for company, payload in data.get_all(AdvertisingData.MANUFACTURER_SPECIFIC_DATA):
            manufacturer[company] = payload
        tx_power = data.get(AdvertisingData.TX_POWER_LEVEL)
        local_name = str(name) if name is not None else None
        ad = AdvertisementData(
            local_name=local_name,
            manufacturer_data=manufacturer,
            service_data={},
            service_uuids=uuids,
            tx_power=int(tx_power) if tx_power is not None else None,
            rssi=int(adv.rssi),
            platform_data=(adv,),
        )
        address = adv.address.to_string(with_type_qualifier=False)
        device = self.create_or_update_device(address, address, local_name, adv.address, ad)
        if self.is_allowed_uuid(uuids):
            self.call_detection_callbacks(device, ad)


class BumbleClient(BaseBleakClient):
    """bleak client backend: connect, MTU exchange, GATT discovery, writes and notifications on bumble.

    Keyword Args:
        bumble_adapter: the :class:`BumbleAdapter` to connect through (required).
        mtu: ATT MTU to request after connecting (23 = no exchange; the server's maximum caps it).
    """

    def __init__(
        self,
        address_or_ble_device: BLEDevice | str,
        *,
        bumble_adapter: BumbleAdapter | None = None,
        mtu: int = DEFAULT_MTU,
        disconnected_callback: Callable[[], None] | None = None,
        timeout: float = 10.0,
        **kwargs: Any,
    ) -> None:
        super().__init__(address_or_ble_device, disconnected_callback=disconnected_callback, timeout=timeout)
        if bumble_adapter is None:
            raise BleakError("BumbleClient needs bumble_adapter=BumbleAdapter(link)")
        self._adapter = bumble_adapter
        self._mtu_request = mtu
        self._peer_address: Address
        self._name = self.address
        if isinstance(address_or_ble_device, BLEDevice):
            details = address_or_ble_device.details
            self._peer_address = details if isinstance(details, Address) else Address(self.address)
            self._name = address_or_ble_device.name or self.address
        else:
            self._peer_address = Address(self.address)
        self._conn: Connection | None = None
        self._connected = False
        self._closing = False
        self._subscriptions: dict[int, Callable[[bytes], None]] = {}

    @property
    def name(self) -> str:
        return self._name

    @property
    def mtu_size(self) -> int:
        return self._conn.att_mtu if self._conn is not None else 23

    @property
    def is_connected(self) -> bool:
        return self._connected

    async def connect(self, pair: bool, **kwargs: Any) -> None:
        dev = await self._adapter.device()
        async with self._adapter.connect_lock:
            try:
                conn = await asyncio.wait_for(
                    dev.connect(self._peer_address, transport=PhysicalTransport.LE, timeout=None),
                    self._timeout,
                )
            except TimeoutError as exc:
                raise BleakDeviceNotFoundError(
                    self.address, f"device {self.address} not found (no connection within {self._timeout} s)"
                ) from exc
        self._conn = conn
        self._connected = True
        self._closing = False
        conn.on(conn.EVENT_DISCONNECTION, self._on_disconnection)
        try:
            peer = Peer(conn)
            if self._mtu_request > 23:
                await peer.request_mtu(self._mtu_request)
            await peer.discover_all()
            self.services = self._service_collection(peer)
        except BaseException:
            await self.disconnect()
            raise

    def _service_collection(self, peer: Peer) -> BleakGATTServiceCollection:
        conn = peer.connection
        services = BleakGATTServiceCollection()
        for svc in peer.services:
            service = BleakGATTService(svc, svc.handle, bleak_uuid(svc.uuid))
            services.add_service(service)
            for chp in svc.characteristics:
                props = [name for flag, name in _PROPERTY_NAMES.items() if chp.properties & flag]
                char = BleakGATTCharacteristic(
                    chp, chp.handle, bleak_uuid(chp.uuid), props, lambda: conn.att_mtu - 3, service
                )
                services.add_characteristic(char)
                for desc in chp.descriptors:
                    services.add_descriptor(BleakGATTDescriptor(desc, desc.handle, bleak_uuid(desc.type), char))
        return services

    def _on_disconnection(self, reason: int) -> None:
        self._connected = False
        self._subscriptions.clear()
        if not self._closing and self._disconnected_callback is not None:
            self._disconnected_callback()

    async def disconnect(self) -> None:
        conn = self._conn
        if conn is None or not self._connected:
            self._connected = False
            return
        self._closing = True
        with contextlib.suppress(Exception):
            await conn.disconnect()
        self._connected = False

    async def pair(self, *args: Any, **kwargs: Any) -> None:
        raise BleakError("pairing is not supported by the bumble test backend")

    async def unpair(self) -> None:
        raise BleakError("pairing is not supported by the bumble test backend")

    def _require(self) -> None:
        if not self._connected:
            raise BleakError("Not connected")

    async def read_gatt_char(
        self, characteristic: BleakGATTCharacteristic, *, use_cached: bool = False, **kwargs: Any
    ) -> bytearray:
        self._require()
        proxy: CharacteristicProxy[bytes] = characteristic.obj
        return bytearray(await proxy.read_value())

    async def read_gatt_descriptor(
        self, descriptor: BleakGATTDescriptor, *, use_cached: bool = False, **kwargs: Any
    ) -> bytearray:
        self._require()
        return bytearray(await descriptor.obj.read_value())

    async def write_gatt_char(self, characteristic: BleakGATTCharacteristic, data: SizedBuffer, response: bool) -> None:
        self._require()
        proxy: CharacteristicProxy[bytes] = characteristic.obj
        await proxy.write_value(bytes(data), with_response=response)

    async def write_gatt_descriptor(self, descriptor: BleakGATTDescriptor, data: SizedBuffer) -> None:
        self._require()
        await descriptor.obj.write_value(bytes(data), with_response=True)

    async def start_notify(
        self, characteristic: BleakGATTCharacteristic, callback: NotifyCallback, **kwargs: Any
    ) -> None:
        self._require()
        proxy: CharacteristicProxy[bytes] = characteristic.obj

        def on_value(value: bytes) -> None:
            callback(bytearray(value))

        self._subscriptions[characteristic.handle] = on_value
        await proxy.subscribe(on_value, prefer_notify=True)

    async def stop_notify(self, characteristic: BleakGATTCharacteristic) -> None:
        on_value = self._subscriptions.pop(characteristic.handle, None)
        if on_value is not None and self._connected:
            proxy: CharacteristicProxy[bytes] = characteristic.obj
            await proxy.unsubscribe(on_value)
