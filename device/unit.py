"""An OpenShoe/MIMU/Oblu unit on a byte link: firmware probe, every output mode, typed batches.

Start (protocol-openshoe.md sections 3, 5, 6, 10):

- the firmware generation is probed first (section 3.3): a 2015 command that 2014 firmware drops
  unparsed is sent (the requested mode's own start command when it is such a command: ``34``, ``40``,
  ``41``, ``33``; otherwise ``32 00 32``); if it is not ACKed within the probe time-out, the 2014 command
  ``14 00 14`` (stepwise dead reckoning) or ``27 00 27`` (processing off), which 2015 firmware drops, is
  sent instead. From then on every command comes from the detected set's builder and
  :meth:`OpenShoeUnit._send` refuses a command of the other set;
- modes: :class:`NormalImuMode` (0x40/0x41), :class:`RawImuMode` (``30 13 00`` then 0x28),
  :class:`InsMode` (``33 00 33`` then OUTPUT_STATE(S)), :class:`StepwiseMode` (0x34, or 0x14 on 2014
  firmware), plus the extension states (:meth:`OpenShoeUnit.enable_extensions`, see
  :mod:`footnav.device.protocol.extensions`);
- in lossless mode (forced by SWDR) every data packet is ACKed, resends included (section 6).

Stream: each read's packets become typed batches (:data:`Batch`), duplicates dropped, the package
number tracked over all packets of the interface (one counter is shared by every output; a number is
believed only in its run, :mod:`footnav.device.protocol.sequence`), values no unit sends rejected
(:mod:`footnav.device.protocol.integrity`), the 64 MHz tick counter unwrapped on one clock for every
packet kind. Packets of unknown length or kind are counted and logged once per length, never fatal.

Stop: processing off then outputs off of the detected set (``32``/``22``, or ``27``/``21``), as the
vendor host apps do.

The module is one class, about 900 lines: start, stream and stop share the driver's state (command
set, mode, package counter, tick clock). The modes are in :mod:`footnav.device.modes`, the link
interface in :mod:`footnav.device.links.base`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import AsyncGenerator, Awaitable, Callable
from dataclasses import dataclass, field
from types import TracebackType
from typing import Final, Self

import numpy as np
from footnav.device.errors import DeviceError, ProtocolError, UnsupportedModeError
from footnav.device.links.base import ByteLink, CaptureTap
from footnav.device.links.reconnecting import ReconnectingLink
from footnav.device.modes import InsMode, Mode, NormalImuMode, RawImuMode, StepwiseMode
from footnav.device.protocol import commands as p
from footnav.device.protocol import extensions, ins_states, raw_imu, stepwise
from footnav.device.protocol.extensions import BaroBatch, TofBatch
from footnav.device.protocol.framer import (
    DataPacket,
    DeviceAck,
    Frame,
    Framer,
    FramerStats,
    PacketRun,
    packet_ends,
    split_by_read,
)
from footnav.device.protocol.imu import PAYLOAD_LEN, SharedTickClock, decode_imu_rows, decode_payloads
from footnav.device.protocol.ins_states import InsLayout, InsStateBatch
from footnav.device.protocol.integrity import ImuGuard, ins_plausible, step_plausible
from footnav.device.protocol.raw_imu import RawImuBatch, RawImuLayout
from footnav.device.protocol.sequence import FAR_AHEAD, NO_TICK, CounterTracker
from footnav.device.protocol.stepwise import StepBatch, StepwiseTracker
from footnav.pipeline.samples import ImuBatch
from numpy.typing import NDArray

log = logging.getLogger(__name__)

START_TIMEOUT_S: Final = 3.0
STOP_TIMEOUT_S: Final = 1.0
PROBE_TIMEOUT_S: Final = 1.0
"""How long the probe waits for the 2015 ACK before trying the 2014 set."""
_MAX_REMEMBERED_ACKS: Final = 16

Batch = ImuBatch | RawImuBatch | InsStateBatch | StepBatch | TofBatch | BaroBatch
"""What :meth:`OpenShoeUnit.batches` yields."""


@dataclass(frozen=True, slots=True)
class LinkStats:
    """Counts since the unit object was created. Corruption is counted, never fatal."""

    packets: int
    """Valid data packets framed (any length)."""
    acks: int
    """Command ACKs received."""
    bytes_skipped: int
    """Bytes that belonged to no valid frame."""
    checksum_errors: int
    """Candidate data packets with a wrong checksum."""
    bad_lengths: int
    """Candidate data packets with an impossible length byte."""
    lost_packets: int
    """Package numbers below the highest received that never arrived (a rejected packet that arrived in
    a number's place stands for it: that number is not counted here)."""
    duplicates: int
    """Packets whose number had already been received (resends, repeats; dropped from the batches)."""
    out_of_order: int
    """Packets that arrived after a higher-numbered one (put back in order within their read)."""
    unexpected_packets: int
    """Valid packets of no active kind or of an unknown length (counted, logged once per length)."""
    bytes_received: int
    samples: int
    """Records yielded in batches (IMU samples, INS states, steps, ToF and barometer readings)."""
    acks_sent: int = 0
    """Host ACKs of data packets sent (lossless mode), resends included."""
    firmware: str = ""
    """Detected command set ("2015" or "2014"), "" before the probe."""
    corrupt_numbers: int = 0
    """Packets rejected because their number or time stamp contradicted the run (a corruption the
    checksum missed, :mod:`footnav.device.protocol.sequence`); not counted lost as well."""
    implausible_rejected: int = 0
    """Packets rejected for values the unit cannot send (:mod:`footnav.device.protocol.integrity`)."""


@dataclass
class _Decoded:
    """Payloads of one read, by kind, in arrival order; ``host_ns`` of the read."""

    host_ns: int
    normal: list[tuple[int, bytes]] = field(default_factory=list)
    raw: list[tuple[int, bytes]] = field(default_factory=list)
    ins: list[tuple[int, bytes]] = field(default_factory=list)
    steps: list[tuple[int, bytes]] = field(default_factory=list)
    tof: list[tuple[int, bytes]] = field(default_factory=list)
    baro: list[tuple[int, bytes]] = field(default_factory=list)


_COALESCE_BELOW_BYTES = 1024  # a read this small means the host has caught up with the unit
_StampedRead = Callable[[], Awaitable[list[tuple[bytes, int]]]]
"""A :class:`footnav.device.links.base.StampedByteLink`'s ``read_stamped``."""


def _skipped(stats: FramerStats) -> tuple[int, int, int]:
    """What a framer has rejected so far."""
    return stats.bytes_skipped, stats.checksum_errors, stats.bad_lengths


class OpenShoeUnit:
    """One unit: probe, start a mode, stream typed batches, stop.

    Parameters
    ----------
    link
        an open byte link (e.g. :class:`footnav.device.links.serial.SerialLink`).
    capture
        optional tap called with every chunk read and written (for the capture file).
    command_set
        the firmware's command set if known (skips the probe).
    read_interval_s
        at most one read of the link per this interval. At 1 kHz a read holds about
        one packet; coalescing reads (10 ms in live sessions: ten packets a read) cuts the
        per-batch cost several-fold for at most that much added latency. Only
        applies while caught up (reads under ``_COALESCE_BELOW_BYTES``); 0 reads as soon as
        bytes arrive.
    """

    def __init__(
        self,
        link: ByteLink,
        *,
        capture: CaptureTap | None = None,
        command_set: p.CommandSet | None = None,
        read_interval_s: float = 0.0,
    ) -> None:
        self.link = link
        self._read_stamped: _StampedRead | None = getattr(link, "read_stamped", None)
        self._dirty_reads = False  # the last stamped reads held bytes in no frame
        self._read_interval_s = read_interval_s
        self._next_read = 0.0
        self._capture = capture
        self._framer = Framer()
        self._clock = SharedTickClock()
        self._counters = CounterTracker()
        self._held: list[tuple[int, bytes]] = []  # suspects of the tracker: (number, payload)
        self._imu_guard = ImuGuard()
        self._raw_guard = ImuGuard(None, None)  # int16 registers cannot exceed the range
        self._implausible = 0
        self._pending: list[list[Batch]] = []
        self._acks: list[int] = []
        self._bytes_received = 0
        self._unexpected = 0
        self._unknown_lengths_logged: set[int] = set()
        self._samples = 0
        self._acks_sent = 0
        self._unacked: list[int] = []
        self._iterating = False
        self._commands: p.CommandBuilder | None = None if command_set is None else p.commands_for(command_set)
        self._mode: Mode | None = None
        self._raw_layout: RawImuLayout | None = None
        self._ins_layout: InsLayout | None = None
        self._lossless = False
        self._extensions: set[int] = set()
        self._mcu_id: bytes | None = None
        self._awaiting_mcu_id = False
        self.steps = StepwiseTracker()
        """The stepwise track so far (position, heading, covariance, step counts)."""

    @classmethod
    async def open_serial(
        cls, port: str, *, capture: CaptureTap | None = None, command_set: p.CommandSet | None = None
    ) -> OpenShoeUnit:
        """Open ``port`` exclusively and return a unit on it (close with :meth:`close` or ``async with``).

        Raises
        ------
        DeviceError
            see :meth:`footnav.device.links.serial.SerialLink.open`.
        """
        from footnav.device.links.serial import SerialLink

        link = SerialLink(port)
        await link.open()
        return cls(link, capture=capture, command_set=command_set)

    @property
    def command_set(self) -> p.CommandSet | None:
        """The firmware's command set, once probed (or given)."""
        return None if self._commands is None else self._commands.command_set

    @property
    def _firmware_name(self) -> str:
        return "unknown" if self.command_set is None else self.command_set.value

    @property
    def stats(self) -> LinkStats:
        """A snapshot of the link statistics."""
        f = self._framer.stats
        c = self._counters
        return LinkStats(
            packets=f.packets,
            acks=f.acks,
            bytes_skipped=f.bytes_skipped,
            checksum_errors=f.checksum_errors,
            bad_lengths=f.bad_lengths,
            lost_packets=c.lost,
            duplicates=c.duplicates,
            out_of_order=c.out_of_order,
            corrupt_numbers=c.corrupt_numbers,
            implausible_rejected=self._implausible,
            unexpected_packets=self._unexpected,
            bytes_received=self._bytes_received,
            samples=self._samples,
            acks_sent=self._acks_sent,
            firmware="" if self.command_set is None else self.command_set.value,
        )

    # --- starting and stopping ---------------------------------------------------------------------

    async def start(
        self, mode: Mode, *, timeout_s: float = START_TIMEOUT_S, probe_timeout_s: float = PROBE_TIMEOUT_S
    ) -> None:
        """Probe the firmware if needed, then start ``mode`` and wait for the unit's ACK.

        Raises
        ------
        DeviceError
            no answer, the link failed, or the unit's firmware (2014) lacks ``mode``.
        ValueError
            an invalid mode parameter (rate divider, IMU mask, state IDs).
        """
        self._set_mode(mode)
        skip_first = False
        if self._commands is None:
            first = self._probe_command(mode)
            probe_s = min(probe_timeout_s, timeout_s)
            if await self._probe(first, probe_s):
                skip_first = first.cmd_id != p.CMD_ALL_PROC_OFF  # the probe was the mode's first command
            else:
                old = p.Commands2014()
                # Only now, with 2015 firmware ruled out, may a 2014 command that 2015 would misparse go out.
                fallback = old.stepwise_dead_reckoning() if isinstance(mode, StepwiseMode) else old.processing_off()
                if pad := first.other_set_awaits:  # complete (as a bad frame) what the probe left there
                    await self._write(bytes(pad))
                if not await self._probe(fallback, probe_s, ruled_out=p.CommandSet.V2015):
                    raise DeviceError(
                        f"no answer from {self.link.name} to the start command within {probe_s:.1f} s "
                        "(tried the 2015 and 2014 command sets); is it an OpenShoe/MIMU unit, powered and "
                        "paired?"
                    )
                skip_first = isinstance(mode, StepwiseMode)
        commands = self._commands
        assert commands is not None
        if isinstance(commands, p.Commands2014):
            if not isinstance(mode, StepwiseMode):
                raise UnsupportedModeError(
                    f"the unit on {self.link.name} runs 2014 (MIMU22BT) firmware: footnav supports only "
                    "stepwise dead reckoning on it; update the firmware for IMU or INS output"
                )
            sequence = [commands.stepwise_dead_reckoning()]
        else:
            sequence = self._start_sequence(commands, mode)
        if skip_first:
            sequence = sequence[1:]
        if not sequence:
            return
        for cmd in sequence[:-1]:
            await self._send(cmd)
        last = sequence[-1]
        await self._send(last)
        if not await self._wait_for_ack(last.cmd_id, timeout_s):
            raise DeviceError(
                f"no answer from {self.link.name} to the start command within {timeout_s:.1f} s; "
                f"is it an OpenShoe/MIMU unit on the {self._firmware_name} firmware?"
            )

    async def start_imu_stream(
        self,
        rate_divider_log2: int = 0,
        *,
        with_bias_estimation: bool = False,
        timeout_s: float = START_TIMEOUT_S,
    ) -> None:
        """Start the calibrated-IMU stream (0x40, or 0x41); lossy. See :meth:`start`.

        Parameters
        ----------
        rate_divider_log2
            output every 2**k samples of the unit's base rate, k = 0..14 (default 0: every
            sample).
        with_bias_estimation
            use 0x41 (on-board gyro-bias estimation; output starts after 128
            samples and is delayed by the front-end buffer).
        timeout_s
            how long to wait for ``A0 40 ..``.

        Raises
        ------
        DeviceError
            no ACK within ``timeout_s``, or the link failed.
        ValueError
            ``rate_divider_log2`` outside 0..14.
        """
        p.imu_mode_byte(rate_divider_log2)  # validate before anything is sent
        mode = NormalImuMode(rate_divider_log2, bias_estimation=with_bias_estimation)
        await self.start(mode, timeout_s=timeout_s, probe_timeout_s=timeout_s)

    async def enable_extensions(
        self, *, tof: bool = True, baro: bool = True, timeout_s: float = START_TIMEOUT_S
    ) -> None:
        """Switch footnav's extension states (ToF 0xE1, barometer 0xE2) on or off (2015 firmware only).

        Raises
        ------
        DeviceError
            firmware not probed yet (call :meth:`start` first) or 2014 firmware, or no ACK.
        """
        commands = self._commands
        if not isinstance(commands, p.Commands2015):
            raise DeviceError(f"extension states need 2015 firmware; start a mode on {self.link.name} first")
        for state, on in ((extensions.STATE_TOF, tof), (extensions.STATE_BARO, baro)):
            cmd = commands.output_state(state, p.imu_mode_byte(0 if on else None, lossless=self._lossless))
            await self._send(cmd)
            if on:
                self._extensions.add(state)
            else:
                self._extensions.discard(state)
            if not await self._wait_for_ack(cmd.cmd_id, timeout_s):
                raise DeviceError(f"{self.link.name} did not ACK the extension state 0x{state:02X}")

    async def request_mcu_id(self, *, timeout_s: float = START_TIMEOUT_S) -> bytes:
        """Ask for the MCU serial number (command 0x04) and return its 15 bytes.

        Raises
        ------
        DeviceError
            no reply within ``timeout_s`` or no firmware probed yet.
        """
        if self._commands is None:
            await self._probe(p.Commands2015().processing_off(), min(PROBE_TIMEOUT_S, timeout_s))
            if self._commands is None and not await self._probe(p.Commands2014().processing_off(), timeout_s):
                raise DeviceError(f"no answer from {self.link.name} to the probe within {timeout_s:.1f} s")
        commands = self._commands
        assert commands is not None
        self._mcu_id = None
        self._awaiting_mcu_id = True
        try:
            await self._send(commands.mcu_id())
            async with asyncio.timeout(timeout_s):
                while self._mcu_id is None:
                    batches = await self._read_batches()
                    if batches is None:
                        break
                    if batches:
                        self._pending.append(batches)
        except TimeoutError:
            pass
        finally:
            self._awaiting_mcu_id = False
        if self._mcu_id is None:
            raise DeviceError(f"{self.link.name} did not send its MCU id within {timeout_s:.1f} s")
        return self._mcu_id

    async def stop(self, *, timeout_s: float = STOP_TIMEOUT_S) -> bool:
        """Send processing off then outputs off (``32``/``22``, or ``27``/``21`` on 2014 firmware).

        If no :meth:`batches` loop is running, also wait up to ``timeout_s`` for the ACK of outputs off
        (data still arriving meanwhile is ACKed if lossless, and discarded).

        Returns
        -------
        bool
            True if the ACK of outputs off was seen (always False while a batch loop is running).

        Raises
        ------
        DeviceError
            the link failed while writing.
        """
        commands = self._commands
        if commands is None:
            return False  # never probed, so nothing was started (and no set is known to be safe)
        off = commands.outputs_off()
        await self._send(commands.processing_off())
        await self._send(off)
        if self._iterating:
            return False
        try:
            acked = await self._wait_for_ack(off.cmd_id, timeout_s)
        except DeviceError:
            return False
        self._pending.clear()
        self._lossless = False
        self._extensions.clear()
        return acked

    async def close(self) -> None:
        """Close the link."""
        await self.link.close()

    async def __aenter__(self) -> Self:
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        await self.close()

    # --- streaming ---------------------------------------------------------------------------------

    async def batches(self) -> AsyncGenerator[Batch, None]:
        """Yield the decoded packets of each read as typed batches, in order, duplicates dropped.

        Ends when the link is closed; wrap in ``contextlib.aclosing`` if you may break out early.

        Raises
        ------
        DeviceError
            the unit was disconnected.
        """
        self._iterating = True
        try:
            while self._pending:
                for batch in self._pending.pop(0):
                    yield batch
            while True:
                batches = await self._read_batches()
                if batches is None:
                    return
                for batch in batches:
                    yield batch
        finally:
            self._iterating = False

    async def imu_batches(self) -> AsyncGenerator[ImuBatch, None]:
        """Only the :class:`ImuBatch` es of :meth:`batches` (the calibrated-IMU stream)."""
        async with contextlib.aclosing(self.batches()) as stream:
            async for batch in stream:
                if isinstance(batch, ImuBatch):
                    yield batch

    # --- internals -------------------------------------------------------------------------------

    def _set_mode(self, mode: Mode) -> None:
        """Validate ``mode`` and set up decoding for it (before its first packet can arrive)."""
        if isinstance(mode, NormalImuMode):
            p.imu_mode_byte(mode.rate_divider_log2)
        elif isinstance(mode, RawImuMode):
            p.Commands2015().raw_imu(mode.imu_mask, mode.rate_divider_log2)  # validates
            self._raw_layout = RawImuLayout(
                raw_imu.mask_to_ids(mode.imu_mask),
                temperature=mode.temperature,
                magnetometer=mode.magnetometer,
            )
        elif isinstance(mode, InsMode):
            p.imu_mode_byte(mode.rate_divider_log2)
            self._ins_layout = InsLayout(mode.state_ids)
        self._mode = mode
        self._lossless = isinstance(mode, StepwiseMode) or bool(getattr(mode, "lossless", False))
        self._counters.far_ahead = 1 if self._lossless else FAR_AHEAD  # lossless packets come in order
        if isinstance(mode, StepwiseMode):
            self.steps = StepwiseTracker()

    @staticmethod
    def _probe_command(mode: Mode) -> p.OutgoingCommand:
        """The 2015 command to probe with: the mode's start if 2014 firmware drops it unparsed."""
        c = p.Commands2015()
        if isinstance(mode, StepwiseMode):
            cmd = c.stepwise_dead_reckoning()
        elif isinstance(mode, NormalImuMode):
            cmd = c.normal_imu(mode.rate_divider_log2, bias_estimation=mode.bias_estimation, lossless=mode.lossless)
        elif isinstance(mode, InsMode):
            cmd = c.reset_ins()
        else:
            cmd = c.processing_off()
        return cmd if cmd.harmless_on_other_set else c.processing_off()

    @staticmethod
    def _start_sequence(c: p.Commands2015, mode: Mode) -> list[p.OutgoingCommand]:
        if isinstance(mode, StepwiseMode):
            return [c.stepwise_dead_reckoning()]
        if isinstance(mode, NormalImuMode):
            return [c.normal_imu(mode.rate_divider_log2, bias_estimation=mode.bias_estimation, lossless=mode.lossless)]
        if isinstance(mode, RawImuMode):
            return [
                c.run_proc(p.PROC_READ_INERTIAL, 0),
                c.raw_imu(
                    mode.imu_mask,
                    mode.rate_divider_log2,
                    lossless=mode.lossless,
                    temperature=mode.temperature,
                    magnetometer=mode.magnetometer,
                ),
            ]
        ids = InsLayout(mode.state_ids).state_ids
        rate = p.imu_mode_byte(mode.rate_divider_log2, lossless=mode.lossless)
        output = c.output_state(ids[0], rate) if len(ids) == 1 else c.output_states(ids, rate)
        return [c.reset_ins(), output]

    async def _probe(self, cmd: p.OutgoingCommand, timeout_s: float, *, ruled_out: p.CommandSet | None = None) -> bool:
        """Send a probe command; on its ACK, adopt its set.

        The command must be one the other set's firmware drops unparsed, unless that other set was
        ``ruled_out`` by an earlier unanswered probe.
        """
        other_ruled_out = ruled_out is not None and ruled_out is not cmd.command_set
        if not (cmd.harmless_on_other_set or other_ruled_out):
            raise ProtocolError(f"0x{cmd.cmd_id:02X} is not safe to send before the firmware is known")
        await self._write(cmd.frame)
        if await self._wait_for_ack(cmd.cmd_id, timeout_s):
            self._commands = p.commands_for(cmd.command_set)
            if isinstance(self.link, ReconnectingLink):  # its resume sequence is in the unit's set
                self.link.use_command_set(cmd.command_set, cmd.frame)
            log.info("%s: firmware command set %s", self.link.name, cmd.command_set.value)
            await self._ack_data()
            return True
        return False

    async def _ack_data(self) -> None:
        """ACK the data packets received so far (held back while the command set is still unknown)."""
        if self._commands is None or not self._unacked:
            return
        numbers, self._unacked = self._unacked, []
        self._acks_sent += len(numbers)
        await self._write(b"".join(self._commands.ack(n).frame for n in numbers))

    async def _send(self, cmd: p.OutgoingCommand) -> None:
        """Write a command of the detected set.

        Raises
        ------
        ProtocolError
            ``cmd`` belongs to the other command set (it would be misparsed).
        """
        if cmd.command_set is not self.command_set:
            raise ProtocolError(
                f"refusing to send {cmd.name} (0x{cmd.cmd_id:02X}) of the {cmd.command_set.value} command "
                f"set to {self.link.name}, which runs {self._firmware_name} firmware"
            )
        await self._write(cmd.frame)

    async def _write(self, data: bytes) -> None:
        if self._capture is not None:
            self._capture("tx", time.monotonic_ns(), data)
        await self.link.write(data)

    async def _read_batches(self) -> list[Batch] | None:
        """Read once; ACK lossless packets; return the read's batches (None at end of stream)."""
        if self._read_stamped is not None:
            return await self._read_stamped_batches(self._read_stamped)
        if self._read_interval_s > 0:
            wait = self._next_read - time.monotonic()
            if wait > 0:
                await asyncio.sleep(wait)
        data = await self.link.read()
        # wait before the next read only when caught up with the unit (a small read); a backlog
        # is read at full speed
        caught_up = len(data) < _COALESCE_BELOW_BYTES
        self._next_read = time.monotonic() + (self._read_interval_s if caught_up else 0.0)
        host_ns = time.monotonic_ns()
        if not data:
            return None
        self._bytes_received += len(data)
        if self._capture is not None:
            self._capture("rx", host_ns, data)
        return await self._read_frames(self._framer.feed_runs(data), host_ns)

    async def _read_stamped_batches(self, read_stamped: _StampedRead) -> list[Batch] | None:
        """:meth:`_read_batches` of a link that stamps its reads (:class:`StampedByteLink`): the reads it
        returns framed in one pass and, when they are one run of normal-IMU packets in sequence, decoded in
        one pass, each packet stamped by the read that completed it; else decoded read by read (framed
        read by read too when a byte belonged to no frame). The batches are those of the reads one by one."""
        reads = await read_stamped()
        if not reads:
            return None
        data = reads[0][0] if len(reads) == 1 else b"".join(d for d, _ in reads)
        self._bytes_received += len(data)
        if self._capture is not None:
            for d, h in reads:
                self._capture("rx", h, d)
        framer, out = self._framer, []
        point = framer.checkpoint()
        starts: list[int] = []
        if not self._dirty_reads:
            frames = framer.feed_runs(data, starts)
            if _skipped(framer.stats) != _skipped(point[1]):
                framer.rewind(point)
                self._dirty_reads = True
        if self._dirty_reads:
            # a byte in no frame: framed read by read, where a false header can hold the frames after it
            # back until the next read, as it did live (and so the next reads, until they are clean)
            for d, h in reads:
                out += await self._read_frames(framer.feed_runs(d), h)
            self._dirty_reads = _skipped(framer.stats) != _skipped(point[1])
            return out
        read_ends = np.cumsum([len(d) for d, _ in reads])
        stamps = np.array([h for _, h in reads], dtype=np.int64)
        if len(frames) == 1 and type(frames[0]) is PacketRun:
            host = stamps[np.searchsorted(read_ends, packet_ends(frames[0], starts[0]))]
            fast = self._normal_run(frames[0], host)
            if fast is not None:
                return fast
        for part, host_ns in zip(split_by_read(frames, starts, read_ends), stamps.tolist(), strict=True):
            out += await self._read_frames(part, host_ns)
        return out

    async def _read_frames(self, frames: list[Frame | PacketRun], host_ns: int) -> list[Batch]:
        """The batches of one read's ``frames``, read at ``host_ns``; ACKs lossless packets."""
        if len(frames) == 1 and type(frames[0]) is PacketRun:
            fast = self._normal_run(frames[0], host_ns)
            if fast is not None:
                return fast
        if self._normal_only(frames):
            return self._normal_reads(frames, host_ns)
        numbers: list[int] = []
        payloads: list[bytes] = []
        for frame in frames:
            if type(frame) is DataPacket:
                numbers.append(frame.number)
                payloads.append(frame.payload)
            elif type(frame) is PacketRun:
                numbers.extend(frame.numbers.tolist())
                payloads.extend(row.tobytes() for row in frame.payloads)
            elif type(frame) is DeviceAck:
                self._acks.append(frame.cmd_id)
                del self._acks[:-_MAX_REMEMBERED_ACKS]
        if not numbers:
            return []
        if self._lossless:
            self._unacked.extend(numbers)
            await self._ack_data()
        # a number is believed only in its run (suspects are held until later packets decide);
        # numbers of packets held from earlier reads come first
        tracked = self._counters.track(np.asarray(numbers, dtype=np.int64), self._ticks_of(payloads))
        numbers = [n for n, _ in self._held] + numbers
        payloads = [pl for _, pl in self._held] + payloads
        self._held = [(numbers[i], payloads[i]) for i in tracked.held.tolist()]
        decoded = _Decoded(host_ns)
        # packets that arrived after their successors are put back in order within the read (a
        # late one whose successors went out in an earlier read reaches the estimators late:
        # they count its time step as bad)
        counters = tracked.counter
        order = np.argsort(counters, kind="stable") if np.any(np.diff(counters) < 0) else range(len(counters))
        for k in order:
            i = int(tracked.positions[k])
            self._route(decoded, int(counters[k]), numbers[i], payloads[i])
        return self._build(decoded)

    def _ticks_of(self, payloads: list[bytes]) -> np.ndarray | None:
        """The packets' 64 MHz time stamps (``NO_TICK`` for a kind without one) when one output with
        time stamps is on, so that numbers and ticks move together; else None (numbers only)."""
        if self._extensions:
            return None
        mode = self._mode
        if isinstance(mode, NormalImuMode):
            length = PAYLOAD_LEN
        elif isinstance(mode, RawImuMode) and self._raw_layout is not None:
            length = self._raw_layout.payload_len
        elif isinstance(mode, InsMode) and self._ins_layout is not None and self._ins_layout.has(p.STATE_IMU_TS):
            length = self._ins_layout.payload_len
        else:
            return None
        return np.asarray(
            [int.from_bytes(pl[:4], "big") if len(pl) == length else NO_TICK for pl in payloads], dtype=np.int64
        )

    def _normal_run(self, run: PacketRun, host_ns: int | NDArray[np.int64]) -> list[Batch] | None:
        """A read that is one run of normal-IMU packets in sequence, read at ``host_ns`` (or per packet),
        decoded without a per-packet step; None, with nothing changed, when the general path is needed
        (another mode, lossless ACKs, gaps, repeats)."""
        if not (
            isinstance(self._mode, NormalImuMode)
            and run.payloads.shape[1] == PAYLOAD_LEN
            and not self._lossless
            and not self._awaiting_mcu_id
        ):
            return None
        ticks = run.heads
        assert ticks is not None
        # numbers only while extension packets share the counter (see _ticks_of)
        counters = self._counters.take_run(run.numbers, None if self._extensions else ticks)
        if counters is None:
            return None
        return self._imu_samples(counters, ticks, run.payloads, host_ns)

    def _imu_samples(
        self,
        counters: NDArray[np.int64],
        ticks: NDArray[np.int64],
        payloads: NDArray[np.uint8],
        host_ns: int | NDArray[np.int64],
    ) -> list[Batch]:
        """The normal-IMU payloads (m, 28) of the packets numbered ``counters`` (m,), time-stamped
        ``ticks`` (m,), as one batch of their plausible samples read at ``host_ns`` (or (m,), per packet;
        [] when none is plausible)."""
        imu = decode_imu_rows(payloads)
        if isinstance(host_ns, int):
            host = np.empty(len(counters), dtype=np.int64)
            host.fill(host_ns)
        else:
            host = host_ns
        if not self._imu_guard.accepts_all(counters, imu, 3):
            ok = self._imu_guard.check_rows(counters, imu, 3)
            self._implausible += len(counters) - int(np.count_nonzero(ok))
            ticks, imu, counters, host = ticks[ok], imu[ok], counters[ok], host[ok]
            if counters.size == 0:
                return []
        self._samples += int(counters.size)
        return [ImuBatch(self._clock.update(ticks), imu[:, :3].copy(), imu[:, 3:].copy(), counters, host)]

    def _normal_only(self, frames: list[Frame | PacketRun]) -> bool:
        """Whether the general path would take every data packet of ``frames`` as a normal-IMU sample
        (normal-IMU mode, lossy, no MCU id awaited, no extension output, none held, all 28 bytes)."""
        if not (
            isinstance(self._mode, NormalImuMode)
            and not self._lossless
            and not self._awaiting_mcu_id
            and not self._extensions
            and not self._held
        ):
            return False
        return all(
            type(f) is DeviceAck
            or (type(f) is PacketRun and f.payloads.shape[1] == PAYLOAD_LEN)
            or (type(f) is DataPacket and len(f.payload) == PAYLOAD_LEN)
            for f in frames
        )

    def _normal_reads(self, frames: list[Frame | PacketRun], host_ns: int) -> list[Batch]:
        """The general path for a read of normal-IMU packets only (:meth:`_normal_only`), as arrays: the
        same tracking, order, plausibility and clock, without a Python step per packet."""
        numbers: list[NDArray[np.int64]] = []
        rows: list[NDArray[np.uint8]] = []
        for frame in frames:
            if type(frame) is PacketRun:
                numbers.append(frame.numbers)
                rows.append(frame.payloads)
            elif type(frame) is DataPacket:
                numbers.append(np.array([frame.number], dtype=np.int64))
                rows.append(np.frombuffer(frame.payload, dtype=np.uint8).reshape(1, PAYLOAD_LEN))
            elif type(frame) is DeviceAck:
                self._acks.append(frame.cmd_id)
                del self._acks[:-_MAX_REMEMBERED_ACKS]
        if not numbers:
            return []
        payloads = np.concatenate(rows) if len(rows) > 1 else rows[0]
        ticks = payloads[:, :4].view(">u4")[:, 0].astype(np.int64)
        read = np.concatenate(numbers)
        tracked = self._counters.track(read, ticks)
        if tracked.held.size:  # suspects: as the general path holds them
            self._held = [(int(read[i]), payloads[i].tobytes()) for i in tracked.held.tolist()]
        positions, counters = tracked.positions, tracked.counter
        if counters.size > 1 and bool((counters[1:] < counters[:-1]).any()):  # late packets back in order
            order = np.argsort(counters, kind="stable")
            positions, counters = positions[order], counters[order]
        if counters.size == 0:
            return []
        return self._imu_samples(counters, ticks[positions], payloads[positions], host_ns)

    def _route(self, out: _Decoded, counter: int, number: int, payload: bytes) -> None:
        n = len(payload)
        kind = extensions.extension_kind(payload) if n in (9, 11) else None
        if kind is not None and kind in self._extensions:
            (out.tof if kind == extensions.STATE_TOF else out.baro).append((counter, payload))
            return
        mode = self._mode
        if isinstance(mode, StepwiseMode) and n == stepwise.PAYLOAD_LEN:
            out.steps.append((number, payload))
        elif isinstance(mode, NormalImuMode) and n == PAYLOAD_LEN:
            out.normal.append((counter, payload))
        elif isinstance(mode, RawImuMode) and self._raw_layout is not None and n == self._raw_layout.payload_len:
            out.raw.append((counter, payload))
        elif isinstance(mode, InsMode) and self._ins_layout is not None and n == self._ins_layout.payload_len:
            out.ins.append((counter, payload))
        elif self._awaiting_mcu_id and n == p.MCU_ID_LEN:
            self._mcu_id = payload
        else:
            self._unexpected += 1
            if n not in self._unknown_lengths_logged:
                self._unknown_lengths_logged.add(n)
                log.warning(
                    "%s: ignoring data packets with a %d-byte payload (not expected in %s mode); "
                    "first: %s; further ones are only counted",
                    self.link.name,
                    n,
                    type(mode).__name__ if mode else "no",
                    payload[:16].hex(" "),
                )

    def _drop_implausible(self, d: _Decoded) -> None:
        """Leave out, counted, the records no unit can send (:mod:`footnav.device.protocol.integrity`)."""
        masks: list[tuple[list[tuple[int, bytes]], np.ndarray]] = []
        if d.normal:
            arr = decode_payloads(b"".join(pl for _, pl in d.normal))
            counters = np.asarray([c for c, _ in d.normal], dtype=np.int64)
            masks.append((d.normal, self._imu_guard.check(counters, arr.acc_b_mps2, arr.gyr_b_radps)))
        if d.raw and self._raw_layout is not None:
            rarr = raw_imu.decode_payloads(b"".join(pl for _, pl in d.raw), self._raw_layout)
            counters = np.asarray([c for c, _ in d.raw], dtype=np.int64)
            masks.append((d.raw, self._raw_guard.check(counters, rarr.acc_b_mps2, rarr.gyr_b_radps)))
        if d.ins and self._ins_layout is not None:
            iarr = ins_states.decode_payloads(b"".join(pl for _, pl in d.ins), self._ins_layout)
            masks.append((d.ins, ins_plausible(iarr.pos_n_m, iarr.vel_n_mps, iarr.quat_nb_wxyz)))
        if d.steps:
            sarr = stepwise.decode_payloads(b"".join(pl for _, pl in d.steps))
            masks.append((d.steps, step_plausible(sarr.dx_m, sarr.dheading_rad, sarr.cov_4x4)))
        for group, ok in masks:
            if not ok.all():
                self._implausible += int(np.count_nonzero(~ok))
                group[:] = [g for g, keep in zip(group, ok.tolist(), strict=True) if keep]

    def _build(self, d: _Decoded) -> list[Batch]:
        """Decode each kind with one ``np.frombuffer``; one shared clock for every time stamp."""
        self._drop_implausible(d)
        ticks: list[int] = []
        for group, offset in ((d.normal, 0), (d.raw, 0), (d.tof, 1), (d.baro, 1)):
            ticks.extend(int.from_bytes(pl[offset : offset + 4], "big") for _, pl in group)
        if self._ins_layout is not None and self._ins_layout.has(p.STATE_IMU_TS):
            ticks.extend(int.from_bytes(pl[:4], "big") for _, pl in d.ins)
        t_all = self._clock.update(np.asarray(ticks, dtype=np.int64))
        out: list[Batch] = []
        k = 0

        def take(m: int) -> np.ndarray:
            nonlocal k
            k += m
            return t_all[k - m : k]

        def counter_of(group: list[tuple[int, bytes]]) -> np.ndarray:
            return np.asarray([c for c, _ in group], dtype=np.int64)

        def host(m: int) -> np.ndarray:
            return np.full(m, d.host_ns, dtype=np.int64)

        if d.normal:
            arr = decode_payloads(b"".join(pl for _, pl in d.normal))
            m = len(d.normal)
            out.append(ImuBatch(take(m), arr.acc_b_mps2, arr.gyr_b_radps, counter_of(d.normal), host(m)))
        if d.raw:
            assert self._raw_layout is not None
            rarr = raw_imu.decode_payloads(b"".join(pl for _, pl in d.raw), self._raw_layout)
            m = len(d.raw)
            out.append(
                RawImuBatch(
                    self._raw_layout.imu_ids,
                    take(m),
                    rarr.acc_b_mps2,
                    rarr.gyr_b_radps,
                    rarr.temperature_raw,
                    rarr.mag_raw,
                    counter_of(d.raw),
                    host(m),
                )
            )
        t_tof = take(len(d.tof)) if d.tof else None
        t_baro = take(len(d.baro)) if d.baro else None
        if d.ins:
            assert self._ins_layout is not None
            iarr = ins_states.decode_payloads(b"".join(pl for _, pl in d.ins), self._ins_layout)
            m = len(d.ins)
            t_ins = take(m) if iarr.ticks is not None else np.full(m, np.nan)
            out.append(
                InsStateBatch(
                    t_ins,
                    iarr.pos_n_m,
                    iarr.vel_n_mps,
                    iarr.quat_nb_wxyz,
                    iarr.cov_9x9,
                    iarr.interrupt_counter,
                    counter_of(d.ins),
                    host(m),
                )
            )
        if d.steps:
            step_batch = self.steps.update([n for n, _ in d.steps], b"".join(pl for _, pl in d.steps), d.host_ns)
            if step_batch is not None:
                out.append(step_batch)
        # Extension readings first: a host that navigates the IMU batch of this read then already
        # holds the readings taken during its samples (the firmware sends each after the IMU sample
        # of its time, so only a read boundary between the two makes a reading late).
        ext: list[Batch] = []
        if d.tof and t_tof is not None:
            tarr = extensions.decode_tof(b"".join(pl for _, pl in d.tof))
            ext.append(TofBatch(t_tof, tarr.sensor, tarr.range_m, tarr.status, counter_of(d.tof), host(len(d.tof))))
        if d.baro and t_baro is not None:
            barr = extensions.decode_baro(b"".join(pl for _, pl in d.baro))
            m = len(d.baro)
            ext.append(BaroBatch(t_baro, barr.pressure_pa, barr.temperature_c, counter_of(d.baro), host(m)))
        out = ext + out
        self._samples += sum(len(b) for b in out)
        return out

    async def _wait_for_ack(self, cmd_id: int, timeout_s: float) -> bool:
        """Read until the ACK of ``cmd_id``; keep decoded batches for :meth:`batches`."""
        try:
            async with asyncio.timeout(timeout_s):
                while cmd_id not in self._acks:
                    batches = await self._read_batches()
                    if batches is None:
                        return False
                    if batches:
                        self._pending.append(batches)
        except TimeoutError:
            return False
        self._acks.clear()
        return True
