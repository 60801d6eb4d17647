"""Serial-port discovery on fake ``ListPortInfo`` objects (ptys never appear in list_ports)."""

from __future__ import annotations

import importlib
import subprocess
import sys

from footnav.device import discovery
from serial.tools.list_ports_common import ListPortInfo


def port(
    device: str, vid: int | None = None, pid: int | None = None, description: str = "n/a", **extra: str
) -> ListPortInfo:
    info = ListPortInfo(device, skip_link_detection=True)
    info.vid, info.pid, info.description = vid, pid, description
    for key, value in extra.items():
        setattr(info, key, value)
    return info


PORTS = [
    port("/dev/ttyS0"),  # a legacy UART: never listed
    port("/dev/ttyUSB0", 0x0403, 0x6001, "FT232R USB UART"),
    port("/dev/ttyACM1", 0x2341, 0x0043, "Arduino Uno"),  # some other CDC device: not listed
    port("/dev/ttyACM0", 0x03EB, 0x2307, "CDC Virtual Com", manufacturer="ATMEL AVR"),
    port("/dev/ttyUSB1", 0x10C4, 0xEA60, "CP2102 USB to UART Bridge Controller"),
    port("/dev/ttyACM2", 0x1234, 0x0001, "Oblu IMU", product="oblu"),
    port("COM7", 0x03EB, 0x6124, "ATMEL CDC Virtual Com"),
]


def test_serial_ports_are_matched_by_usb_id_and_description() -> None:
    found = discovery.serial_candidates(PORTS)
    assert [(c.device, c.confidence) for c in found] == [
        ("/dev/ttyACM0", "likely"),
        ("/dev/ttyACM2", "likely"),
        ("COM7", "likely"),
        ("/dev/ttyUSB0", "possible"),
        ("/dev/ttyUSB1", "possible"),
    ]
    assert found[0].usb_id == "03EB:2307" and "AVR32" in found[0].why
    assert found[1].why == "description names a shoe unit"
    assert found[3].why == "FTDI USB-UART bridge"


async def test_scan_lists_serial_ports_without_ble() -> None:
    report = await discovery.scan(list_ports=lambda: PORTS, ble=False)
    assert report.ble == () and report.ble_error is None
    lines = report.lines()
    assert lines[0] == "serial  /dev/ttyACM0  03EB:2307  CDC Virtual Com  [likely: Atmel AVR32 UC3 CDC (ASF 'AVR CDC')]"
    assert len(lines) == 6 and lines[-1].startswith("ble     no units")


async def test_scan_with_no_ports_says_so() -> None:
    report = await discovery.scan(list_ports=list, ble=False)
    assert report.lines()[0].startswith("serial  no ports that look like a shoe unit")


def test_runtime_modules_do_not_import_bumble() -> None:
    code = (
        "import sys, footnav.device.links.ble, footnav.device.links.reconnecting, footnav.device.discovery, "
        "footnav.device.unit; "
        "assert not [m for m in sys.modules if m.startswith('bumble')], 'bumble imported'"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
    importlib.import_module("footnav.device.discovery")
