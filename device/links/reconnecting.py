"""Links that survive faults: reconnect with backoff, resume the unit's stream, record every gap.

:class:`ReconnectingLink` is itself a :class:`footnav.device.links.base.ByteLink`, so a unit driver uses it unchanged::

    link = ReconnectingLink.serial("/dev/ttyACM0")        # or ReconnectingLink.ble("MIMU22BL")
    await link.open()
    unit = OpenShoeUnit(link, capture=tap)
    await unit.start_imu_stream()                          # learned as the resume sequence
    async for batch in unit.imu_batches(): ...             # continues across unplug/replug

When the inner link raises ``DeviceError`` (serial unplug, BLE disconnect) or ends, the wrapper
reconnects in the background with exponential backoff (:func:`backoff_s`: 0.1 s doubling to 2 s),
writes the **resume sequence** to the new link and carries on: the pending ``read()`` simply returns
later. The resume sequence is learned from what the driver writes (the 2015 command set, parsed with
:class:`footnav.device.protocol.commands.CommandParser`): the latest stream-start command per output (0x40/0x41 normal
IMU, 0x20/0x21 output states, 0x28 raw IMU, 0x34 stepwise dead reckoning), or the stop commands
(0x32/0x22) once the driver stopped the unit. It can also be set with :meth:`ReconnectingLink.set_resume`
or replaced by a ``resume`` hook.

Every interruption becomes a :class:`LinkGap`: when data stopped, how long until it flowed again, how
many reconnect attempts it took, and how many packets are missing by package number (the wrapper
frames a copy of the stream for the numbers, believed only in their run: a corrupt one misstates no
gap, :mod:`footnav.device.protocol.sequence`; the driver still sees every byte). An **idle
watchdog** notices a unit that stops streaming while the driver is waiting for data: after
``idle_timeout_s`` (1 s) it records a stall and re-sends the resume sequence; if the unit stays silent
for another ``idle_timeout_s`` it forces a reconnect. It only runs while a continuous stream is
expected (not for stepwise dead reckoning, which may be quiet for seconds while the wearer stands),
only once the unit has sent data since the driver's last start command (a unit that never answers the
start is the driver's time-out to report, not a stall), and only while a ``read()`` is pending, so a
slow consumer is never mistaken for a silent unit.

Events (:class:`LinkEvent`, to ``on_event``): ``disconnected`` / ``stalled`` when a gap opens,
``reconnected`` when a new inner link is up, ``resumed`` when data flows again (emitted once the first
data packet after the gap is framed, so :attr:`LinkGap.packets_missing` is known by then, or when the
next gap opens first), ``gave_up``.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Final, Literal, Self

import numpy as np
from footnav.device.errors import DeviceError
from footnav.device.protocol import commands as protocol
from footnav.device.protocol.framer import Framer, data_numbers
from footnav.device.protocol.sequence import COUNTER_WRAP, CounterTracker

if TYPE_CHECKING:
    from types import TracebackType

    from footnav.device.links.base import ByteLink
    from footnav.device.links.ble import BleBackend

log = logging.getLogger(__name__)

BACKOFF_INITIAL_S: Final = 0.1
BACKOFF_FACTOR: Final = 2.0
BACKOFF_MAX_S: Final = 2.0
IDLE_TIMEOUT_S: Final = 1.0
"""A unit that sends nothing for this long while a stream is expected is noticed as stalled."""

_CONTINUOUS_STARTS: Final = frozenset(
    {
        protocol.CMD_NORMAL_IMU,
        protocol.CMD_NORMAL_IMU_WITH_BIAS_EST,
        protocol.CMD_OUTPUT_STATE,
        protocol.CMD_OUTPUT_MULTIPLE_STATES,
        protocol.CMD_OUTPUT_IMU_RD,
    }
)
"""Commands that start output at a fixed rate (their last payload byte is the mode byte)."""
_STOPS: Final = frozenset({protocol.CMD_ALL_PROC_OFF, protocol.CMD_OUTPUT_ALL_OFF})
_STOPS_2014: Final = frozenset({protocol.CMD_2014_PROCESSING_OFF, protocol.CMD_2014_OUTPUT_ALL_OFF})

Connector = Callable[[], Awaitable["ByteLink"]]
"""Opens a fresh inner link (raising ``DeviceError`` when the unit is not there)."""
ResumeHook = Callable[["ByteLink", bytes], Awaitable[None]]
"""``hook(new_link, learned_resume_bytes)``: bring a reconnected unit back to streaming."""
EventKind = Literal["disconnected", "stalled", "reconnected", "resumed", "gave_up"]


def backoff_s(attempt: int) -> float:
    """Delay before reconnect attempt ``attempt`` (0-based): 0.1, 0.2, 0.4, ... capped at 2 s."""
    return min(BACKOFF_MAX_S, BACKOFF_INITIAL_S * BACKOFF_FACTOR ** min(attempt, 32))


@dataclass(slots=True)
class LinkGap:
    """One interruption of the byte stream. Times are host ``time.monotonic_ns()``."""

    reason: str
    """What happened, e.g. "the unit on /dev/ttyACM0 was disconnected (...)" or "no data for 1.0 s"."""
    start_ns: int
    """Last byte received before the gap (or the fault time if nothing had arrived yet)."""
    detected_ns: int
    end_ns: int | None = None
    """First byte received after the gap (None while the gap is open)."""
    reconnect_attempts: int = 0
    """Connect attempts it took (0: the stream came back without reconnecting)."""
    last_packet_before: int | None = None
    """Package number of the last data packet before the gap."""
    first_packet_after: int | None = None
    """Package number of the first data packet after the gap."""
    packet_len: int | None = None
    """Length of the last data packet seen (for :attr:`bytes_missing`)."""

    @property
    def duration_s(self) -> float | None:
        """From the last byte before to the first byte after (None while open)."""
        return None if self.end_ns is None else (self.end_ns - self.start_ns) / 1e9

    @property
    def packets_missing(self) -> int | None:
        """Packets the unit numbered but the host never got, by package number (None if unknown).

        0 when numbering continued without a jump (e.g. a unit that stopped and was restarted).
        """
        a, b = self.last_packet_before, self.first_packet_after
        if a is None or b is None:
            return None
        step = (b - a + COUNTER_WRAP // 2) % COUNTER_WRAP - COUNTER_WRAP // 2
        return max(step - 1, 0)

    @property
    def bytes_missing(self) -> int | None:
        """:attr:`packets_missing` × packet length (None if unknown)."""
        n = self.packets_missing
        return None if n is None or self.packet_len is None else n * self.packet_len

    def __str__(self) -> str:
        duration = "ongoing" if self.duration_s is None else f"{self.duration_s:.2f} s"
        missing = "" if self.packets_missing is None else f", {self.packets_missing} packets missing"
        return f"gap of {duration} ({self.reason}; {self.reconnect_attempts} reconnect attempts{missing})"


@dataclass(frozen=True, slots=True)
class LinkEvent:
    """A change in link health, for the status line and the log."""

    kind: EventKind
    at_ns: int
    message: str
    gap: LinkGap | None = None


@dataclass(slots=True)
class LinkHealth:
    """Counts since :meth:`ReconnectingLink.open`."""

    state: Literal["closed", "connected", "reconnecting", "failed"] = "closed"
    reconnects: int = 0
    """Successful reconnections."""
    stalls: int = 0
    """Times the idle watchdog fired."""
    gaps: list[LinkGap] = field(default_factory=list)
    """Every gap, in order; the last may still be open."""

    @property
    def packets_missing(self) -> int:
        """Sum over gaps of the packets missing by package number."""
        return sum(g.packets_missing or 0 for g in self.gaps)

    @property
    def downtime_s(self) -> float:
        """Sum of the closed gaps' durations."""
        return sum(g.duration_s or 0.0 for g in self.gaps)


class ReconnectingLink:
    """A :class:`footnav.device.links.base.ByteLink` that reconnects its inner link and resumes the unit's stream.

    Parameters
    ----------
    connect
        opens a fresh inner link; called by :meth:`open` and for every reconnect attempt.
    name
        the unit, for messages.
    resume
        how to bring a reconnected unit back; default: write the learned resume bytes.
    idle_timeout_s
        idle-watchdog timeout (None: no watchdog).
    give_up_after_s
        stop reconnecting after this long and make ``read()`` raise (None: never).
    on_event
        called on every :class:`LinkEvent` (keep it quick; it runs on the event loop).
    tx_tap
        called as ``tap("tx", host_ns, data)`` for bytes the wrapper writes itself (resume sequences), so a capture file
        sees them too.
    """

    def __init__(
        self,
        connect: Connector,
        *,
        name: str,
        resume: ResumeHook | None = None,
        idle_timeout_s: float | None = IDLE_TIMEOUT_S,
        give_up_after_s: float | None = None,
        on_event: Callable[[LinkEvent], None] | None = None,
        tx_tap: Callable[[Literal["rx", "tx"], int, bytes], None] | None = None,
    ) -> None:
        self._connect = connect
        self._name = name
        self._resume_hook = resume
        self.idle_timeout_s = idle_timeout_s
        self.give_up_after_s = give_up_after_s
        self._on_event = on_event
        self._tx_tap = tx_tap
        self.health = LinkHealth()
        self.events: list[LinkEvent] = []
        """Every event, in order."""

        self._link: ByteLink | None = None
        self._up = asyncio.Event()
        self._closed = False
        self._failure: DeviceError | None = None
        self._reconnect_task: asyncio.Task[None] | None = None
        self._watchdog_task: asyncio.Task[None] | None = None
        self._parser = protocol.CommandParser()
        self._command_set = protocol.CommandSet.V2015
        self._stops, self._swdr = _STOPS, protocol.CMD_STEPWISE_DEAD_RECKONING
        self._desired: dict[tuple[int, int], bytes] = {}
        self._explicit_resume: bytes | None = None
        self._continuous = False
        self._framer = Framer()
        self._numbers = CounterTracker()  # a corrupt number that passed the checksum misstates no gap
        self._held_numbers: list[int] = []
        self._last_number: int | None = None
        self._packet_len: int | None = None
        self._last_rx_ns = 0
        self._reading_since_ns: int | None = None
        self._gap: LinkGap | None = None  # open: waiting for data / its first packet
        self._stalled = False
        self._nudged_ns = 0
        self._streamed = False  # data packets since the driver's last start command
        self._unreported: LinkGap | None = None  # data came back; "resumed" not emitted yet

    # --- construction helpers ---------------------------------------------------------------------

    @classmethod
    def serial(cls, port: str, **kwargs: object) -> ReconnectingLink:
        """A reconnecting :class:`footnav.device.links.serial.SerialLink` on ``port`` (same path after replug)."""

        async def connect() -> ByteLink:
            from footnav.device.links.serial import SerialLink

            link = SerialLink(port)
            await link.open()
            return link

        return cls(connect, name=port, **kwargs)  # type: ignore[arg-type]

    @classmethod
    def ble(
        cls,
        target: str | None,
        *,
        backend: BleBackend | None = None,
        scan_timeout_s: float = 5.0,
        **kwargs: object,
    ) -> ReconnectingLink:
        """A reconnecting :class:`footnav.device.links.ble.BleLink` (name, address, or None for the first unit).

        Each reconnect attempt scans again (for up to ``scan_timeout_s``): a unit that was reset may
        advertise again only after a while.
        """

        async def connect() -> ByteLink:
            from footnav.device.links.ble import BleLink

            link = BleLink(target, backend=backend, scan_timeout_s=scan_timeout_s)
            await link.open()
            return link

        return cls(connect, name=f"BLE unit {target or '(first found)'}", **kwargs)  # type: ignore[arg-type]

    # --- ByteLink ---------------------------------------------------------------------------------

    @property
    def name(self) -> str:
        """The unit, for messages."""
        return self._name

    @property
    def inner(self) -> ByteLink | None:
        """The current inner link (None while reconnecting)."""
        return self._link

    @property
    def resume_bytes(self) -> bytes:
        """What is written to a reconnected unit (learned, or set with :meth:`set_resume`)."""
        if self._explicit_resume is not None:
            return self._explicit_resume
        return b"".join(self._desired.values())

    def set_resume(self, data: bytes | None) -> None:
        """Register the bytes that bring the unit back to streaming (None: go back to learning)."""
        self._explicit_resume = data

    async def open(self) -> None:
        """Connect for the first time (no retry: a unit that is not there is reported at once).

        Raises
        ------
        DeviceError
            from the connector.
        """
        self._closed = False
        self._failure = None
        link = await self._connect()
        self._link = link
        self._up.set()
        self.health.state = "connected"
        self._last_rx_ns = time.monotonic_ns()
        if self.idle_timeout_s is not None and self._watchdog_task is None:
            self._watchdog_task = asyncio.create_task(self._watchdog(), name=f"watchdog {self._name}")

    async def read(self) -> bytes:
        """Next bytes from the unit, across reconnects; ``b""`` after :meth:`close`.

        Raises
        ------
        DeviceError
            reconnecting was given up (``give_up_after_s``), or never opened.
        """
        while True:
            if self._closed:
                return b""
            link = self._link
            if link is None:
                if self._failure is not None:
                    raise self._failure
                if self._reconnect_task is None:
                    raise DeviceError(f"{self._name} is not open")
                await self._up.wait()
                continue
            self._reading_since_ns = time.monotonic_ns()
            try:
                data = await link.read()
            except DeviceError as exc:
                self._fault(link, str(exc))
                continue
            finally:
                self._reading_since_ns = None
            if not data:
                if not self._closed:
                    self._fault(link, f"the stream from {self._name} ended")
                continue
            self._on_rx(data)
            return data

    async def write(self, data: bytes) -> None:
        """Send ``data``; commands that set the unit's streaming state are also remembered for resume.

        While reconnecting, a write made only of such commands returns at once (they are applied on
        reconnect); anything else raises.

        Raises
        ------
        DeviceError
            the link is down (and ``data`` is not only state commands) or the write failed.
        """
        only_state = self._learn(data)
        link = self._link
        if link is None:
            if only_state and self._failure is None and not self._closed:
                return
            raise DeviceError(f"cannot write to {self._name}: the link is down (reconnecting)")
        try:
            await link.write(data)
        except DeviceError as exc:
            self._fault(link, str(exc))
            if not only_state:
                raise

    async def close(self) -> None:
        """Stop reconnecting and close the inner link (idempotent); a pending read returns ``b""``."""
        self._closed = True
        self.health.state = "closed"
        self._up.set()
        for task in (self._reconnect_task, self._watchdog_task):
            if task is not None and task is not asyncio.current_task():
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError, DeviceError):
                    await task
        self._reconnect_task = self._watchdog_task = None
        link, self._link = self._link, None
        if link is not None:
            with contextlib.suppress(DeviceError, OSError):
                await link.close()

    async def __aenter__(self) -> Self:
        await self.open()
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        await self.close()

    # --- internals --------------------------------------------------------------------------------

    def _emit(self, kind: EventKind, message: str, gap: LinkGap | None = None) -> None:
        event = LinkEvent(kind, time.monotonic_ns(), message, gap)
        self.events.append(event)
        log.log(logging.INFO if kind in ("reconnected", "resumed") else logging.WARNING, "%s", message)
        if self._on_event is not None:
            self._on_event(event)

    def use_command_set(self, command_set: protocol.CommandSet, acked: bytes = b"") -> None:
        """Read the host's bytes as ``command_set`` from now on (the driver probed the firmware); on a
        change, forget what the other set's probes taught and learn ``acked``, the answered probe."""
        if command_set is self._command_set:
            return
        self._command_set = command_set
        self._parser = protocol.CommandParser(command_set)
        v2014 = command_set is protocol.CommandSet.V2014
        self._stops = _STOPS_2014 if v2014 else _STOPS
        self._swdr = protocol.CMD_2014_STEPWISE_DEAD_RECKONING if v2014 else protocol.CMD_STEPWISE_DEAD_RECKONING
        self._desired.clear()
        self._continuous = False
        self._learn(acked)

    def _learn(self, data: bytes) -> bool:
        """Update the resume state from host -> device bytes; True if they held only state commands."""
        commands = self._parser.feed(data)
        only_state = bool(commands)
        v2014 = self._command_set is protocol.CommandSet.V2014
        for cmd in commands:
            cid = cmd.cmd_id
            if cid in self._stops:
                if self._continuous or any(k[0] not in self._stops for k in self._desired):
                    self._desired.clear()
                self._continuous = False
                self._desired[(cid, 0)] = bytes(cmd)
            elif (cid in _CONTINUOUS_STARTS and not v2014) or cid == self._swdr:
                for key in [k for k in self._desired if k[0] in self._stops]:
                    del self._desired[key]
                key = (cid, cmd.payload[0] if cid == protocol.CMD_OUTPUT_STATE else 0)
                raw = cid == protocol.CMD_OUTPUT_IMU_RD
                off = (
                    cid in _CONTINUOUS_STARTS and protocol.rate_divider_log2_from_mode(cmd.payload[-1], raw=raw) is None
                )
                if off:
                    self._desired.pop(key, None)
                else:
                    self._desired[key] = bytes(cmd)
                    self._streamed = False
                self._continuous = any(k[0] in _CONTINUOUS_STARTS for k in self._desired)
            else:
                only_state = False
        return only_state

    def _on_rx(self, data: bytes) -> None:
        now = time.monotonic_ns()
        self._last_rx_ns = now
        gap = self._gap
        if gap is not None and gap.end_ns is None:
            gap.end_ns = now
            self._stalled = False
            self._unreported = gap
        new, payload_len = data_numbers(self._framer.feed_runs(data))
        if payload_len is not None:
            self._packet_len, self._streamed = payload_len + 6, True
            tracked = self._numbers.track(new)
            seen = np.concatenate([np.asarray(self._held_numbers, dtype=np.int64), new])
            self._held_numbers = seen[tracked.held].tolist()
            if tracked.positions.size and gap is not None and gap.first_packet_after is None:
                gap.first_packet_after = int(seen[tracked.positions[np.argmin(tracked.counter)]])
                self._gap = gap = None
            self._last_number = self._numbers.high_raw
        unreported = self._unreported
        if unreported is not None and unreported.first_packet_after is not None:
            self._report_resumed()

    def _report_resumed(self) -> None:
        gap, self._unreported = self._unreported, None
        if gap is None:
            return
        missing = "" if gap.packets_missing is None else f", {gap.packets_missing} packets missing"
        self._emit("resumed", f"data from {self._name} again after {gap.duration_s:.2f} s{missing}", gap)

    def _open_gap(self, reason: str) -> LinkGap:
        now = time.monotonic_ns()
        self._report_resumed()  # data had come back, but no packet before this new gap
        gap = self._gap
        if gap is None or gap.end_ns is not None:
            if gap is not None:
                self._gap = None  # data came back but no packet yet: close it as it is
            gap = LinkGap(
                reason=reason,
                start_ns=self._last_rx_ns or now,
                detected_ns=now,
                last_packet_before=self._last_number,
                packet_len=self._packet_len,
            )
            self.health.gaps.append(gap)
            self._gap = gap
        return gap

    def _fault(self, link: ByteLink, reason: str) -> None:
        """The inner link failed: drop it and reconnect in the background (once per link)."""
        if link is not self._link or self._closed:
            return
        self._link = None
        self._up.clear()
        self.health.state = "reconnecting"
        gap = self._open_gap(reason)
        self._emit("disconnected", f"{reason}; reconnecting", gap)
        self._reconnect_task = asyncio.create_task(self._reconnect(link, gap), name=f"reconnect {self._name}")

    async def _reconnect(self, old: ByteLink, gap: LinkGap) -> None:
        with contextlib.suppress(DeviceError, OSError):
            await old.close()
        t0 = time.monotonic()
        attempt = 0
        last_error = ""
        while not self._closed:
            await asyncio.sleep(backoff_s(attempt))
            attempt += 1
            gap.reconnect_attempts += 1
            try:
                link = await self._connect()
            except DeviceError as exc:
                if str(exc) != last_error:
                    last_error = str(exc)
                    log.info("reconnect to %s: %s (retrying with backoff)", self._name, exc)
                if self.give_up_after_s is not None and time.monotonic() - t0 > self.give_up_after_s:
                    self._failure = DeviceError(
                        f"gave up reconnecting to {self._name} after {time.monotonic() - t0:.1f} s "
                        f"and {attempt} attempts: {exc}"
                    )
                    self.health.state = "failed"
                    self._emit("gave_up", str(self._failure), gap)
                    self._up.set()
                    return
                continue
            try:
                await self._resume(link)
            except DeviceError as exc:
                log.info("resuming %s failed: %s (retrying)", self._name, exc)
                with contextlib.suppress(DeviceError, OSError):
                    await link.close()
                continue
            if self._closed:
                with contextlib.suppress(DeviceError, OSError):
                    await link.close()
                return
            self._framer = Framer()  # the old tail belongs to no packet
            self._link = link
            self._stalled = False
            self.health.state = "connected"
            self.health.reconnects += 1
            self._reconnect_task = None
            self._up.set()
            self._emit("reconnected", f"reconnected to {self._name} after {attempt} attempts", gap)
            return

    async def _resume(self, link: ByteLink) -> None:
        data = self.resume_bytes
        if self._resume_hook is not None:
            await self._resume_hook(link, data)
            return
        if data:
            if self._tx_tap is not None:
                self._tx_tap("tx", time.monotonic_ns(), data)
            await link.write(data)

    async def _watchdog(self) -> None:
        timeout = self.idle_timeout_s
        assert timeout is not None
        limit_ns = int(timeout * 1e9)
        while not self._closed:
            await asyncio.sleep(min(0.1, timeout / 4))
            link = self._link
            reading = self._reading_since_ns
            if link is None or reading is None or not self._continuous or not self._streamed:
                continue
            now = time.monotonic_ns()
            silent_ns = now - max(self._last_rx_ns, reading, self._nudged_ns)
            if silent_ns < limit_ns:
                continue
            if not self._stalled:
                self._stalled = True
                self.health.stalls += 1
                gap = self._open_gap(f"no data from {self._name} for {silent_ns / 1e9:.1f} s")
                self._emit("stalled", f"{self._name} stopped streaming; re-sending the start command", gap)
                try:
                    await self._resume(link)
                except DeviceError as exc:
                    self._fault(link, str(exc))
                self._nudged_ns = time.monotonic_ns()  # give the restart a full timeout
                continue
            self._fault(link, f"no data from {self._name} for {silent_ns / 1e9:.1f} s after a restart")
