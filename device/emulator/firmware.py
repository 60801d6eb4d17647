"""The emulated unit's firmware, sans-I/O: host bytes in, timed output bytes out, every output mode.

A transport (the pty server, a BLE peripheral) calls :meth:`ShoeFirmware.receive` with host bytes,
:meth:`ShoeFirmware.produce` whenever it may write, and drains :attr:`ShoeFirmware.out`; it sleeps
until :meth:`ShoeFirmware.next_wakeup`. Behaviour follows the firmware as documented in
protocol-openshoe.md (sections 3, 4, 5, 6):

- commands parsed with the detected generation's table (:class:`~footnav.device.protocol.commands.CommandSet`): the
  2015 set (default) or the 2014 MIMU22BT set, which answers only the old IDs (``14`` SWDR, ``27``
  processing off, ``21`` outputs off, ``03``, ``04``); IDs of the other set are dropped unparsed or
  misparsed exactly as that firmware would;
- every valid command is ACKed (``A0 id chk``); host ACKs (0x01) never are;
- outputs: normal IMU 0x40/0x41 (mode-byte divider), raw IMU 0x28 (any IMU subset, optional
  temperature/magnetometer blocks), INS states requested with 0x20/0x21 after 0x33 (any subset of
  0x01, 0x02, 0x20–0x23), stepwise dead reckoning 0x34 (from a :class:`~.scripts.StepScript`),
  footnav's extension states 0xE1 (ToF) and 0xE2 (barometer), the MCU id (0x04); one package counter
  shared by all of them, starting at 1 and never reset by commands;
- **lossless mode** (mode bit 0x10, forced by 0x34): packets wait in a queue of at most 512 entries /
  2048 bytes; only the oldest is sent, and resent every ``resend_interval_s`` (128 ms) until the host
  ACKs exactly its number; command ACKs queue behind unACKed data; a full queue drops new packets (the
  gap shows in the package numbers). 0x22 (0x21 on 2014) empties the queue.

Time: the device clock starts with the first start command and runs at ``speed`` × wall time; at
``speed = inf`` it runs as fast as the transport takes the bytes (and, in lossless mode, as fast as
the host ACKs).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final

import numpy as np
from footnav.device.emulator.scripts import BaroScript, InsTruth, StepScript, TofScript
from footnav.device.protocol import commands as p
from footnav.device.protocol import extensions, ins_states, raw_imu, stepwise
from footnav.device.protocol.imu import PAYLOAD_DTYPE, TICK_HZ, TICK_WRAP, frame_payload_rows
from numpy.typing import NDArray

F64 = NDArray[np.float64]

DEFAULT_TICK0: Final = (1 << 32) - int(20 * 64e6)
"""First sample's tick: the 32-bit 64 MHz counter wraps 20 s into the stream."""
RESEND_INTERVAL_S: Final = 0.128
"""``RESEND_DELAY`` = 128 main-loop ticks at 1 kHz (package_queue.c)."""
QUEUE_MAX_ENTRIES: Final = 512
QUEUE_MAX_BYTES: Final = 2048
MAX_CHUNK_PACKETS: Final = 256
"""Packets produced per call at infinite speed."""
DEFAULT_MCU_ID: Final = bytes.fromhex("46 4e 41 56 00 01 02 03 04 05 06 07 08 09 0a")
"""A made-up 15-byte MCU serial number ("FNAV" + counter)."""
_INS_STATE_SET: Final = frozenset(ins_states.INS_STATE_IDS)


@dataclass
class _Output:
    """One periodic or event output: item times, a payload encoder, a cursor."""

    times: F64
    encode: Callable[[NDArray[np.int64]], NDArray[np.uint8]]
    step: int = 1
    cursor: int = 0
    once: bool = False

    def remaining(self) -> bool:
        return self.cursor < self.times.shape[0]

    def next_time(self) -> float:
        return float(self.times[self.cursor])


class ShoeFirmware:
    """A virtual OpenShoe/MIMU/Oblu unit's command handling and output generation.

    Parameters
    ----------
    t_s
        (n,) base sample times, s (1 kHz on MIMU boards).
    acc_b_mps2
        (n, 3) calibrated specific force for 0x40/0x41.
    gyr_b_radps
        (n, 3) calibrated angular rate for 0x40/0x41.
    imu_acc_b_mps2
        (n, k, 3) per-IMU specific force for 0x28 (default: ``acc_b_mps2`` on 4 IMUs).
    imu_gyr_b_radps
        (n, k, 3) per-IMU angular rate for 0x28.
    ins
        INS states at ``t_s`` for 0x33 + 0x20/0x21 (footnav frame; sent z-down).
    steps
        stepwise-dead-reckoning packets for 0x34 / 0x14.
    tof
        ToF readings for state 0xE1.
    baro
        barometer readings for state 0xE2.
    command_set
        firmware generation.
    speed
        device seconds per wall second; ``math.inf`` = as fast as taken.
    tick0
        64 MHz tick at ``t_s[0]``.
    first_packet_number
        package number of the first packet.
    resend_interval_s
        lossless resend period.
    mcu_id
        the 15 bytes answered to 0x04.
    temp_c
        (n,) sensor temperature, °C, sent in the raw output's temperature block (default: a constant 24 °C, the register
        value 1000).
    """

    def __init__(
        self,
        t_s: F64,
        acc_b_mps2: F64,
        gyr_b_radps: F64,
        *,
        imu_acc_b_mps2: F64 | None = None,
        imu_gyr_b_radps: F64 | None = None,
        ins: InsTruth | None = None,
        steps: StepScript | None = None,
        tof: TofScript | None = None,
        baro: BaroScript | None = None,
        command_set: p.CommandSet = p.CommandSet.V2015,
        speed: float = 1.0,
        tick0: int = DEFAULT_TICK0,
        first_packet_number: int = 1,
        resend_interval_s: float = RESEND_INTERVAL_S,
        mcu_id: bytes = DEFAULT_MCU_ID,
        temp_c: F64 | None = None,
    ) -> None:
        self._t = np.asarray(t_s, dtype=np.float64)
        n = self._t.shape[0]
        self._acc = np.asarray(acc_b_mps2, dtype=np.float64)
        self._gyr = np.asarray(gyr_b_radps, dtype=np.float64)
        if self._acc.shape != (n, 3) or self._gyr.shape != (n, 3):
            shapes = f"{self._t.shape}, {self._acc.shape}, {self._gyr.shape}"
            raise ValueError(f"need t_s (n,), acc (n, 3), gyr (n, 3); got {shapes}")
        if imu_acc_b_mps2 is None or imu_gyr_b_radps is None:
            imu_acc_b_mps2 = np.repeat(self._acc[:, None, :], 4, axis=1)
            imu_gyr_b_radps = np.repeat(self._gyr[:, None, :], 4, axis=1)
        imu_acc = np.asarray(imu_acc_b_mps2, dtype=np.float64)
        if imu_acc.ndim != 3 or imu_acc.shape[0] != n or imu_acc.shape[2] != 3:
            raise ValueError(f"per-IMU arrays must be (n, k, 3) with n = {n}; got {imu_acc.shape}")
        self._registers = raw_imu.si_to_registers(imu_acc, np.asarray(imu_gyr_b_radps, dtype=np.float64))
        if len(mcu_id) != p.MCU_ID_LEN:
            raise ValueError(f"mcu_id must be {p.MCU_ID_LEN} bytes")
        if not speed > 0:
            raise ValueError(f"speed must be > 0 (math.inf for as fast as possible), got {speed}")
        self.n_imus = int(imu_acc.shape[1])
        if temp_c is None:
            self._temp_raw = np.full(n, 1000, dtype=np.int16)
        else:
            if np.shape(temp_c) != (n,):
                raise ValueError(f"temp_c must be (n,) with n = {n}; got {np.shape(temp_c)}")
            self._temp_raw = raw_imu.temperature_registers(np.asarray(temp_c, dtype=np.float64))
        self._ins, self._steps, self._tof, self._baro = ins, steps, tof, baro
        self.command_set = command_set
        self.speed = speed
        self._tick0 = tick0
        self._resend_s = resend_interval_s
        self._mcu_id = mcu_id
        self._parser = p.CommandParser(command_set)
        self._next_number = first_packet_number & 0xFFFF

        self._outputs: dict[str, _Output] = {}
        self._ins_states: dict[int, int] = {}
        self._processing = True
        self._ins_running = False
        self._lossless = False
        self._started = False
        self._wall0 = 0.0
        self._dev_now = float(self._t[0]) if n else 0.0
        self._dev_now_at_start = self._dev_now
        self._sent_until: dict[str, float] = {}  # per output, the device time of its latest item taken
        self._outputs_ever = False
        self._step_base = 0
        self._queue: deque[tuple[int | None, bytes]] = deque()
        self._queue_bytes = 0
        self._head_sent_at: float | None = None

        self.out: deque[tuple[bytes, int]] = deque()
        """Bytes to write and the number of data packets in each item; the transport pops from the left."""
        self.commands: list[p.Command] = []
        """Valid host commands received, in order (host ACKs included)."""
        self.resends = 0
        """Lossless packets sent again because their ACK had not come."""
        self.queue_overflows = 0
        """Lossless packets dropped because the queue was full."""
        self.acked_numbers: list[int] = []
        """Package numbers removed from the lossless queue by a matching host ACK."""

    # --- transport-facing ----------------------------------------------------------------------

    def receive(self, data: bytes, now: float) -> None:
        """Parse host bytes received at wall time ``now`` and execute the commands."""
        for cmd in self._parser.feed(data, now):
            self.commands.append(cmd)
            self._execute(cmd, now)

    def produce(self, now: float) -> None:
        """Queue what is due at wall time ``now`` (everything up to a chunk at infinite speed)."""
        if self._processing and self._outputs:
            if self._lossless:
                self._produce_lossless(now)
            elif not (math.isinf(self.speed) and len(self.out) >= 2):
                self._emit(self._collect(self._limit(now), None), now)
        self._service_queue(now)

    def next_wakeup(self, now: float) -> float | None:
        """Wall time at which :meth:`produce` has something new to do (None: only on host input)."""
        wake: list[float] = []
        if self._queue:
            head_number = self._queue[0][0]
            if head_number is None or self._head_sent_at is None:
                wake.append(now)
            else:
                wake.append(self._head_sent_at + self._resend_s)
        if self._processing and not math.isinf(self.speed):
            room = not self._lossless or self._room() > 0
            for out in self._outputs.values():
                if out.remaining() and room:
                    wake.append(self._wall0 + (out.next_time() - self._dev_now_at_start) / self.speed)
        return min(wake) if wake else None

    @property
    def exhausted(self) -> bool:
        """True once something was started and no active output has anything left to send."""
        return self._started and not self._queue and not any(o.remaining() for o in self._outputs.values())

    @property
    def streaming(self) -> bool:
        """True while some output is active and processing is on."""
        return self._processing and any(o.remaining() for o in self._outputs.values())

    # --- time ------------------------------------------------------------------------------------

    def _dev_time(self, now: float) -> float:
        if math.isinf(self.speed):
            return self._dev_now
        return self._dev_now_at_start + (now - self._wall0) * self.speed

    def _start_clock(self, now: float) -> None:
        if not self._started:
            self._started = True
            self._wall0 = now
            self._dev_now_at_start = self._dev_now

    def _ticks_at(self, t: F64) -> NDArray[np.int64]:
        rel = np.rint((np.asarray(t, dtype=np.float64) - self._t[0]) * TICK_HZ).astype(np.int64)
        return (rel + self._tick0) % TICK_WRAP

    def _limit(self, now: float) -> float:
        """Device time up to which items are due."""
        if not math.isinf(self.speed):
            return self._dev_time(now)
        ends = [
            float(o.times[min(o.cursor + (MAX_CHUNK_PACKETS - 1) * o.step, o.times.shape[0] - 1)])
            for o in self._outputs.values()
            if o.remaining()
        ]
        return min(ends) if ends else -math.inf

    # --- output generation -----------------------------------------------------------------------

    def _add_output(
        self,
        key: str,
        times: F64,
        encode: Callable[[NDArray[np.int64]], NDArray[np.uint8]],
        *,
        now: float,
        step: int = 1,
        once: bool = False,
    ) -> None:
        self._start_clock(now)
        t_now = self._dev_time(now)
        if (math.isinf(self.speed) and self._outputs_ever) or t_now <= self._sent_until.get(key, -math.inf):
            # an output (re)started where it just sent items begins after them: a start command sent
            # again while streaming outputs no sample twice
            cursor = int(np.searchsorted(times, t_now, side="right"))
        else:
            cursor = int(np.searchsorted(times, t_now, side="left"))
        if once:
            cursor = max(0, min(cursor, times.shape[0] - 1))
        self._outputs[key] = _Output(times, encode, step=step, cursor=cursor, once=once)
        self._outputs_ever = True

    def _collect(self, t_limit: float, max_packets: int | None) -> list[tuple[F64, NDArray[np.uint8]]]:
        """Take the items due by ``t_limit`` from every output: [(times (m,), payload rows (m, L))]."""
        taken: list[tuple[F64, NDArray[np.uint8]]] = []
        for key in list(self._outputs):
            o = self._outputs[key]
            if not o.remaining():
                continue
            stop = int(np.searchsorted(o.times, t_limit, side="right"))
            idx = np.arange(o.cursor, stop, o.step, dtype=np.int64)
            if o.once:
                idx = idx[:1] if idx.size else np.asarray([o.cursor], dtype=np.int64)
            if max_packets is not None:
                idx = idx[:max_packets]
            if idx.size == 0:
                continue
            o.cursor = int(idx[-1]) + o.step
            self._sent_until[key] = float(o.times[idx[-1]])
            if o.once:
                del self._outputs[key]
            taken.append((o.times[idx], o.encode(idx)))
        return taken

    def _emit(self, taken: list[tuple[F64, NDArray[np.uint8]]], now: float) -> None:
        """Number, frame and queue the taken payloads in time order."""
        if not taken:
            return
        total = sum(t.shape[0] for t, _ in taken)
        self._dev_now = max(self._dev_now, *(float(t[-1]) for t, _ in taken))
        first = self._next_number
        self._next_number = (first + total) & 0xFFFF
        if len(taken) == 1 and not self._lossless:
            rows = taken[0][1]
            frames = frame_payload_rows(np.arange(first, first + total), rows)
            self.out.append((frames.tobytes(), total))
            return
        times = np.concatenate([t for t, _ in taken])
        order = np.argsort(times, kind="stable")
        numbers = np.empty(total, dtype=np.int64)
        numbers[order] = np.arange(first, first + total)
        packets: list[bytes] = [b""] * total
        k = 0
        for t, rows in taken:
            m = t.shape[0]
            frames = frame_payload_rows(numbers[k : k + m], rows)
            for j in range(m):
                packets[k + j] = frames[j].tobytes()
            k += m
        in_order = [packets[i] for i in order]
        if self._lossless:
            for i, pkt in zip(order, in_order, strict=True):
                self._enqueue(int(numbers[i]) & 0xFFFF, pkt)
        else:
            self.out.append((b"".join(in_order), total))

    def _produce_lossless(self, now: float) -> None:
        if math.isinf(self.speed):
            while self._room() > 0 and any(o.remaining() for o in self._outputs.values()):
                t_next = min(o.next_time() for o in self._outputs.values() if o.remaining())
                taken = self._collect(t_next, 1)
                if not taken:
                    break
                self._emit(taken, now)
        else:
            self._emit(self._collect(self._dev_time(now), None), now)

    def _room(self) -> int:
        return min(QUEUE_MAX_ENTRIES - len(self._queue), (QUEUE_MAX_BYTES - self._queue_bytes) // 64)

    def _enqueue(self, number: int | None, packet: bytes) -> None:
        if number is not None and (
            len(self._queue) >= QUEUE_MAX_ENTRIES or self._queue_bytes + len(packet) > QUEUE_MAX_BYTES
        ):
            self.queue_overflows += 1
            return
        self._queue.append((number, packet))
        self._queue_bytes += len(packet)

    def _service_queue(self, now: float) -> None:
        """Send the lossless queue's head: command ACKs once, data until ACKed (resent periodically)."""
        q = self._queue
        while q and q[0][0] is None:
            pkt = q.popleft()[1]
            self._queue_bytes -= len(pkt)
            self.out.append((pkt, 0))
        if not q:
            return
        if self._head_sent_at is None:
            self.out.append((q[0][1], 1))
            self._head_sent_at = now
        elif now - self._head_sent_at >= self._resend_s:
            self.out.append((q[0][1], 1))
            self._head_sent_at = now
            self.resends += 1

    def _host_ack(self, number: int) -> None:
        q = self._queue
        if q and q[0][0] == number:  # only the oldest, only its exact number
            self._queue_bytes -= len(q.popleft()[1])
            self._head_sent_at = None
            self.acked_numbers.append(number)

    def _send_packet(self, payload: bytes) -> None:
        """A single packet outside the periodic outputs (the MCU id)."""
        number = self._next_number
        self._next_number = (number + 1) & 0xFFFF
        pkt = p.data_packet(number, payload)
        if self._lossless or self._queue:
            self._enqueue(number, pkt)
        else:
            self.out.append((pkt, 1))

    # --- encoders ---------------------------------------------------------------------------------

    def _encode_normal(self, idx: NDArray[np.int64]) -> NDArray[np.uint8]:
        rec = np.empty(idx.size, dtype=PAYLOAD_DTYPE)
        rec["ts"] = self._ticks_at(self._t[idx])
        rec["acc"] = self._acc[idx]
        rec["gyr"] = self._gyr[idx]
        return rec.view(np.uint8).reshape(idx.size, PAYLOAD_DTYPE.itemsize)

    def _raw_encoder(self, layout: raw_imu.RawImuLayout) -> Callable[[NDArray[np.int64]], NDArray[np.uint8]]:
        cols = np.asarray(layout.imu_ids, dtype=np.int64)

        def encode(idx: NDArray[np.int64]) -> NDArray[np.uint8]:
            regs = self._registers[idx][:, cols, :]
            temp = np.repeat(self._temp_raw[idx][:, None], cols.size, axis=1) if layout.temperature else None
            return raw_imu.encode_payloads(layout, self._ticks_at(self._t[idx]), regs, temp, None)

        return encode

    def _ins_encoder(self, layout: ins_states.InsLayout) -> Callable[[NDArray[np.int64]], NDArray[np.uint8]]:
        truth = self._ins

        def encode(idx: NDArray[np.int64]) -> NDArray[np.uint8]:
            if truth is None:
                return ins_states.encode_payloads(layout, ticks=self._ticks_at(self._t[idx]))
            return ins_states.encode_payloads(
                layout,
                ticks=self._ticks_at(self._t[idx]),
                interrupt_counter=idx,
                pos_n_m=truth.pos_n_m[idx],
                vel_n_mps=truth.vel_n_mps[idx],
                quat_nb_wxyz=truth.quat_nb_wxyz[idx],
                cov_9x9=None if truth.cov_9x9 is None else truth.cov_9x9[idx],
            )

        return encode

    def _encode_steps(self, idx: NDArray[np.int64]) -> NDArray[np.uint8]:
        s = self._steps
        assert s is not None
        counter = idx - self._step_base + 1
        return stepwise.encode_payloads(s.dx_m[idx], s.dheading_rad[idx], s.cov_4x4[idx], counter)

    def _encode_tof(self, idx: NDArray[np.int64]) -> NDArray[np.uint8]:
        s = self._tof
        assert s is not None
        return extensions.encode_tof(self._ticks_at(s.t_s[idx]), s.sensor[idx], s.range_m[idx], s.status[idx])

    def _encode_baro(self, idx: NDArray[np.int64]) -> NDArray[np.uint8]:
        s = self._baro
        assert s is not None
        return extensions.encode_baro(self._ticks_at(s.t_s[idx]), s.pressure_pa[idx], s.temperature_c[idx])

    # --- commands ---------------------------------------------------------------------------------

    def _ack(self, cmd_id: int) -> None:
        ack = p.device_ack(cmd_id)
        if self._queue:
            self._enqueue(None, ack)  # behind unACKed data (protocol-openshoe.md 3.1)
        else:
            self.out.append((ack, 0))

    def _outputs_off(self) -> None:
        self._outputs.clear()
        self._ins_states.clear()
        self._queue.clear()
        self._queue_bytes = 0
        self._head_sent_at = None
        self.out = deque(item for item in self.out if item[1] == 0)  # ACKs already queued still go out

    def _execute(self, cmd: p.Command, now: float) -> None:
        cid = cmd.cmd_id
        if cid == p.CMD_ACK:
            self._host_ack(int.from_bytes(cmd.payload, "big"))
            return
        if self.command_set is p.CommandSet.V2014:
            self._execute_2014(cid, now)
            return
        pl = cmd.payload
        if cid in (p.CMD_NORMAL_IMU, p.CMD_NORMAL_IMU_WITH_BIAS_EST):
            self._processing = True
            self._set_lossless(pl[0])
            self._periodic("normal", pl[0], self._encode_normal, now)
        elif cid == p.CMD_OUTPUT_IMU_RD:
            mask = int.from_bytes(pl[:4], "big") & ((1 << self.n_imus) - 1)
            self._set_lossless(pl[4])
            layout = raw_imu.RawImuLayout.from_command(mask, pl[4]) if mask else None
            if layout is None or not pl[4] & p.MODE_INERTIAL:
                self._outputs.pop("raw", None)
            else:
                self._periodic("raw", pl[4], self._raw_encoder(layout), now)
        elif cid == p.CMD_OUTPUT_STATE:
            self._output_states([pl[0]], pl[1], now)
        elif cid == p.CMD_OUTPUT_MULTIPLE_STATES:
            self._output_states([s for s in pl[:8] if s], pl[8], now)
        elif cid == p.CMD_OUTPUT_ALL_OFF:
            self._outputs_off()
        elif cid == p.CMD_ALL_PROC_OFF:
            self._processing = False
            self._ins_running = False
        elif cid == p.CMD_RESET_ZUPT_AIDED_INS:
            self._outputs_off()
            self._processing = True
            self._ins_running = True
        elif cid == p.CMD_STEPWISE_DEAD_RECKONING:
            self._start_swdr(now)
        elif cid in (p.CMD_RUN_PROC, p.CMD_RUN_MULT_PROC, p.CMD_MIMU_FRONTEND):
            self._processing = True
        elif cid == p.CMD_MCU_ID:
            self._ack(cid)
            self._send_packet(self._mcu_id)
            return
        self._ack(cid)

    def _execute_2014(self, cid: int, now: float) -> None:
        if cid == p.CMD_2014_STEPWISE_DEAD_RECKONING:
            self._start_swdr(now)
        elif cid == p.CMD_2014_OUTPUT_ALL_OFF:
            self._outputs_off()
        elif cid == p.CMD_2014_PROCESSING_OFF:
            self._processing = False
        elif cid == p.CMD_MCU_ID:
            self._ack(cid)
            self._send_packet(self._mcu_id)
            return
        self._ack(cid)

    def _start_swdr(self, now: float) -> None:
        self._outputs_off()
        self._processing = True
        self._lossless = True
        if self._steps is not None and len(self._steps):
            self._add_output("steps", self._steps.t_s, self._encode_steps, now=now)
            self._step_base = self._outputs["steps"].cursor  # the step counter restarts at 1

    def _set_lossless(self, mode: int) -> None:
        self._lossless = bool(mode & p.MODE_LOSSLESS)  # per interface, set by every output command

    def _periodic(
        self, key: str, mode: int, encode: Callable[[NDArray[np.int64]], NDArray[np.uint8]], now: float
    ) -> None:
        log2 = p.rate_divider_log2_from_mode(mode, raw=key == "raw")
        if log2 is None:
            self._outputs.pop(key, None)
            return
        self._add_output(key, self._t, encode, now=now, step=1 << log2, once=bool(mode & p.MODE_PULL))

    def _output_states(self, state_ids: list[int], mode: int, now: float) -> None:
        self._set_lossless(mode)
        on = p.rate_divider_log2_from_mode(mode) is not None
        for sid in state_ids:
            if sid == extensions.STATE_TOF and self._tof is not None:
                self._event("tof", self._tof.t_s, self._encode_tof, on, now)
            elif sid == extensions.STATE_BARO and self._baro is not None:
                self._event("baro", self._baro.t_s, self._encode_baro, on, now)
            elif sid == p.STATE_MCU_ID and on:
                self._send_packet(self._mcu_id)
            elif sid in _INS_STATE_SET:
                if on:
                    self._ins_states[sid] = mode
                else:
                    self._ins_states.pop(sid, None)
        ins_ids = tuple(self._ins_states)
        if ins_ids and (self._ins_running or set(ins_ids) <= {p.STATE_IMU_TS, p.STATE_INTERRUPT_COUNTER}):
            layout = ins_states.InsLayout(ins_ids)
            self._periodic("ins", mode, self._ins_encoder(layout), now)
        elif not ins_ids:
            self._outputs.pop("ins", None)

    def _event(
        self,
        key: str,
        times: F64,
        encode: Callable[[NDArray[np.int64]], NDArray[np.uint8]],
        on: bool,
        now: float,
    ) -> None:
        if on:
            self._add_output(key, times, encode, now=now)
        else:
            self._outputs.pop(key, None)
