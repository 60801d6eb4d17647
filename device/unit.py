"""An OpenShoe/MIMU/Oblu unit (2015 firmware) streaming normal-IMU packets over a byte link.

Start: ``40 mode chk`` and wait for ``A0 40 ..``; stream: 34-byte packets decoded in batches; stop:
``32 00 32`` (processing off) then ``22 00 22`` (outputs off), as the vendor host apps do
(protocol-openshoe.md sections 0, 3.5, 5.3, 9).
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from types import TracebackType
from typing import Final, Literal, Protocol, Self

import numpy as np

from device import protocol
from device.framer import DataPacket, DeviceAck, Framer
from device.imu_packets import PAYLOAD_LEN, CounterTracker, TickUnwrapper, decode_payloads
from pipeline.errors import DeviceError
from pipeline.samples import ImuBatch

START_TIMEOUT_S: Final = 3.0
STOP_TIMEOUT_S: Final = 1.0
_MAX_REMEMBERED_ACKS: Final = 16

CaptureTap = Callable[[Literal["rx", "tx"], int, bytes], None]
"""``tap(direction, host_ns, data)``: sees every byte read or written, before any decoding."""


class ByteLink(Protocol):
    """What a unit needs from a transport (serial, BLE, TCP, replay)."""

    @property
    def name(self) -> str:
        """Port or address, for messages."""
        ...

    async def read(self) -> bytes:
        """Next bytes (at least one), ``b""`` after close; raise ``DeviceError`` on disconnect."""
        ...

    async def write(self, data: bytes) -> None:
        """Send bytes; raise ``DeviceError`` on failure."""
        ...

    async def close(self) -> None:
        """Release the transport (idempotent)."""
        ...


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
    """Packets missing according to package-number gaps."""
    duplicates: int
    """Packets that repeated the previous package number (dropped from the batches)."""
    out_of_order: int
    """Package numbers that stepped backwards."""
    unexpected_packets: int
    """Valid packets that are not normal-IMU packets (ignored)."""
    bytes_received: int
    samples: int
    """IMU samples yielded in batches."""


class OpenShoeUnit:
    """Normal-IMU streaming from one unit.

    Args:
        link: an open byte link (e.g. :class:`device.serial_link.SerialLink`).
        capture: optional tap called with every chunk read and written (for the capture file).
    """

    def __init__(self, link: ByteLink, *, capture: CaptureTap | None = None) -> None:
        self.link = link
        self._capture = capture
        self._framer = Framer(accepted_lengths=(PAYLOAD_LEN,))
        self._ticks = TickUnwrapper()
        self._counters = CounterTracker()
        self._pending: list[tuple[int, list[bytes], list[int]]] = []
        self._acks: list[int] = []
        self._bytes_received = 0
        self._unexpected = 0
        self._samples = 0
        self._iterating = False

    @classmethod
    async def open_serial(cls, port: str, *, capture: CaptureTap | None = None) -> OpenShoeUnit:
        """Open ``port`` exclusively and return a unit on it (close with :meth:`close` or ``async with``).

        Raises:
            DeviceError: see :meth:`device.serial_link.SerialLink.open`.
        """
        from device.serial_link import SerialLink

        link = SerialLink(port)
        await link.open()
        return cls(link, capture=capture)

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
            unexpected_packets=self._unexpected,
            bytes_received=self._bytes_received,
            samples=self._samples,
        )

    async def start_imu_stream(
        self,
        rate_divider_log2: int = 0,
        *,
        with_bias_estimation: bool = False,
        timeout_s: float = START_TIMEOUT_S,
    ) -> None:
        """Send the normal-IMU command (0x40, or 0x41) and wait for its ACK.

        Args:
            rate_divider_log2: output every 2**k samples, k = 0..6: 1000, 500, ... 15.625 Hz at the
                1 kHz base rate (default 0: every sample). Lossy mode (no per-packet host ACK).
            with_bias_estimation: use 0x41 (on-board gyro-bias estimation; output starts after 128
                samples and is delayed by the front-end buffer).
            timeout_s: how long to wait for ``A0 40 ..``.

        Raises:
            DeviceError: no ACK within ``timeout_s``, or the link failed.
            ValueError: ``rate_divider_log2`` outside 0..6.
        """
        if with_bias_estimation:
            cmd_id = protocol.CMD_NORMAL_IMU_WITH_BIAS_EST
            frame = protocol.normal_imu_with_bias_est_command(rate_divider_log2)
        else:
            cmd_id = protocol.CMD_NORMAL_IMU
            frame = protocol.normal_imu_command(rate_divider_log2)
        await self._write(frame)
        if not await self._wait_for_ack(cmd_id, timeout_s):
            raise DeviceError(
                f"no answer from {self.link.name} to the start command within {timeout_s:.1f} s; "
                "is it an OpenShoe/MIMU unit on the 2015 firmware?"
            )

    async def imu_batches(self) -> AsyncIterator[ImuBatch]:
        """Yield the samples of each read as one :class:`ImuBatch`, in order, duplicates dropped.

        Ends when the link is closed; wrap in ``contextlib.aclosing`` if you may break out early.

        Raises:
            DeviceError: the unit was disconnected.
        """
        self._iterating = True
        try:
            while self._pending:
                host_ns, payloads, numbers = self._pending.pop(0)
                batch = self._batch(host_ns, payloads, numbers)
                if batch is not None:
                    yield batch
            while True:
                host_ns, payloads, numbers = await self._read_frames()
                if host_ns < 0:
                    return
                batch = self._batch(host_ns, payloads, numbers)
                if batch is not None:
                    yield batch
        finally:
            self._iterating = False

    async def stop(self, *, timeout_s: float = STOP_TIMEOUT_S) -> bool:
        """Send processing off (0x32) then outputs off (0x22).

        If no :meth:`imu_batches` loop is running, also wait up to ``timeout_s`` for the ACK of 0x22
        (data still arriving meanwhile is discarded).

        Returns:
            True if the ACK of 0x22 was seen (always False while a batch loop is running).

        Raises:
            DeviceError: the link failed while writing.
        """
        await self._write(protocol.processing_off_command())
        await self._write(protocol.outputs_off_command())
        if self._iterating:
            return False
        try:
            acked = await self._wait_for_ack(protocol.CMD_OUTPUT_ALL_OFF, timeout_s)
        except DeviceError:
            return False
        self._pending.clear()
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

    # --- internals -------------------------------------------------------------------------------

    async def _write(self, data: bytes) -> None:
        if self._capture is not None:
            self._capture("tx", time.monotonic_ns(), data)
        await self.link.write(data)

    async def _read_frames(self) -> tuple[int, list[bytes], list[int]]:
        """Read once; return (host_ns, normal-IMU payloads, their numbers); host_ns = -1 at end of stream."""
        data = await self.link.read()
        host_ns = time.monotonic_ns()
        if not data:
            return -1, [], []
        self._bytes_received += len(data)
        if self._capture is not None:
            self._capture("rx", host_ns, data)
        payloads: list[bytes] = []
        numbers: list[int] = []
        for frame in self._framer.feed(data):
            if type(frame) is DataPacket:
                if len(frame.payload) == PAYLOAD_LEN:
                    payloads.append(frame.payload)
                    numbers.append(frame.number)
                else:  # pragma: no cover - the framer only accepts PAYLOAD_LEN
                    self._unexpected += 1
            elif type(frame) is DeviceAck:
                self._acks.append(frame.cmd_id)
                del self._acks[:-_MAX_REMEMBERED_ACKS]
        return host_ns, payloads, numbers

    async def _wait_for_ack(self, cmd_id: int, timeout_s: float) -> bool:
        """Read until the ACK of ``cmd_id``; keep data packets for :meth:`imu_batches`."""
        try:
            async with asyncio.timeout(timeout_s):
                while cmd_id not in self._acks:
                    host_ns, payloads, numbers = await self._read_frames()
                    if host_ns < 0:
                        return False
                    if payloads:
                        self._pending.append((host_ns, payloads, numbers))
        except TimeoutError:
            return False
        self._acks.clear()
        return True

    def _batch(self, host_ns: int, payloads: list[bytes], numbers: list[int]) -> ImuBatch | None:
        if not payloads:
            return None
        counters, dup = self._counters.update(np.asarray(numbers, dtype=np.int64))
        arrays = decode_payloads(b"".join(payloads))
        ticks = arrays.ticks
        acc = arrays.acc_b_mps2
        gyr = arrays.gyr_b_radps
        if dup.any():
            keep = ~dup
            counters, ticks, acc, gyr = counters[keep], ticks[keep], acc[keep], gyr[keep]
            if counters.size == 0:
                return None
        t_s = self._ticks.update(ticks)
        self._samples += int(counters.size)
        return ImuBatch(
            t_s=t_s,
            acc_b_mps2=acc,
            gyr_b_radps=gyr,
            counter=counters,
            host_ns=np.full(counters.size, host_ns, dtype=np.int64),
        )
