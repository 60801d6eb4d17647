"""A virtual OpenShoe unit (2015 firmware, normal-IMU output) served on a pseudo-terminal.

The host opens :attr:`PtyShoeServer.port` with real pyserial, as it would ``/dev/ttyACM0``. A background
thread does blocking I/O on the pty master: ``select()`` for host commands and for room to write,
``os.write`` for data. Like the firmware it ACKs valid commands (``A0 id chk``), drops unknown and
bad-checksum bytes, streams 34-byte 0x40 packets only after the 0x40/0x41 start command (respecting the
rate divider) and stops on 0x32/0x22 (0x22 also empties the TX queue). Package numbers start at 1 and
are not reset by commands. Pty pitfalls handled here: transports-and-emulation.md section 1.2 (raw slave
before the host opens it; pyserial flushes input on open; the slave fd is kept open; closing the master
is an unplug). Firmware behaviour: protocol-openshoe.md sections 3.1, 4.1, 5.3.
"""

from __future__ import annotations

import contextlib
import math
import os
import select
import termios
import threading
import time
import tty
from collections import deque
from types import TracebackType
from typing import Final, Self

import numpy as np
from numpy.typing import NDArray

from device import protocol
from device.imu_packets import PACKET_LEN, encode_packets, seconds_to_ticks

DEFAULT_TICK0: Final = (1 << 32) - int(20 * 64e6)
"""First sample's tick: the 32-bit 64 MHz counter wraps 20 s into the stream."""
DEFAULT_CHUNK_INTERVAL_S: Final = 0.001
"""At finite speed, data leaves in chunks at most this often (USB full-speed frames are 1 ms)."""
MAX_CHUNK_PACKETS: Final = 256
"""Packets encoded per chunk when streaming as fast as the reader takes them."""
_READ_SIZE: Final = 4096


class PtyShoeServer:
    """Stream IMU sample arrays as a unit on a pty.

    Args:
        t_s: (n,) sample times, s, increasing (the unit's 1 kHz base rate; divider applies on top).
        acc_b_mps2: (n, 3) specific force, body frame, m/s².
        gyr_b_radps: (n, 3) angular rate, body frame, rad/s.
        speed: 1.0 = real time, paced by absolute deadlines, chunks every ≥1 ms; ``math.inf`` = as
            fast as the reader takes them.
        chunk_interval_s: at finite speed, the shortest time between chunks of due packets (1–10 ms
            is USB-like).
        tick0: 64 MHz tick of ``t_s[0]``; the default makes the uint32 counter wrap after 20 s.
        first_packet_number: package number of the first packet (wraps at 2**16).
        split_writes_max: if set, cut the byte stream into writes of random size 1..k, regardless of
            packet boundaries (split and glued packets).
        garbage_every: if set, insert 1..``garbage_max_len`` random bytes (about half the time starting
            with a fake ``AA`` header) after every this many packets.
        seed: seed for the fault generators.
        record: keep every byte written, for :attr:`sent_bytes`.
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
    ) -> None:
        self._t_s = np.asarray(t_s, dtype=np.float64)
        self._acc = np.asarray(acc_b_mps2, dtype=np.float64)
        self._gyr = np.asarray(gyr_b_radps, dtype=np.float64)
        n = self._t_s.shape[0]
        if self._acc.shape != (n, 3) or self._gyr.shape != (n, 3):
            shapes = f"{self._t_s.shape}, {self._acc.shape}, {self._gyr.shape}"
            raise ValueError(f"need t_s (n,), acc (n, 3), gyr (n, 3); got {shapes}")
        if not speed > 0:
            raise ValueError(f"speed must be > 0 (math.inf for as fast as possible), got {speed}")
        if split_writes_max is not None and split_writes_max < 1:
            raise ValueError("split_writes_max must be >= 1")
        if garbage_every is not None and garbage_every < 1:
            raise ValueError("garbage_every must be >= 1")
        self._ticks = seconds_to_ticks(self._t_s, tick0) if n else np.empty(0, np.uint32)
        self.speed = speed
        self._chunk_interval_s = chunk_interval_s
        self._split_max = split_writes_max
        self._garbage_every = garbage_every
        self._garbage_max_len = max(1, garbage_max_len)
        self._rng = np.random.default_rng(seed)
        self._record = record

        self._master, self._slave = os.openpty()
        tty.setraw(self._slave, termios.TCSANOW)  # before the host opens it: no echo, no line editing
        os.set_blocking(self._master, False)
        self.port: str = os.ttyname(self._slave)
        """Path of the pty slave: hand it to the host as its serial port."""
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)
        os.set_blocking(self._wake_w, False)

        self._parser = protocol.CommandParser()
        self._next_number = first_packet_number
        self._next_index = 0
        self._divider = 1
        self._streaming = False
        self._wall0 = 0.0
        self._t0 = 0.0
        self._packets_since_garbage = 0
        self._out: deque[tuple[bytes, int]] = deque()
        self._inflight: memoryview | None = None
        self._inflight_packets = 0
        self._sent = bytearray()
        self._lock = threading.Lock()
        self._quit = False
        self._closed = False
        self._thread = threading.Thread(target=self._run, name=f"pty-shoe {self.port}", daemon=True)

        self.finished = threading.Event()
        """Set once the last sample has been streamed (or dropped by 0x22) and nothing is left to write.

        It stays set; the server keeps answering commands until :meth:`stop`."""
        self.packets_sent = 0
        """Data packets written to the pty so far."""
        self.commands: list[protocol.Command] = []
        """Valid host commands received, in order."""
        self.error: BaseException | None = None
        """What stopped the server thread, if it failed."""

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
        n = self._t_s.shape[0]
        while not self._quit:
            now = time.monotonic()
            if self._streaming and self._next_index < n:
                self._produce(now)
            pending = self._inflight is not None or bool(self._out)
            if not pending and self._next_index >= n and not self.finished.is_set():
                self.finished.set()
            timeout: float | None = None
            if self._streaming and self._next_index < n and (not pending or not math.isinf(self.speed)):
                due = self._due_s(self._next_index)
                timeout = max(due - time.monotonic(), self._chunk_interval_s)
            readable, writable, _ = select.select([master, wake], [master] if pending else [], [], timeout)
            if wake in readable:
                with contextlib.suppress(BlockingIOError):
                    os.read(wake, 64)
                continue
            if master in readable:
                self._on_host_bytes(os.read(master, _READ_SIZE))
            if master in writable:
                self._write_some()

    def _due_s(self, index: int) -> float:
        if math.isinf(self.speed):
            return time.monotonic()
        return self._wall0 + (float(self._t_s[index]) - self._t0) / self.speed

    def _produce(self, now: float) -> None:
        """Queue the samples that are due (all up to a chunk at infinite speed)."""
        start, step, n = self._next_index, self._divider, self._t_s.shape[0]
        if math.isinf(self.speed):
            if len(self._out) >= 2:
                return
            stop = min(n, start + MAX_CHUNK_PACKETS * step)
        else:
            t_limit = self._t0 + (now - self._wall0) * self.speed
            stop = int(np.searchsorted(self._t_s, t_limit, side="right"))
        idx = np.arange(start, stop, step)
        if idx.size == 0:
            return
        self._next_index = int(idx[-1]) + step
        numbers = np.arange(self._next_number, self._next_number + idx.size)
        self._next_number = (self._next_number + idx.size) & 0xFFFF
        data = encode_packets(numbers, self._ticks[idx], self._acc[idx], self._gyr[idx])
        if self._garbage_every is not None:
            data = self._with_garbage(data)
        self._out.append((data, int(idx.size)))

    def _with_garbage(self, data: bytes) -> bytes:
        every = self._garbage_every
        assert every is not None
        parts: list[bytes] = []
        for k in range(0, len(data), PACKET_LEN):
            parts.append(data[k : k + PACKET_LEN])
            self._packets_since_garbage += 1
            if self._packets_since_garbage >= every:
                self._packets_since_garbage = 0
                parts.append(self._garbage())
        return b"".join(parts)

    def _garbage(self) -> bytes:
        rng = self._rng
        length = int(rng.integers(1, self._garbage_max_len + 1))
        junk = rng.bytes(length)
        if rng.random() < 0.5:  # a fake, truncated packet header
            return bytes((0xAA, *rng.bytes(2), 0x1C)) + junk
        return junk

    def _write_some(self) -> None:
        """Write what the pty takes now; with split writes, many small writes."""
        budget = 64 if self._split_max is not None else 1
        while budget > 0:
            budget -= 1
            if self._inflight is None:
                if not self._out:
                    return
                data, count = self._out.popleft()
                self._inflight, self._inflight_packets = memoryview(data), count
            view = self._inflight
            size = len(view) if self._split_max is None else int(self._rng.integers(1, self._split_max + 1))
            try:
                written = os.write(self._master, view[:size])
            except BlockingIOError:
                return
            if self._record:
                with self._lock:
                    self._sent += view[:written]
            if written == len(view):
                self._inflight = None
                self.packets_sent += self._inflight_packets
            else:
                self._inflight = view[written:]

    def _on_host_bytes(self, data: bytes) -> None:
        for cmd in self._parser.feed(data, time.monotonic()):
            self.commands.append(cmd)
            self._execute(cmd)

    def _execute(self, cmd: protocol.Command) -> None:
        cid = cmd.cmd_id
        if cid == protocol.CMD_ACK:
            return  # host ACKs are never acknowledged
        if cid in (protocol.CMD_NORMAL_IMU, protocol.CMD_NORMAL_IMU_WITH_BIAS_EST):
            log2 = protocol.rate_divider_log2_from_mode(cmd.payload[0])
            self._ack(cid)
            if log2 is None:
                self._streaming = False
            else:
                self._divider = 1 << log2
                if not self._streaming and self._next_index < self._t_s.shape[0]:
                    self._wall0 = time.monotonic()
                    self._t0 = float(self._t_s[self._next_index])
                self._streaming = True
            return
        if cid == protocol.CMD_OUTPUT_ALL_OFF:
            # Empties the TX queue of data; ACKs still queued and bytes already in flight go out.
            self._out = deque(item for item in self._out if item[1] == 0)
            self._streaming = False
        elif cid == protocol.CMD_ALL_PROC_OFF:
            self._streaming = False
        self._ack(cid)

    def _ack(self, cmd_id: int) -> None:
        self._out.append((protocol.device_ack(cmd_id), 0))

    def _close_fds(self) -> None:
        with self._lock:
            if self._closed:
                return
            self._closed = True
        for fd in (self._master, self._slave, self._wake_r, self._wake_w):
            with contextlib.suppress(OSError):
                os.close(fd)
