"""OpenShoe host commands (2015 and 2014 sets): frame builders, device ACKs, a firmware-style parser.

Sans-I/O: bytes in, bytes or values out. Host -> device frame::

    [cmd_id][payload, fixed length per cmd_id][chk_hi][chk_lo]    chk = sum(cmd_id..payload) mod 2**16

Device ACK of a valid command: ``A0 cmd chk_hi chk_lo`` with chk = 0xA0 + cmd. Host ACKs (0x01) are
never acknowledged. Sources: ``hcarlsso/openshoe-framework:src/external_interfaces/parsing_util.h``,
``external_interface.c``, ``src/tables/commands.c``, ``src/tables/control_tables.h`` (HEAD, 2015–2016);
see protocol-openshoe.md sections 3 and 6.

Two command sets exist and **must not be mixed** (the same ID means a different command with a
different payload length; a wrong length stalls the firmware's parser for ≈3 s):

- :attr:`CommandSet.V2015` (openshoe-framework HEAD; Oblu, MIMU22BL, MIMU4844): :class:`Commands2015`;
- :attr:`CommandSet.V2014` (MIMU22BT firmware 2014 to 2015-01, commit 1824d70): :class:`Commands2014`.

The builders return :class:`OutgoingCommand` values tagged with their set, so a sender can refuse a
command of the wrong set (``footnav.device.unit.OpenShoeUnit`` does). The module-level helpers
(:func:`command_frame`, :func:`stepwise_dead_reckoning_command`, ...) build 2015 frames as bytes.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Final

from footnav.device.errors import ProtocolError

# Command IDs (2015 set, control_tables.h HEAD). The 2014 MIMU22BT set differs: do not mix them.
CMD_ACK: Final = 0x01
CMD_PING: Final = 0x03
CMD_MCU_ID: Final = 0x04
CMD_OUTPUT_STATE: Final = 0x20
CMD_OUTPUT_MULTIPLE_STATES: Final = 0x21
CMD_OUTPUT_ALL_OFF: Final = 0x22
CMD_SET_STATE_1: Final = 0x12
CMD_SET_STATE_4: Final = 0x13
CMD_SET_STATE_12: Final = 0x14
CMD_SET_STATE_24: Final = 0x15
CMD_SET_STATE_48: Final = 0x16
CMD_SET_STATE_254: Final = 0x17
CMD_STATE_IF_SETUP: Final = 0x23
CMD_OUTPUT_IMU_RD: Final = 0x28
CMD_SET_IMU_BANDWIDTH: Final = 0x29
CMD_RUN_PROC: Final = 0x30
CMD_RUN_MULT_PROC: Final = 0x31
CMD_ALL_PROC_OFF: Final = 0x32
CMD_RESET_ZUPT_AIDED_INS: Final = 0x33
CMD_STEPWISE_DEAD_RECKONING: Final = 0x34
CMD_NORMAL_IMU: Final = 0x40
CMD_NORMAL_IMU_WITH_BIAS_EST: Final = 0x41
CMD_MIMU_FRONTEND: Final = 0x35

SET_STATE_COMMANDS: Final[dict[int, int]] = {1: 0x12, 4: 0x13, 12: 0x14, 24: 0x15, 48: 0x16, 254: 0x17}
"""Value length (bytes) -> SET_STATE command ID (2015 set)."""

# Processing functions for RUN_PROC / RUN_MULT_PROC (control_tables.h HEAD).
PROC_FRONTEND_PREPROC: Final = 0x10
PROC_STATDET: Final = 0x11
PROC_BIASEST: Final = 0x12
PROC_READ_INERTIAL: Final = 0x13
PROC_MECHANIZATION: Final = 0x20
PROC_TIME_UPDATE: Final = 0x21
PROC_ZUPT_UPDATE: Final = 0x22
PROC_INITIAL_ALIGNMENT: Final = 0x23
PROC_STEPWISE_SYSTEM_RESET: Final = 0x24

# Output state IDs (system_states.c HEAD), protocol-openshoe.md section 4.2.
STATE_IMU_TS: Final = 0x01
STATE_INTERRUPT_COUNTER: Final = 0x02
STATE_MCU_ID: Final = 0x04
STATE_U_K: Final = 0x13
STATE_TH_ZUPT: Final = 0x19
STATE_TH_ZARU: Final = 0x1A
STATE_POSITION: Final = 0x20
STATE_VELOCITY: Final = 0x21
STATE_QUATERNION: Final = 0x22
STATE_P: Final = 0x23
STATE_DX: Final = 0x30
STATE_DP: Final = 0x31
STATE_STEP_COUNTER: Final = 0x32
STATE_IMU0_RD: Final = 0x40
MCU_ID_LEN: Final = 15
"""Bytes of the MCU serial number (state 0x04), sent alone in one packet after command 0x04."""

DEVICE_ACK_HEADER: Final = 0xA0
DEVICE_ACK_LEN: Final = 4
CID_LIMIT: Final = 0x50
"""Command IDs at or above this are dropped by the firmware parser."""

COMMAND_PAYLOAD_LENGTHS: Final[dict[int, int]] = {
    0x01: 2,  # ACK: pkt number uint16 BE
    0x03: 0,  # PING
    0x04: 0,  # MCU_ID
    0x12: 2,
    0x13: 5,
    0x14: 13,
    0x15: 25,
    0x16: 49,
    0x17: 255,  # SET_STATE_1/4/12/24/48/254: id + value
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
MODE_RATE_MASK: Final = 0x0F
"""The rate field d of 0x20, 0x21, 0x40 and 0x41: 4 bits on GT Silicon's firmware (its logging tool
sends d up to 15, and a unit streamed at 7.8125 Hz with d = 8); OpenShoe's 2016 framework reads 3
(``OUTPUT_DIVIDER_MASK 0x07`` in ``response_util.h``), so there d = 8..15 is off or wraps to 0..7."""
RAW_MODE_RATE_MASK: Final = 0x07
"""The rate field of 0x28: 3 bits, for its bit 3 is :data:`MODE_MAGNETOMETER`."""
MODE_MAGNETOMETER: Final = 0x08
"""0x28 only: also send each IMU's magnetometer (states 0x90+i)."""
MODE_LOSSLESS: Final = 0x10
"""Every packet must be ACKed with 0x01 (the firmware macro is misleadingly named OUTPUT_LOSSY_MASK)."""
MODE_PULL: Final = 0x20
"""Send the state once instead of periodically."""
MODE_INERTIAL: Final = 0x40
"""0x28 only: the inertial registers (states 0x40+i); GT's raw loggers always set it."""
MODE_TEMPERATURE: Final = 0x80
"""0x28 only: also send each IMU's temperature (states 0x60+i)."""
MAX_RATE_DIVIDER_LOG2: Final = 14
"""Output every 2**k samples, k = 0..14 (d = 1..15): 1000 .. 0.061 Hz at a 1 kHz base rate."""
MAX_RAW_RATE_DIVIDER_LOG2: Final = 6
"""0x28: k = 0..6 (d = 1..7)."""

COMMAND_RX_TIMEOUT_S: Final = 200_000_000 / 64e6
"""An incomplete command is discarded after COM_TIMEOUT_LIMIT cycles at 64 MHz (≈3.1 s)."""


def checksum16(data: bytes | bytearray | memoryview) -> int:
    """Return the 16-bit unsigned sum of ``data`` (the protocol's checksum, sent MSB first)."""
    return sum(data) & 0xFFFF


def command_frame(cmd_id: int, payload: bytes = b"") -> bytes:
    """Return ``cmd_id | payload | chk_hi chk_lo``.

    Raises
    ------
    ValueError
        ``cmd_id`` is not in the 2015 command table or ``payload`` has the wrong length.
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


def imu_mode_byte(rate_divider_log2: int | None, *, lossless: bool = False, pull: bool = False, flags: int = 0) -> int:
    """Return the mode byte for output every ``2**rate_divider_log2`` samples (None: output off).

    The rate field carries d = rate_divider_log2 + 1 (d = 0 means off): bits 0–3 (d up to 15), or
    bits 0–2 for the raw output 0x28, which ``flags`` marks by holding its bits
    :data:`MODE_MAGNETOMETER`, :data:`MODE_INERTIAL` and :data:`MODE_TEMPERATURE`. Bit 4 (0x10)
    selects lossless mode, bit 5 (0x20) pull (send once).

    Raises
    ------
    ValueError
        ``rate_divider_log2`` is outside 0..14 (0..6 for 0x28), or ``flags`` has bits other than
        0x08/0x40/0x80.
    """
    if flags & ~(MODE_MAGNETOMETER | MODE_INERTIAL | MODE_TEMPERATURE):
        raise ValueError(f"flags may only hold 0x08, 0x40 and 0x80, got 0x{flags:02X}")
    top = MAX_RAW_RATE_DIVIDER_LOG2 if flags else MAX_RATE_DIVIDER_LOG2
    if rate_divider_log2 is not None and not 0 <= rate_divider_log2 <= top:
        raise ValueError(f"rate_divider_log2 must be in 0..{top}, got {rate_divider_log2}")
    d = 0 if rate_divider_log2 is None else rate_divider_log2 + 1
    return d | (MODE_LOSSLESS if lossless else 0) | (MODE_PULL if pull else 0) | flags


def rate_divider_log2_from_mode(mode: int, *, raw: bool = False) -> int | None:
    """Inverse of :func:`imu_mode_byte` for the rate field (3 bits with ``raw``, the 0x28 output):
    None when the mode turns output off."""
    d = mode & (RAW_MODE_RATE_MASK if raw else MODE_RATE_MASK)
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

    Raises
    ------
    ProtocolError
        not 4 bytes, wrong header, or wrong checksum.
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

    Raises
    ------
    ValueError
        payload longer than 255 bytes.
    """
    if len(payload) > 0xFF:
        raise ValueError(f"a data packet holds at most 255 payload bytes, got {len(payload)}")
    head = bytes((0xAA, (pkt_number >> 8) & 0xFF, pkt_number & 0xFF, len(payload))) + payload
    return head + checksum16(head).to_bytes(2, "big")


@dataclass(frozen=True, slots=True)
class Command:
    """One host command as the device parsed it (by either set's table)."""

    cmd_id: int
    payload: bytes

    def __bytes__(self) -> bytes:
        body = bytes((self.cmd_id,)) + self.payload
        return body + checksum16(body).to_bytes(2, "big")


class CommandParser:
    """Device-side parser of host commands, behaving like the firmware's RX parser.

    Bytes that are not a known command ID (< 0x50 and in the table) are dropped one at a time. A
    complete frame with a bad checksum is dropped whole, silently. An incomplete frame is discarded
    when ``now_s`` passes its first byte's arrival by :data:`COMMAND_RX_TIMEOUT_S` (only if the caller
    passes times). Source: ``hcarlsso/openshoe-framework:src/external_interfaces/external_interface.c``.

    Parameters
    ----------
    command_set
        whose table decides the IDs and payload lengths (default: the 2015 set).
    """

    def __init__(self, command_set: CommandSet | None = None) -> None:
        self._table = COMMAND_TABLES[command_set or CommandSet.V2015]
        self._buf = bytearray()
        self._started_s: float | None = None
        self.bytes_dropped = 0
        """Bytes discarded: unknown IDs, bad-checksum frames, timed-out partial frames."""
        self.bad_checksums = 0

    def feed(self, data: bytes, now_s: float | None = None) -> list[Command]:
        """Add received bytes; return the commands completed by them, in order."""
        buf = self._buf
        if buf and now_s is not None and self._started_s is not None and now_s - self._started_s > COMMAND_RX_TIMEOUT_S:
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
            length = self._table.get(cmd_id) if cmd_id < CID_LIMIT else None
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

    @property
    def bytes_awaited(self) -> int:
        """Bytes the buffered partial frame still needs (0: none buffered)."""
        if not self._buf:
            return 0
        return 1 + self._table[self._buf[0]] + 2 - len(self._buf)


# --- the 2014 MIMU22BT set and tagged builders for both sets -----------------------------------------

COMMAND_PAYLOAD_LENGTHS_2014: Final[dict[int, int]] = {
    0x01: 2,  # ACK: pkt number uint16 BE
    0x03: 0,  # PING
    0x04: 0,  # MCU_ID
    0x10: 0,  # RESET_ZUPT_AIDED_INS
    0x11: 0,  # GYRO_CALIBRATION_INIT
    0x13: 1,  # SET_LOWPASS_FILTER_IMU: log2 taps
    0x14: 0,  # STEPWISE_DEAD_RECKONING
    0x15: 1,  # RESET_SWDR_GYROCAL
    0x17: 1,  # STEPWISE_DEAD_RECKONING_TOR
    0x20: 2,  # OUTPUT_STATE: state_id, divider (low nibble) | lossless 0x10 | pull 0x20
    0x21: 0,  # OUTPUT_ALL_OFF
    0x22: 1,  # OUTPUT_ONOFF_INERT: divider
    0x23: 1,  # OUTPUT_POSITION_PLUS_ZUPT: divider
    0x24: 1,  # OUTPUT_NAVIGATIONAL_STATES: divider
    0x25: 2,  # ADD_SYNC_OUTPUT
    0x26: 0,  # SYNC_OUTPUT
    0x27: 0,  # PROCESSING_OFF
    0x28: 5,  # OUTPUT_IMU_RD: imu mask uint32, divider
    0x29: 5,  # OUTPUT_IMU_TEMP: imu mask uint32, divider
    0x30: 3,  # PROCESSING_FUNCTION_ONOFF: function id, on/off, slot
    0x31: 0,  # MIMU_FRONTEND
}
"""Payload length per command ID, 2014 MIMU22BT firmware (``hcarlsso/openshoe-framework:src/tables/
commands.c`` and ``control_tables.h`` at 1824d70). INPUT_IMU_RD (0x05), SETUP_DEBUG_PROC (0x06),
NACK (0x02) and ACC_CALIBRATION_INIT (0x12) depend on the build or are not in that table: left out."""

CMD_2014_STEPWISE_DEAD_RECKONING: Final = 0x14
CMD_2014_OUTPUT_ALL_OFF: Final = 0x21
CMD_2014_PROCESSING_OFF: Final = 0x27


class CommandSet(enum.Enum):
    """Firmware command-set generation (protocol-openshoe.md section 3.3)."""

    V2015 = "2015"
    """openshoe-framework from 2015-01 (commit a3f0240) on: Oblu, MIMU22BL, MIMU4844."""
    V2014 = "2014"
    """MIMU22BT firmware 2014 to early 2015."""


COMMAND_TABLES: Final[Mapping[CommandSet, Mapping[int, int]]] = {
    CommandSet.V2015: COMMAND_PAYLOAD_LENGTHS,
    CommandSet.V2014: COMMAND_PAYLOAD_LENGTHS_2014,
}


@dataclass(frozen=True, slots=True)
class OutgoingCommand:
    """A host command built for one command set; :attr:`frame` is what goes on the wire."""

    command_set: CommandSet
    cmd_id: int
    payload: bytes
    name: str

    @property
    def frame(self) -> bytes:
        """``cmd_id | payload | chk_hi chk_lo``."""
        body = bytes((self.cmd_id,)) + self.payload
        return body + checksum16(body).to_bytes(2, "big")

    @property
    def other_set_awaits(self) -> int:
        """Bytes the other set's parser still waits for after this frame: a payload byte that is one
        of its IDs starts a frame there (``40 01 00 41`` is ACK ``01`` waiting for 2 more bytes on 2014
        firmware), which would swallow the start of the next command unless padded."""
        parser = CommandParser(CommandSet.V2014 if self.command_set is CommandSet.V2015 else CommandSet.V2015)
        parser.feed(self.frame)
        return parser.bytes_awaited

    @property
    def harmless_on_other_set(self) -> bool:
        """True if firmware of the other set drops this ID unparsed (it is not in that table).

        Only such commands may be sent before the firmware generation is known (the probe).
        """
        other = CommandSet.V2014 if self.command_set is CommandSet.V2015 else CommandSet.V2015
        return self.cmd_id not in COMMAND_TABLES[other]


def _make(command_set: CommandSet, name: str, cmd_id: int, payload: bytes = b"") -> OutgoingCommand:
    expected = COMMAND_TABLES[command_set].get(cmd_id)
    if expected is None:
        raise ValueError(f"command 0x{cmd_id:02X} is not in the {command_set.value} command table")
    if len(payload) != expected:
        raise ValueError(f"command 0x{cmd_id:02X} takes {expected} payload bytes, got {len(payload)}")
    return OutgoingCommand(command_set, cmd_id, payload, name)


class _CommandsCommon:
    """The builders both command sets share (same IDs, same bytes)."""

    command_set: CommandSet

    def _cmd(self, name: str, cmd_id: int, payload: bytes = b"") -> OutgoingCommand:
        return _make(self.command_set, name, cmd_id, payload)

    def ack(self, pkt_number: int) -> OutgoingCommand:
        """``01 hi lo chk``: host ACK of data packet ``pkt_number`` (lossless mode); never answered."""
        return self._cmd("ack", CMD_ACK, (pkt_number & 0xFFFF).to_bytes(2, "big"))

    def ping(self) -> OutgoingCommand:
        """``03 00 03`` -> ``A0 03 00 A3``."""
        return self._cmd("ping", CMD_PING)

    def mcu_id(self) -> OutgoingCommand:
        """``04 00 04``: the unit answers with one packet holding its 15-byte MCU serial number."""
        return self._cmd("mcu id", CMD_MCU_ID)


class Commands2015(_CommandsCommon):
    """Builders for the 2015 command set (openshoe-framework HEAD), protocol-openshoe.md section 3.2."""

    command_set = CommandSet.V2015

    def outputs_off(self) -> OutgoingCommand:
        """``22 00 22``: all outputs off; empties the TX queue."""
        return self._cmd("outputs off", CMD_OUTPUT_ALL_OFF)

    def processing_off(self) -> OutgoingCommand:
        """``32 00 32``: empties the process sequence, including the IMU read."""
        return self._cmd("processing off", CMD_ALL_PROC_OFF)

    def reset_ins(self) -> OutgoingCommand:
        """``33 00 33``: outputs off, initial alignment (keep the unit still), then ZUPT-aided INS."""
        return self._cmd("reset ZUPT-aided INS", CMD_RESET_ZUPT_AIDED_INS)

    def stepwise_dead_reckoning(self) -> OutgoingCommand:
        """``34 00 34`` -> ``A0 34 00 D4``: stepwise dead reckoning (forces lossless mode)."""
        return self._cmd("stepwise dead reckoning", CMD_STEPWISE_DEAD_RECKONING)

    def mimu_frontend(self) -> OutgoingCommand:
        """``35 00 35``: IMU read plus front end only."""
        return self._cmd("MIMU front end", CMD_MIMU_FRONTEND)

    def normal_imu(
        self, rate_divider_log2: int | None = 0, *, bias_estimation: bool = False, lossless: bool = False
    ) -> OutgoingCommand:
        """``40 mode chk`` (or ``41`` with on-board gyro-bias estimation): timestamp + calibrated IMU."""
        cmd_id = CMD_NORMAL_IMU_WITH_BIAS_EST if bias_estimation else CMD_NORMAL_IMU
        mode = imu_mode_byte(rate_divider_log2, lossless=lossless)
        return self._cmd("normal IMU", cmd_id, bytes((mode,)))

    def raw_imu(
        self,
        imu_mask: int,
        rate_divider_log2: int | None = 0,
        *,
        lossless: bool = False,
        temperature: bool = False,
        magnetometer: bool = False,
    ) -> OutgoingCommand:
        """``28 mask(4) mode chk``: raw int16 registers of the IMUs whose bits are set in ``imu_mask``.

        E.g. IMUs 0–3 at 500 Hz: ``28 00 00 00 0F 42 00 79``.

        Raises
        ------
        ValueError
            ``imu_mask`` is 0 or wider than 32 bits.
        """
        if not 0 < imu_mask < 1 << 32:
            raise ValueError(f"imu_mask must select 1..32 IMUs (a non-zero uint32), got 0x{imu_mask:X}")
        flags = MODE_INERTIAL | (MODE_TEMPERATURE if temperature else 0)
        flags |= MODE_MAGNETOMETER if magnetometer else 0
        mode = imu_mode_byte(rate_divider_log2, lossless=lossless, flags=flags)
        return self._cmd("raw IMU", CMD_OUTPUT_IMU_RD, imu_mask.to_bytes(4, "big") + bytes((mode,)))

    def output_state(self, state_id: int, mode: int) -> OutgoingCommand:
        """``20 id mode chk``: one state's output on/off (``mode`` from :func:`imu_mode_byte`)."""
        return self._cmd("output state", CMD_OUTPUT_STATE, bytes((state_id & 0xFF, mode & 0xFF)))

    def output_states(self, state_ids: Sequence[int], mode: int) -> OutgoingCommand:
        """``21 id×8 mode chk``: up to 8 states at once (unused slots 0x00).

        Raises
        ------
        ValueError
            more than 8 IDs.
        """
        if len(state_ids) > 8:
            raise ValueError(f"OUTPUT_MULTIPLE_STATES takes at most 8 state IDs, got {len(state_ids)}")
        ids = bytes(i & 0xFF for i in state_ids).ljust(8, b"\x00")
        return self._cmd("output states", CMD_OUTPUT_MULTIPLE_STATES, ids + bytes((mode & 0xFF,)))

    def run_proc(self, function_id: int, slot: int) -> OutgoingCommand:
        """``30 fid slot chk``: put a processing function into a process-sequence slot (e.g. ``30 13 00``)."""
        return self._cmd("run processing function", CMD_RUN_PROC, bytes((function_id & 0xFF, slot & 0xFF)))

    def set_state(self, state_id: int, value: bytes) -> OutgoingCommand:
        """SET_STATE_1/4/12/24/48/254 (0x12–0x17) chosen by ``len(value)``; ``value`` must be big-endian.

        Raises
        ------
        ValueError
            ``len(value)`` is not 1, 4, 12, 24, 48 or 254.
        """
        cmd_id = SET_STATE_COMMANDS.get(len(value))
        if cmd_id is None:
            raise ValueError(f"state values are 1, 4, 12, 24, 48 or 254 bytes, got {len(value)}")
        return self._cmd("set state", cmd_id, bytes((state_id & 0xFF,)) + value)


class Commands2014(_CommandsCommon):
    """Builders for the 2014 MIMU22BT set (commit 1824d70), protocol-openshoe.md section 3.3."""

    command_set = CommandSet.V2014

    def outputs_off(self) -> OutgoingCommand:
        """``21 00 21`` (in the 2015 set 0x21 is OUTPUT_MULTIPLE_STATES: never send it there)."""
        return self._cmd("outputs off", CMD_2014_OUTPUT_ALL_OFF)

    def processing_off(self) -> OutgoingCommand:
        """``27 00 27``."""
        return self._cmd("processing off", CMD_2014_PROCESSING_OFF)

    def stepwise_dead_reckoning(self) -> OutgoingCommand:
        """``14 00 14`` -> ``A0 14 00 B4``."""
        return self._cmd("stepwise dead reckoning", CMD_2014_STEPWISE_DEAD_RECKONING)


CommandBuilder = Commands2015 | Commands2014


def commands_for(command_set: CommandSet) -> CommandBuilder:
    """The builder for ``command_set``."""
    return Commands2015() if command_set is CommandSet.V2015 else Commands2014()
