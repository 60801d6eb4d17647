"""A virtual OpenShoe unit served on a pseudo-terminal: every output mode, lossless resends, link budget.

The host opens :attr:`PtyShoeServer.port` with real pyserial, as it would ``/dev/ttyACM0``. A background
thread does blocking I/O on the pty master: ``select()`` for host commands and for room to write,
``os.write`` for data. What the unit says and when is decided by the sans-I/O
:class:`~footnav.device.emulator.firmware.ShoeFirmware` (every mode of protocol-openshoe.md: normal and raw
IMU, INS states, stepwise dead reckoning with lossless resends, footnav's ToF/barometer extension
states, the MCU id, 2015 or 2014 command set). This module adds the transport: pacing, an optional
link budget (bytes/s, e.g. 11 500 for a 115200-baud Bluetooth UART), and fault injection (split
writes, garbage). Pty pitfalls handled here: transports-and-emulation.md section 1.2 (raw slave before
the host opens it; pyserial flushes input on open; the slave fd is kept open; closing the master is an
unplug).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import select
import termios
import threading
import time
import tty
from types import TracebackType
from typing import Final, Self

import numpy as np
from footnav.device.emulator.firmware import DEFAULT_TICK0, RESEND_INTERVAL_S, ShoeFirmware
from footnav.device.emulator.scripts import BaroScript, InsTruth, StepScript, TofScript
from footnav.device.emulator.serving.faults import FaultInjector, FaultLog, WireFaults, split_frames
from footnav.device.protocol import commands as protocol
from numpy.typing import NDArray

__all__ = ["DEFAULT_TICK0", "PtyShoeServer"]

DEFAULT_CHUNK_INTERVAL_S: Final = 0.001
"""At finite speed, data leaves in chunks at most this often (USB full-speed frames are 1 ms)."""
BT_UART_BUDGET_BPS: Final = 11_500.0
"""What a 115200-baud 8N1 UART to a Bluetooth module carries (protocol-openshoe.md section 8)."""
_READ_SIZE: Final = 4096
_BUDGET_BURST_S: Final = 0.01
"""The link budget's bucket holds this many seconds of bytes (a UART FIFO's worth)."""
_TAIL_KEEP: Final = 4096
"""Bytes kept of the end of what was written (see :meth:`PtyShoeServer.sent_prefix`)."""


class PtyShoeServer:
    """Serve an emulated unit on a pty.

    Parameters
    ----------
    t_s
        (n,) sample times, s, increasing (the unit's 1 kHz base rate; dividers apply on top).
    acc_b_mps2
        (n, 3) specific force, body frame, m/s² (normal-IMU output).
    gyr_b_radps
        (n, 3) angular rate, body frame, rad/s.
    speed
        1.0 = real time, paced by absolute deadlines, chunks every ≥1 ms; ``math.inf`` = as fast as the reader takes
        them (and, in lossless mode, as fast as it ACKs).
    chunk_interval_s
        at finite speed, the shortest time between chunks of due packets.
    tick0
        64 MHz tick of ``t_s[0]``; the default makes the uint32 counter wrap after 20 s.
    first_packet_number
        package number of the first packet (wraps at 2**16).
    split_writes_max
        if set, cut the byte stream into writes of random size 1..k, regardless of packet boundaries (split and glued
        packets).
    garbage_every
        if set, insert 1..``garbage_max_len`` random bytes (about half the time starting with a fake ``AA`` header)
        after every this many packets.
    seed
        seed for the fault generators.
    record
        keep every byte written, for :attr:`sent_bytes`.
    imu_acc_b_mps2, imu_gyr_b_radps
        (n, k, 3) per-IMU signals for raw output 0x28 (k = 1..4 or more).
    ins
        INS truth at ``t_s`` for INS-state output.
    steps
        stepwise-dead-reckoning packets (see :func:`footnav.device.emulator.scripts.steps_from_truth`).
    tof, baro
        extension-state readings.
    command_set
        firmware generation (the 2014 set answers only the old IDs).
    resend_interval_s
        lossless resend period (128 ms).
    mcu_id
        15 bytes answered to command 0x04.
    link_budget_bps
        if set, never write faster than this many bytes per second.
    faults
        bit errors, dropped, duplicated and reordered packets (:mod:`.faults`); what was done is in :attr:`fault_log`.
    stall_every_s, stall_s
        if set, stop writing for ``stall_s`` of every ``stall_every_s`` of wall time (a host or hub that stops reading);
        the firmware keeps producing meanwhile.
    temp_c
        (n,) sensor temperature, °C, for the raw output's temperature block.
    """

    def __init__(
        self,
        t_s: NDArray[np.float64],
        acc_b_mps2: NDArray[np.float64],
        gyr_b_radps: NDArray[np.float64],
        *,
        speed: float = 1.0,
        chunk_interval_s: float = DEFAULT_CHUNK_INTERVAL_S,
        tick0: int = DEFAULT_TICK0,
        first_packet_number: int = 1,
        split_writes_max: int | None = None,
        garbage_every: int | None = None,
        garbage_max_len: int = 16,
        seed: int = 0,
        record: bool = True,
        imu_acc_b_mps2: NDArray[np.float64] | None = None,
        imu_gyr_b_radps: NDArray[np.float64] | None = None,
        ins: InsTruth | None = None,
        steps: StepScript | None = None,
        tof: TofScript | None = None,
        baro: BaroScript | None = None,
        command_set: protocol.CommandSet = protocol.CommandSet.V2015,
        resend_interval_s: float = RESEND_INTERVAL_S,
        mcu_id: bytes | None = None,
        link_budget_bps: float | None = None,
        faults: WireFaults | None = None,
        stall_every_s: float | None = None,
        stall_s: float = 0.0,
        temp_c: NDArray[np.float64] | None = None,
    ) -> None:
        if split_writes_max is not None and split_writes_max < 1:
            raise ValueError("split_writes_max must be >= 1")
        if garbage_every is not None and garbage_every < 1:
            raise ValueError("garbage_every must be >= 1")
        if link_budget_bps is not None and not link_budget_bps > 0:
            raise ValueError(f"link_budget_bps must be > 0, got {link_budget_bps}")
        if stall_every_s is not None and not 0.0 < stall_s < stall_every_s:
            raise ValueError(f"need 0 < stall_s < stall_every_s, got {stall_s} and {stall_every_s}")
        extra = {} if mcu_id is None else {"mcu_id": mcu_id}
        self.firmware = ShoeFirmware(
            t_s,
            acc_b_mps2,
            gyr_b_radps,
            imu_acc_b_mps2=imu_acc_b_mps2,
            imu_gyr_b_radps=imu_gyr_b_radps,
            ins=ins,
            steps=steps,
            tof=tof,
            baro=baro,
            command_set=command_set,
            speed=speed,
            tick0=tick0,
            first_packet_number=first_packet_number,
            resend_interval_s=resend_interval_s,
            temp_c=temp_c,
            **extra,
        )
        """The emulated firmware (commands received, resends, ...); touch it only while stopped."""
        self.speed = speed
        self._chunk_interval_s = chunk_interval_s
        self._split_max = split_writes_max
        self._garbage_every = garbage_every
        self._garbage_max_len = max(1, garbage_max_len)
        self._rng = np.random.default_rng(seed)
        self._injector = FaultInjector(faults, seed + 1) if faults is not None and faults.any else None
        self._stall_every_s, self._stall_s = stall_every_s, stall_s
        self._stalls_started = 0
        self._record = record
        self._budget_bps = link_budget_bps
        self._tokens = 0.0 if link_budget_bps is None else link_budget_bps * _BUDGET_BURST_S
        self._tokens_at = time.monotonic()

        self._master, self._slave = os.openpty()
        tty.setraw(self._slave, termios.TCSANOW)  # before the host opens it: no echo, no line editing
        os.set_blocking(self._master, False)
        self.port: str = os.ttyname(self._slave)
        """Path of the pty slave: hand it to the host as its serial port."""
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)
        os.set_blocking(self._wake_w, False)

        self._packets_since_garbage = 0
        self._inflight: memoryview | None = None
        self._inflight_packets = 0
        self._sent = bytearray()
        self._head_hash = hashlib.sha256()  # the bytes before the tail
        self._head_len = 0
        self._tail = bytearray()  # the last _TAIL_KEEP..2*_TAIL_KEEP bytes written
        self._lock = threading.Lock()
        self._quit = False
        self._closed = False
        self._thread = threading.Thread(target=self._run, name=f"pty-shoe {self.port}", daemon=True)

        self.finished = threading.Event()
        """Set once every started output has sent its last item and nothing is left to write.

        It stays set; the server keeps answering commands until :meth:`stop`."""
        self.packets_sent = 0
        """Data packets written to the pty so far (lossless resends included)."""
        self.bytes_written = 0
        """Bytes written to the pty so far."""
        self.error: BaseException | None = None
        """What stopped the server thread, if it failed."""
        self._t_start = time.monotonic()

    @property
    def fault_log(self) -> FaultLog:
        """What the fault injector did so far (empty without ``faults``); read it once stopped."""
        return self._injector.log if self._injector is not None else FaultLog()

    def sent_prefix(self, length: int) -> tuple[str, bytes] | None:
        """SHA-256 (hex) of the first ``length`` bytes written and the bytes written after them, if
        ``length`` falls within the last few kB written (else None): what a host that stopped reading
        after ``length`` bytes got, and what it left unread."""
        with self._lock:
            k = length - self._head_len
            if not 0 <= k <= len(self._tail):
                return None
            digest = self._head_hash.copy()
            digest.update(self._tail[:k])
            return digest.hexdigest(), bytes(self._tail[k:])

    @property
    def stalls(self) -> int:
        """Stall windows entered so far."""
        return self._stalls_started

    @property
    def commands(self) -> list[protocol.Command]:
        """Valid host commands received, in order."""
        return self.firmware.commands

    # --- control (any thread) ---------------------------------------------------------------------

    def start(self) -> None:
        """Start serving in the background thread."""
        self._thread.start()

    def stop(self) -> None:
        """Stop the thread and close the pty (a host still reading sees a disconnect). Idempotent."""
        with self._lock:
            self._quit = True
            if not self._closed:
                with contextlib.suppress(OSError):
                    os.write(self._wake_w, b"x")  # fd still ours: closing happens under the same lock
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join()
        self._close_fds()

    def unplug(self) -> None:
        """Pull the cable: close the pty master and slave now; the host's next read fails."""
        self.stop()

    @property
    def sent_bytes(self) -> bytes:
        """Every byte written so far (data, ACKs, garbage), in order (empty if ``record=False``)."""
        with self._lock:
            return bytes(self._sent)

    def __enter__(self) -> Self:
        self.start()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    # --- the server thread ------------------------------------------------------------------------

    def _run(self) -> None:
        try:
            self._serve()
        except BaseException as exc:  # surfaced through .error; the host sees a disconnect
            self.error = exc
        finally:
            self._close_fds()

    def _serve(self) -> None:
        master, wake = self._master, self._wake_r
        fw = self.firmware
        self._t_start = time.monotonic()
        while not self._quit:
            now = time.monotonic()
            fw.produce(now)
            pending = self._inflight is not None or bool(fw.out)
            if not pending and fw.exhausted and self._injector is not None:
                held = self._injector.flush()
                if held:
                    fw.out.append((held, -1))  # already through the injector
                    pending = True
            if not pending and fw.exhausted and not self.finished.is_set():
                self.finished.set()
            timeout: float | None = None
            wake_at = fw.next_wakeup(now)
            if wake_at is not None:
                timeout = max(wake_at - time.monotonic(), self._chunk_interval_s)
            want_write = pending
            stall_left = self._stall_left(now)
            if pending and stall_left > 0.0:
                want_write = False
                timeout = stall_left if timeout is None else min(timeout, stall_left)
            if pending and self._budget_bps is not None and self._refill(now) < 1.0:
                want_write = False  # out of budget: sleep until a byte's worth has accrued
                wait = (1.0 - self._tokens) / self._budget_bps
                timeout = wait if timeout is None else min(timeout, wait)
            readable, writable, _ = select.select([master, wake], [master] if want_write else [], [], timeout)
            if wake in readable:
                with contextlib.suppress(BlockingIOError):
                    os.read(wake, 64)
                continue
            if master in readable:
                fw.receive(os.read(master, _READ_SIZE), time.monotonic())
            if master in writable:
                self._write_some()

    def _refill(self, now: float) -> float:
        assert self._budget_bps is not None
        self._tokens = min(
            self._budget_bps * _BUDGET_BURST_S, self._tokens + (now - self._tokens_at) * self._budget_bps
        )
        self._tokens_at = now
        return self._tokens

    def _stall_left(self, now: float) -> float:
        """Seconds left of the current stall window (0 outside one)."""
        every = self._stall_every_s
        if every is None:
            return 0.0
        cycle, phase = divmod(now - self._t_start, every)
        if phase < every - self._stall_s:
            return 0.0
        self._stalls_started = max(self._stalls_started, int(cycle) + 1)
        return every - phase

    def _on_the_wire(self, data: bytes, count: int) -> tuple[bytes, int]:
        """A firmware chunk as it goes out: through the fault injector, with garbage between packets."""
        if count < 0:  # a packet the injector held back, flushed at the end: already through it
            return data, 1
        every = self._garbage_every
        if self._injector is not None and count:
            if every is None:
                return self._injector.apply(data)
            frames, count = self._injector.apply_frames(data)  # cut before any header byte was hit
        elif every is None or count == 0:
            return data, count
        else:
            frames = [(frame, frame[0] == 0xAA) for frame in split_frames(data)]
        if every is None or count == 0:
            return b"".join(frame for frame, _ in frames), count
        parts: list[bytes] = []
        for frame, is_data in frames:
            parts.append(frame)
            if not is_data:
                continue
            self._packets_since_garbage += 1
            if self._packets_since_garbage >= every:
                self._packets_since_garbage = 0
                parts.append(self._garbage())
        return b"".join(parts), count

    def _garbage(self) -> bytes:
        rng = self._rng
        length = int(rng.integers(1, self._garbage_max_len + 1))
        junk = rng.bytes(length)
        if rng.random() < 0.5:  # a fake, truncated packet header
            return bytes((0xAA, *rng.bytes(2), 0x1C)) + junk
        return junk

    def _write_some(self) -> None:
        """Write what the pty (and the link budget) takes now; with split writes, many small writes."""
        fw = self.firmware
        budget = 64 if self._split_max is not None else 1
        while budget > 0:
            budget -= 1
            if self._inflight is None:
                if not fw.out:
                    return
                data, count = self._on_the_wire(*fw.out.popleft())
                self._inflight, self._inflight_packets = memoryview(data), count
            view = self._inflight
            size = len(view) if self._split_max is None else int(self._rng.integers(1, self._split_max + 1))
            if self._budget_bps is not None:
                size = min(size, int(self._refill(time.monotonic())))
                if size <= 0:
                    return
            try:
                written = os.write(self._master, view[:size])
            except BlockingIOError:
                return
            if self._budget_bps is not None:
                self._tokens -= written
            self.bytes_written += written
            with self._lock:
                self._tail += view[:written]
                if len(self._tail) > 2 * _TAIL_KEEP:
                    moved = len(self._tail) - _TAIL_KEEP
                    self._head_hash.update(self._tail[:moved])
                    self._head_len += moved
                    del self._tail[:moved]
                if self._record:
                    self._sent += view[:written]
            if written == len(view):
                self._inflight = None
                self.packets_sent += self._inflight_packets
            else:
                self._inflight = view[written:]

    def _close_fds(self) -> None:
        with self._lock:
            if self._closed:
                return
            self._closed = True
        for fd in (self._master, self._slave, self._wake_r, self._wake_w):
            with contextlib.suppress(OSError):
                os.close(fd)
