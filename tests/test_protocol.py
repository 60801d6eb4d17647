"""Command frames, device ACKs and the firmware-style command parser (protocol-openshoe.md section 3.5)."""

from __future__ import annotations

import pytest
from footnav.device.errors import ProtocolError
from footnav.device.protocol import commands as protocol
from footnav.device.protocol.commands import Command, CommandParser


def h(text: str) -> bytes:
    return bytes.fromhex(text)


@pytest.mark.parametrize(
    ("frame", "expected"),
    [
        (protocol.stepwise_dead_reckoning_command(), "34 00 34"),
        (protocol.processing_off_command(), "32 00 32"),
        (protocol.outputs_off_command(), "22 00 22"),
        (protocol.ping_command(), "03 00 03"),
        (protocol.ack_command(0x0102), "01 01 02 00 04"),
        (protocol.ack_command(0xFFFF), "01 FF FF 01 FF"),
        (protocol.normal_imu_command(3), "40 04 00 44"),  # 125 Hz lossy
        (protocol.normal_imu_command(0), "40 01 00 41"),  # 1 kHz
        (protocol.normal_imu_command(0, lossless=True), "40 11 00 51"),
        (protocol.normal_imu_with_bias_est_command(3), "41 04 00 45"),
        (protocol.command_frame(0x28, h("00 00 00 0F 42")), "28 00 00 00 0F 42 00 79"),
        (protocol.command_frame(0x30, h("13 00")), "30 13 00 00 43"),
        (
            protocol.command_frame(0x21, h("01 20 21 22 00 00 00 00 03")),
            "21 01 20 21 22 00 00 00 00 03 00 88",
        ),
    ],
)
def test_command_golden_bytes(frame: bytes, expected: str) -> None:
    assert frame == h(expected)


@pytest.mark.parametrize(
    ("cmd_id", "ack"),
    [
        (0x34, "A0 34 00 D4"),
        (0x32, "A0 32 00 D2"),
        (0x22, "A0 22 00 C2"),
        (0x03, "A0 03 00 A3"),
        (0x40, "A0 40 00 E0"),
        (0x28, "A0 28 00 C8"),
        (0xFF, "A0 FF 01 9F"),
    ],
)
def test_device_ack_round_trip(cmd_id: int, ack: str) -> None:
    assert protocol.device_ack(cmd_id) == h(ack)
    assert protocol.parse_device_ack(h(ack)) == cmd_id


@pytest.mark.parametrize("bad", ["A0 34 00 D5", "A1 34 00 D5", "A0 34 00", "A0 34 00 D4 00"])
def test_parse_device_ack_rejects(bad: str) -> None:
    with pytest.raises(ProtocolError):
        protocol.parse_device_ack(h(bad))


def test_mode_byte() -> None:
    assert [protocol.imu_mode_byte(k) for k in range(7)] == [1, 2, 3, 4, 5, 6, 7]
    assert protocol.imu_mode_byte(1, lossless=True) == 0x12
    assert [protocol.rate_divider_log2_from_mode(m) for m in (0x00, 0x01, 0x14, 0x17)] == [None, 0, 3, 6]
    # the rate field is 4 bits (d up to 15, as GT Silicon's logging tool sends it), 3 for the raw 0x28
    assert [protocol.imu_mode_byte(k) for k in (7, 14)] == [8, 15]
    assert [protocol.rate_divider_log2_from_mode(m) for m in (0x08, 0x1F)] == [7, 14]
    assert protocol.rate_divider_log2_from_mode(0x48, raw=True) is None  # 0x28: bit 3 is the magnetometer
    assert protocol.rate_divider_log2_from_mode(0x4C, raw=True) == 3
    for bad in (-1, 15):
        with pytest.raises(ValueError, match="rate_divider_log2"):
            protocol.imu_mode_byte(bad)
    with pytest.raises(ValueError, match=r"rate_divider_log2 must be in 0\.\.6"):
        protocol.imu_mode_byte(7, flags=protocol.MODE_INERTIAL)


def test_command_frame_checks_table() -> None:
    with pytest.raises(ValueError, match="not in the 2015 command table"):
        protocol.command_frame(0x27)  # 2014-era "processing off"
    with pytest.raises(ValueError, match="takes 1 payload bytes"):
        protocol.command_frame(0x40)


def test_data_packet_checksum() -> None:
    pkt = protocol.data_packet(0x0102, h("01 02 03"))
    assert pkt == h("AA 01 02 03 01 02 03 00 B6")
    with pytest.raises(ValueError):
        protocol.data_packet(1, bytes(256))


def test_command_parser_like_firmware() -> None:
    parser = CommandParser()
    stream = (
        h("FF 55 AA")  # not command IDs: dropped one by one
        + protocol.normal_imu_command(1)
        + h("32 00 33")  # bad checksum: dropped whole
        + protocol.outputs_off_command()
    )
    cmds = [c for i in range(len(stream)) for c in parser.feed(stream[i : i + 1])]
    assert cmds == [Command(0x40, h("02")), Command(0x22, b"")]
    assert parser.bad_checksums == 1
    assert parser.bytes_dropped == 6
    assert bytes(cmds[0]) == protocol.normal_imu_command(1)


def test_command_parser_discards_stale_partial_frame() -> None:
    parser = CommandParser()
    assert parser.feed(h("40 01"), now_s=0.0) == []  # incomplete
    assert parser.feed(protocol.ping_command(), now_s=10.0) == [Command(0x03, b"")]
    assert parser.bytes_dropped == 2


# --- the complete 2015 builder set and the 2014 MIMU22BT set --------------------------------------------

C15 = protocol.Commands2015()
C14 = protocol.Commands2014()


@pytest.mark.parametrize(
    ("cmd", "expected"),
    [
        (C15.stepwise_dead_reckoning(), "34 00 34"),
        (C15.ping(), "03 00 03"),
        (C15.mcu_id(), "04 00 04"),
        (C15.outputs_off(), "22 00 22"),
        (C15.processing_off(), "32 00 32"),
        (C15.reset_ins(), "33 00 33"),
        (C15.ack(0x0102), "01 01 02 00 04"),
        (C15.normal_imu(3), "40 04 00 44"),
        (C15.normal_imu(3, bias_estimation=True), "41 04 00 45"),
        (C15.raw_imu(0x0F, 1), "28 00 00 00 0F 42 00 79"),
        (C15.run_proc(protocol.PROC_READ_INERTIAL, 0), "30 13 00 00 43"),
        (
            C15.output_states([0x01, 0x20, 0x21, 0x22], protocol.imu_mode_byte(2)),
            "21 01 20 21 22 00 00 00 00 03 00 88",
        ),
        (C15.output_state(0x20, protocol.imu_mode_byte(0, lossless=True, pull=True)), "20 20 31 00 71"),
        (C15.set_state(protocol.STATE_TH_ZUPT, (300_000).to_bytes(4, "big")), "13 19 00 04 93 E0 01 A3"),
        (C14.stepwise_dead_reckoning(), "14 00 14"),
        (C14.processing_off(), "27 00 27"),
        (C14.outputs_off(), "21 00 21"),
    ],
)
def test_builder_golden_bytes(cmd: protocol.OutgoingCommand, expected: str) -> None:
    assert cmd.frame == h(expected)


def test_command_sets_do_not_mix() -> None:
    assert C15.stepwise_dead_reckoning().harmless_on_other_set  # 0x34 is not in the 2014 table
    assert C14.processing_off().harmless_on_other_set  # 0x27 is not in the 2015 table
    assert not C15.outputs_off().harmless_on_other_set  # 0x22 = OUTPUT_ONOFF_INERT on 2014
    assert not C14.outputs_off().harmless_on_other_set  # 0x21 = OUTPUT_MULTIPLE_STATES (9 bytes) on 2015
    assert not C14.stepwise_dead_reckoning().harmless_on_other_set  # 0x14 = SET_STATE_12 on 2015
    assert protocol.device_ack(0x14) == h("A0 14 00 B4")
    parser = protocol.CommandParser(protocol.CommandSet.V2014)
    got = parser.feed(C15.stepwise_dead_reckoning().frame + C14.stepwise_dead_reckoning().frame)
    assert got == [Command(0x14, b"")]  # the 2015 ID was dropped byte by byte
    with pytest.raises(ValueError, match="not in the 2014 command table"):
        protocol._make(protocol.CommandSet.V2014, "x", 0x34)
    with pytest.raises(ValueError, match="1, 4, 12"):
        C15.set_state(0x19, b"\x00\x00")
    with pytest.raises(ValueError, match="imu_mask"):
        C15.raw_imu(0)
    with pytest.raises(ValueError, match="at most 8"):
        C15.output_states(list(range(9)), 1)
