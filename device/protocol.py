"""OpenShoe host commands (2015 set): frame builders, device ACKs and a firmware-style command parser.

Sans-I/O: bytes in, bytes or values out. Host -> device frame::

    [cmd_id][payload, fixed length per cmd_id][chk_hi][chk_lo]    chk = sum(cmd_id..payload) mod 2**16

Device ACK of a valid command: ``A0 cmd chk_hi chk_lo`` with chk = 0xA0 + cmd. Host ACKs (0x01) are
never acknowledged. Sources: ``hcarlsso/openshoe-framework:src/external_interfaces/parsing_util.h``,
``external_interface.c``, ``src/tables/commands.c``, ``src/tables/control_tables.h`` (HEAD, 2015–2016);
see protocol-openshoe.md sections 3 and 6.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

from pipeline.errors import ProtocolError

# Command IDs (2015 set, control_tables.h HEAD). The 2014 MIMU22BT set differs: do not mix them.
CMD_ACK: Final = 0x01
CMD_PING: Final = 0x03
CMD_MCU_ID: Final = 0x04
CMD_OUTPUT_STATE: Final = 0x20
CMD_OUTPUT_MULTIPLE_STATES: Final = 0x21
CMD_OUTPUT_ALL_OFF: Final = 0x22
CMD_OUTPUT_IMU_RD: Final = 0x28
CMD_ALL_PROC_OFF: Final = 0x32
CMD_RESET_ZUPT_AIDED_INS: Final = 0x33
CMD_STEPWISE_DEAD_RECKONING: Final = 0x34
CMD_NORMAL_IMU: Final = 0x40
CMD_NORMAL_IMU_WITH_BIAS_EST: Final = 0x41

DEVICE_ACK_HEADER: Final = 0xA0
DEVICE_ACK_LEN: Final = 4
CID_LIMIT: Final = 0x50
"""Command IDs at or above this are dropped by the firmware parser."""

COMMAND_PAYLOAD_LENGTHS: Final[dict[int, int]] = {
    0x01: 2,  # ACK: pkt number uint16 BE
    0x03: 0,  # PING
    0x04: 0,  # MCU_ID
    0x12: 2, 0x13: 5, 0x14: 13, 0x15: 25, 0x16: 49, 0x17: 255,  # SET_STATE_1/4/12/24/48/254: id + value
    0x20: 2,  # OUTPUT_STATE: state_id, mode
    0x21: 9,  # OUTPUT_MULTIPLE_STATES: 8 state ids, mode
    0x22: 0,  # OUTPUT_ALL_OFF
    0x23: 10,  # STATE_IF_SETUP: flag_state, mode, 8 bytes
    0x28: 5,  # OUTPUT_IMU_RD: imu_mask uint32 BE, mode
    0x29: 1,  # SET_IMU_BANDWIDTH
    0x30: 2,  # RUN_PROC: function_id, slot
    0x31: 8,  # RUN_MULT_PROC
    0x32: 0,  # ALL_PROC_OFF
    0x33: 0,  # RESET_ZUPT_AIDED_INS
    0x34: 0,  # STEPWISE_DEAD_RECKONING
    0x35: 0,  # MIMU_FRONTEND
    0x36: 1,  # RESET_PROC_SETUP
    0x37: 0,  # STORE_AND_EMPTY_PROC_SEQU
    0x38: 0,  # RESTORE_PROC_SEQU
    0x40: 1,  # NORMAL_IMU: mode
    0x41: 1,  # NORMAL_IMU_WITH_BIAS_EST: mode
    0x42: 8,  # GP_TEST_ID
    0x43: 0,  # SMOOTHED_ZUPT_AIDED_INS (only in SMOOTHING builds)
}
"""Payload length per command ID (2015 set). 0x10/0x11 depend on build constants and are left out."""

# Mode byte (0x20, 0x21, 0x28, 0x40, 0x41): response_util.h.
MODE_RATE_MASK: Final = 0x07
MODE_LOSSLESS: Final = 0x10
MAX_RATE_DIVIDER_LOG2: Final = 6
"""Output every 2**k samples, k = 0..6: 1000 .. 15.625 Hz at the 1 kHz base rate."""

COMMAND_RX_TIMEOUT_S: Final = 200_000_000 / 64e6
"""An incomplete command is discarded after COM_TIMEOUT_LIMIT cycles at 64 MHz (≈3.1 s)."""


def checksum16(data: bytes | bytearray | memoryview) -> int:
    """Return the 16-bit unsigned sum of ``data`` (the protocol's checksum, sent MSB first)."""
    return sum(data) & 0xFFFF


def command_frame(cmd_id: int, payload: bytes = b"") -> bytes:
    """Return ``cmd_id | payload | chk_hi chk_lo``.

    Raises:
        ValueError: ``cmd_id`` is not in the 2015 command table or ``payload`` has the wrong length.
    """
    expected = COMMAND_PAYLOAD_LENGTHS.get(cmd_id)
    if expected is None:
        raise ValueError(f"command 0x{cmd_id:02X} is not in the 2015 command table")
    if len(payload) != expected:
        raise ValueError(f"command 0x{cmd_id:02X} takes {expected} payload bytes, got {len(payload)}")
    body = bytes((cmd_id,)) + payload
    return body + checksum16(body).to_bytes(2, "big")


def ack_command(pkt_number: int) -> bytes:
    """Host ACK of data packet ``pkt_number`` (lossless mode): ``01 hi lo chk_hi chk_lo``."""
    return command_frame(CMD_ACK, (pkt_number & 0xFFFF).to_bytes(2, "big"))


def ping_command() -> bytes:
    """``03 00 03``; the device answers ``A0 03 00 A3``."""
    return command_frame(CMD_PING)


def outputs_off_command() -> bytes:
    """``22 00 22``: all outputs off; also empties the device's TX queue."""
    return command_frame(CMD_OUTPUT_ALL_OFF)


def processing_off_command() -> bytes:
    """``32 00 32``: empties the process sequence, including the IMU read."""
    return command_frame(CMD_ALL_PROC_OFF)


def stepwise_dead_reckoning_command() -> bytes:
    """``34 00 34``: start stepwise dead reckoning (forces lossless mode)."""
    return command_frame(CMD_STEPWISE_DEAD_RECKONING)


def imu_mode_byte(rate_divider_log2: int, *, lossless: bool = False) -> int:
    """Return the mode byte for output every ``2**rate_divider_log2`` samples.

    Bits 0–2 carry d = rate_divider_log2 + 1 (d = 0 means off); bit 4 (0x10) selects lossless mode.

    Raises:
        ValueError: ``rate_divider_log2`` is outside 0..6.
    """
    if not 0 <= rate_divider_log2 <= MAX_RATE_DIVIDER_LOG2:
        raise ValueError(f"rate_divider_log2 must be in 0..{MAX_RATE_DIVIDER_LOG2}, got {rate_divider_log2}")
    return (rate_divider_log2 + 1) | (MODE_LOSSLESS if lossless else 0)


def rate_divider_log2_from_mode(mode: int) -> int | None:
    """Inverse of :func:`imu_mode_byte` for the rate bits: None when the mode turns output off."""
    d = mode & MODE_RATE_MASK
    return None if d == 0 else d - 1


def normal_imu_command(rate_divider_log2: int = 0, *, lossless: bool = False) -> bytes:
    """``40 mode chk``: timestamp + calibrated IMU (34-byte packets), e.g. 125 Hz lossy = ``40 04 00 44``."""
    return command_frame(CMD_NORMAL_IMU, bytes((imu_mode_byte(rate_divider_log2, lossless=lossless),)))


def normal_imu_with_bias_est_command(rate_divider_log2: int = 0, *, lossless: bool = False) -> bytes:
    """``41 mode chk``: as 0x40 with on-board ZARU gyro-bias estimation (output starts after 128 samples)."""
    mode = imu_mode_byte(rate_divider_log2, lossless=lossless)
    return command_frame(CMD_NORMAL_IMU_WITH_BIAS_EST, bytes((mode,)))


def device_ack(cmd_id: int) -> bytes:
    """The device's ACK of command ``cmd_id``: ``A0 cmd chk_hi chk_lo`` (what the emulator sends)."""
    return bytes((DEVICE_ACK_HEADER, cmd_id)) + (DEVICE_ACK_HEADER + cmd_id).to_bytes(2, "big")


def parse_device_ack(data: bytes | bytearray | memoryview) -> int:
    """Return the command ID acknowledged by the 4-byte ACK ``data``.

    Raises:
        ProtocolError: not 4 bytes, wrong header, or wrong checksum.
    """
    if len(data) != DEVICE_ACK_LEN:
        raise ProtocolError(f"a device ACK is 4 bytes (A0 id chk chk), got {bytes(data).hex(' ')}")
    if data[0] != DEVICE_ACK_HEADER:
        raise ProtocolError(f"a device ACK starts with A0, got {bytes(data).hex(' ')}")
    if (data[2] << 8 | data[3]) != DEVICE_ACK_HEADER + data[1]:
        raise ProtocolError(f"device ACK with a bad checksum: {bytes(data).hex(' ')}")
    return int(data[1])


def data_packet(pkt_number: int, payload: bytes) -> bytes:
    """Device -> host data packet ``AA hi lo N payload chk_hi chk_lo`` (chk from AA through the payload).

    Raises:
        ValueError: payload longer than 255 bytes.
    """
    if len(payload) > 0xFF:
        raise ValueError(f"a data packet holds at most 255 payload bytes, got {len(payload)}")
    head = bytes((0xAA, (pkt_number >> 8) & 0xFF, pkt_number & 0xFF, len(payload))) + payload
    return head + checksum16(head).to_bytes(2, "big")


@dataclass(frozen=True, slots=True)
class Command:
    """One host command as the device parsed it."""

    cmd_id: int
    payload: bytes

    def __bytes__(self) -> bytes:
        return command_frame(self.cmd_id, self.payload)


class CommandParser:
    """Device-side parser of host commands, behaving like the firmware's RX parser.

    Bytes that are not a known command ID (< 0x50 and in the table) are dropped one at a time. A
    complete frame with a bad checksum is dropped whole, silently. An incomplete frame is discarded
    when ``now_s`` passes its first byte's arrival by :data:`COMMAND_RX_TIMEOUT_S` (only if the caller
    passes times). Source: ``hcarlsso/openshoe-framework:src/external_interfaces/external_interface.c``.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self._started_s: float | None = None
        self.bytes_dropped = 0
        """Bytes discarded: unknown IDs, bad-checksum frames, timed-out partial frames."""
        self.bad_checksums = 0

    def feed(self, data: bytes, now_s: float | None = None) -> list[Command]:
        """Add received bytes; return the commands completed by them, in order."""
        buf = self._buf
        if (
            buf
            and now_s is not None
            and self._started_s is not None
            and now_s - self._started_s > COMMAND_RX_TIMEOUT_S
        ):
            self.bytes_dropped += len(buf)
            buf.clear()
        if not buf:
            self._started_s = now_s
        buf += data
        out: list[Command] = []
        i = 0
        n = len(buf)
        while i < n:
            cmd_id = buf[i]
            length = COMMAND_PAYLOAD_LENGTHS.get(cmd_id) if cmd_id < CID_LIMIT else None
            if length is None:
                self.bytes_dropped += 1
                i += 1
                continue
            end = i + 1 + length + 2
            if end > n:
                break
            if checksum16(buf[i : end - 2]) == (buf[end - 2] << 8 | buf[end - 1]):
                out.append(Command(cmd_id, bytes(buf[i + 1 : end - 2])))
            else:
                self.bad_checksums += 1
                self.bytes_dropped += end - i
            i = end
        del buf[:i]
        if i and buf:
            self._started_s = now_s
        return out
