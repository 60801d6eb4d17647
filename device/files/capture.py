"""Capture files: every byte a unit sent and was sent, with host timestamps, in MCAP.

Format (``.mcap``, profile ``footnav``, capture format version :data:`FORMAT_VERSION`):

- an MCAP ``Header`` (profile ``footnav``, library ``footnav <version>``);
- a ``Metadata`` record ``footnav.session`` (footnav version, format version, start time, the host
  clock offset) and one ``footnav.unit`` record per unit (foot, unit kind, firmware command set,
  transport, port, settings and calibration as JSON), written before any data;
- per unit (``<foot>`` is ``foot``, ``left`` or ``right``) three channels without schema:
  ``<foot>/rx`` device -> host bytes, ``<foot>/tx`` host -> device bytes (message encoding
  ``application/octet-stream``; one message per read or write, exactly as the link saw it) and
  ``<foot>/events`` (``application/json``: session start/stop marks, e.g. how many samples the live
  session navigated, so that a replay stops where the live session stopped);
- message ``publish_time`` = the host's ``time.monotonic_ns()`` of the read (what the unit driver
  stamps samples with), ``log_time`` = the same instant on the wall clock (ns since the Unix epoch);
- zstd-compressed chunks, one at least every :data:`FLUSH_PERIOD_S`, each flushed to the OS as it
  closes, and the MCAP summary (index, statistics) at a clean close.

Why MCAP: it is the robotics field's standard log container, append-only by design, readable while it
grows and after a crash up to the last complete chunk (a killed writer leaves no summary; the stream
reader does not need one), chunk CRCs catch corruption, and any MCAP tool (``mcap info``, Foxglove)
can list and export the raw bytes. The ``mcap`` Python package is pure Python.

Reading: :func:`read_capture_info` for the header (checked against the schema of
``footnav.device.files.capture_schema``: a capture is untrusted input), :func:`iter_capture` for the
messages (it stops at the end of a truncated file and reports it);
:class:`footnav.device.links.replay.CaptureReplayLink` plays one unit's device -> host bytes back read
for read, so the same unit driver decodes them.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import IO, Any, Final, Literal

from footnav.device.files.capture_header import apply_policy, sealed, verify
from footnav.device.files.capture_records import (
    Gap,
    RawMetadata,
    capture_records,
    summary_crc_ok,
)
from footnav.device.files.capture_records import RecordState as ReadState
from footnav.device.files.capture_schema import MCAP_MAGIC, check_session, checked_unit_fields
from footnav.pipeline.errors import InputFormatError
from mcap.reader import make_reader
from mcap.records import Channel, Header, Message
from mcap.writer import CompressionType, IndexType, Writer

log = logging.getLogger(__name__)

FORMAT_VERSION: Final = 1
PROFILE: Final = "footnav"
SUFFIX: Final = ".mcap"
FLUSH_PERIOD_S: Final = 1.0
"""Data is on disk (in the OS) at most this long after it was read. Each flush closes a chunk, and the
``mcap`` writer keeps every chunk's index entry (about 300 bytes of small Python objects) until the
file is closed: at 0.1 s that was 36 000 entries an hour, 7.5 MB/h of heap that also pinned the
allocator's arenas (the resident size of an hour's soak crept 16 MB/h); at 1 s it is 3 600."""
CHUNK_BYTES: Final = 1 << 18
"""A chunk also closes at this many uncompressed bytes. Paced in real time a unit sends about 47 kB a
second, so chunks close on :data:`FLUSH_PERIOD_S`; a replay or ``--pace max`` fills one faster, and
at 1 MiB one compressed chunk came near 1 MB: what a crash or a full disk loses at once."""
_BYTES: Final = "application/octet-stream"
_JSON: Final = "application/json"
EXPECTED: Final = "a footnav capture (.mcap, MCAP profile 'footnav')"

Direction = Literal["rx", "tx"]


def footnav_version() -> str:
    """The installed footnav version (``0+unknown`` when running from a bare checkout)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("footnav")
    except PackageNotFoundError:  # pragma: no cover - always installed in development
        return "0+unknown"


@dataclass(frozen=True, slots=True)
class UnitHeader:
    """What a capture records about one unit before its bytes.

    Attributes
    ----------
    foot
        ``foot`` (one unit), ``left`` or ``right``: the channel prefix.
    unit
        kind of unit, e.g. ``OpenShoe/MIMU (normal IMU 0x40)``.
    command_set
        firmware command set spoken, e.g. ``openshoe-2015``.
    transport
        ``serial``, ``ble`` or ``pty (emulator)``.
    port
        port, device path or address.
    settings
        output settings sent to the unit (rate divider, mode), JSON-able.
    calibration
        what is known of the unit's calibration and the noise profile assumed, JSON-able.
    """

    foot: str
    unit: str
    command_set: str
    transport: str
    port: str
    settings: dict[str, Any] = field(default_factory=dict)
    calibration: dict[str, Any] = field(default_factory=dict)

    def to_metadata(self) -> dict[str, str]:
        d = asdict(self)
        return {k: json.dumps(v) if isinstance(v, dict) else str(v) for k, v in d.items()}

    @classmethod
    def checked(cls, path: Path, md: dict[str, str]) -> UnitHeader:
        """From a ``footnav.unit`` record of the capture ``path``, its foot name and settings checked
        against the schema (``footnav.device.files.capture_schema``).

        Raises
        ------
        InputFormatError
            the foot name or a setting does not fit the schema (the message names it).
        """
        fields = checked_unit_fields(path, md)
        return replace(cls.from_metadata(md), **fields)

    @classmethod
    def from_metadata(cls, md: dict[str, str]) -> UnitHeader:
        """From a ``footnav.unit`` record as written, unchecked (a settings field that is not a JSON
        object reads as empty)."""

        def obj(key: str) -> dict[str, Any]:
            try:
                value = json.loads(md.get(key, "{}"))
            except json.JSONDecodeError:
                return {}
            return value if isinstance(value, dict) else {}

        return cls(
            foot=md.get("foot", "foot"),
            unit=md.get("unit", ""),
            command_set=md.get("command_set", ""),
            transport=md.get("transport", ""),
            port=md.get("port", ""),
            settings=obj("settings"),
            calibration=obj("calibration"),
        )


CaptureTap = Callable[[Direction, int, bytes], None]


class CaptureWriter:
    """Write a capture file; safe to call from one thread (the event loop) while a timer flushes.

    Parameters
    ----------
    path
        the ``.mcap`` file to create (parent folders are created).
    session
        extra ``footnav.session`` metadata (e.g. the command line).
    flush_period_s
        longest time between a read and its bytes reaching the OS.

    Raises
    ------
    OSError
        the file cannot be created.
    """

    def __init__(
        self, path: Path, *, session: dict[str, str] | None = None, flush_period_s: float = FLUSH_PERIOD_S
    ) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file: IO[bytes] = open(self.path, "xb")  # noqa: SIM115 - closed in close()
        # no per-chunk message indexes: the writer keeps every chunk's index in memory until the
        # file closes, and a session's length is open (readers scan chunks; the statistics stay)
        self._writer = Writer(
            self._file,
            compression=CompressionType.ZSTD,
            chunk_size=CHUNK_BYTES,
            index_types=IndexType.CHUNK | IndexType.METADATA,
        )
        self._lock = threading.Lock()
        self._channels: dict[tuple[str, str], int] = {}
        self._sequence = 0
        self._dirty = False
        self._closed = False
        self.error: OSError | None = None
        """Why writing stopped (disk full, file too large, device gone), or None."""
        self.messages = 0
        self.bytes_captured = 0
        self.rx_bytes = 0
        """Device -> host bytes captured (0: no unit ever answered)."""
        self.write_seconds = 0.0
        """Time spent in the tap and in flushes (the capture's cost), s."""
        self._mono_to_wall_ns = time.time_ns() - time.monotonic_ns()
        self._writer.start(profile=PROFILE, library=f"footnav {footnav_version()}")
        meta = {
            "footnav_version": footnav_version(),
            "format_version": str(FORMAT_VERSION),
            "started_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "monotonic_to_unix_ns": str(self._mono_to_wall_ns),
        }
        meta.update(session or {})
        self._writer.add_metadata("footnav.session", sealed("footnav.session", meta))
        self._writer.flush()
        self._period = flush_period_s
        self._stop = threading.Event()
        self._flusher = threading.Thread(target=self._flush_loop, name="footnav-capture", daemon=True)
        self._flusher.start()

    def add_unit(self, header: UnitHeader) -> CaptureTap:
        """Declare a unit and return its tap ``tap(direction, host_ns, data)`` for ``OpenShoeUnit``.

        Raises
        ------
        ValueError
            a unit of this foot name was declared already (its bytes would merge into one stream).
        """
        with self._lock:
            if any(foot == header.foot for foot, _ in self._channels):
                raise ValueError(f"two units named {header.foot!r} in one capture: each unit needs its own foot name")
            self._writer.add_metadata("footnav.unit", sealed("footnav.unit", header.to_metadata()))
            for direction in ("rx", "tx"):
                self._channels[(header.foot, direction)] = self._writer.register_channel(
                    f"{header.foot}/{direction}", _BYTES, 0, {"direction": direction, "foot": header.foot}
                )
            self._channels[(header.foot, "events")] = self._writer.register_channel(
                f"{header.foot}/events", _JSON, 0, {"foot": header.foot}
            )
            self._writer.flush()
        foot = header.foot

        def tap(direction: Direction, host_ns: int, data: bytes) -> None:
            if direction == "rx":
                self.rx_bytes += len(data)
            self._add(self._channels[(foot, direction)], host_ns, bytes(data))

        return tap

    def event(self, foot: str, name: str, **fields: Any) -> None:
        """Write a JSON event (``{"event": name, ...}``) on the unit's events channel, now."""
        payload = json.dumps({"event": name, **fields}).encode()
        self._add(self._channels[(foot, "events")], time.monotonic_ns(), payload)

    def _add(self, channel: int, host_ns: int, data: bytes) -> None:
        t0 = time.perf_counter()
        with self._lock:
            if self._closed or self.error is not None:
                return
            self._sequence += 1
            try:
                self._writer.add_message(
                    channel, host_ns + self._mono_to_wall_ns, data, host_ns, sequence=self._sequence
                )
            except OSError as exc:  # the chunk was full and could not be written
                self._fail(exc)
                return
            self._dirty = True
        self.messages += 1
        self.bytes_captured += len(data)
        self.write_seconds += time.perf_counter() - t0

    def flush(self) -> None:
        """Close the current chunk and hand it to the OS (what survives a ``kill -9``)."""
        t0 = time.perf_counter()
        with self._lock:
            if self._closed or not self._dirty or self.error is not None:
                return
            try:
                self._writer.flush()
            except OSError as exc:
                self._fail(exc)
                return
            self._dirty = False
        self.write_seconds += time.perf_counter() - t0

    def _fail(self, exc: OSError) -> None:
        """Stop capturing for good (the lock is held): the file keeps every chunk written before.

        Nothing more is buffered (memory stays bounded); the session goes on without capture.
        """
        self.error = exc
        with contextlib.suppress(OSError):
            self._file.close()
        log.error(
            "capture stopped: %s writing %s; what was written before stays readable "
            "(`footnav replay` reads it up to there); the session goes on without capture",
            exc.strerror or exc,
            self.path,
        )

    def _flush_loop(self) -> None:
        while not self._stop.wait(self._period):
            self.flush()
            if self.error is not None:
                return

    def close(self) -> None:
        """Write the summary (index, statistics) and close the file. Idempotent."""
        self._stop.set()
        if self._flusher.is_alive() and threading.current_thread() is not self._flusher:
            self._flusher.join()
        with self._lock:
            if self._closed:
                return
            self._closed = True
            if self.error is not None:
                return
            try:
                self._writer.finish()
            except OSError as exc:
                self._fail(exc)
            finally:
                self._file.close()

    def __enter__(self) -> CaptureWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# ------------------------------------------------------------------------------------------ reading


@dataclass(frozen=True, slots=True)
class CaptureInfo:
    """The header of a capture file.

    Attributes
    ----------
    path
        the file.
    session
        ``footnav.session`` metadata.
    units
        one header per unit, in the order they were declared.
    warnings
        header values that failed their checksum and were replaced by a default, each named (see
        ``footnav.device.files.capture_header``).
    """

    path: Path
    session: dict[str, str]
    units: tuple[UnitHeader, ...]
    warnings: tuple[str, ...] = ()

    @property
    def feet(self) -> tuple[str, ...]:
        return tuple(u.foot for u in self.units)


@dataclass(frozen=True, slots=True)
class CaptureMessage:
    """One read, write or event of a capture (``host_ns``: ``time.monotonic_ns()`` when it happened)."""

    foot: str
    direction: str  # "rx", "tx" or "events"
    host_ns: int
    data: bytes


def _check_magic(path: Path) -> None:
    try:
        with open(path, "rb") as f:
            head = f.read(len(MCAP_MAGIC))
    except OSError as exc:
        raise InputFormatError(f"cannot read {path}: {exc.strerror or exc}") from exc
    if head != MCAP_MAGIC:
        what = "an empty file" if not head else "not an MCAP file"
        raise InputFormatError(f"{path} is {what}; expected {EXPECTED}")


def _first_data_lost(path: Path, gap: Gap) -> InputFormatError:
    return InputFormatError(
        f"{path} is corrupt: bytes {gap.start} to {gap.end}, before its first message, do not decode (its first "
        "chunk of data, which holds the unit's answer to the start command, fails its CRC check); expected a "
        f"footnav capture whose header and first chunk are intact"
    )


class _Header:
    """The header records of a capture as they are read (see :func:`iter_capture`)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.session: dict[str, str] | None = None
        self.units: list[UnitHeader] = []
        self.warnings: list[str] = []
        self.recover_offset = False

    def add(self, raw: RawMetadata) -> None:
        record = verify(raw)
        if record.name == "footnav.session":
            values, warnings = apply_policy(self.path, record, "session")
            check_session(self.path, values, FORMAT_VERSION)
            self.session = values
            self.recover_offset = "monotonic_to_unix_ns" not in values and any("monotonic" in w for w in warnings)
        elif record.name == "footnav.unit":
            label = f"unit {record.metadata.get('foot', '?')!r}"
            values, warnings = apply_policy(self.path, record, label)
            unit = UnitHeader.checked(self.path, values)
            if unit.foot in (u.foot for u in self.units):
                raise InputFormatError(
                    f"{self.path}: capture metadata: two units are named {unit.foot!r}; expected one foot name per unit"
                )
            self.units.append(unit)
        else:
            return
        self.warnings.extend(warnings)

    def info(self, first: Message | None) -> CaptureInfo:
        if self.session is None:
            raise InputFormatError(f"{self.path} has no footnav.session header; expected {EXPECTED}")
        if self.recover_offset and first is not None:
            self.session["monotonic_to_unix_ns"] = str(first.log_time - first.publish_time)
        return CaptureInfo(self.path, self.session, tuple(self.units), tuple(self.warnings))


def iter_capture(path: Path, state: ReadState | None = None) -> Iterator[CaptureMessage | CaptureInfo]:
    """Every record of a capture in file order: a :class:`CaptureInfo` once the header has been read
    (before the first message), then the messages.

    A damaged stretch of the data is skipped to the next intact chunk and appended to
    ``state.gaps`` (the first message after it follows); the end of a truncated file stops the pass
    quietly and sets ``state.truncated``.

    Raises
    ------
    InputFormatError
        not an MCAP file, an MCAP file from another tool, a header that does not fit the schema
        (``footnav.device.files.capture_schema``) or whose damaged value cannot be replaced
        (``footnav.device.files.capture_header``), two units of one name, or data lost before the
        first message.
    """
    path = Path(path)
    _check_magic(path)
    state = state if state is not None else ReadState()
    header = _Header(path)
    channels: dict[int, tuple[str, str]] = {}
    announced = False
    with open(path, "rb") as f:
        records = capture_records(f, state, strict=lambda: header.session is None)
        while True:
            try:
                rec = next(records)
            except StopIteration:
                break
            except ValueError as exc:
                raise InputFormatError(f"{path} is not readable as MCAP ({exc}); expected {EXPECTED}") from exc
            if isinstance(rec, Header):
                if rec.profile != PROFILE:
                    raise InputFormatError(
                        f"{path} is an MCAP file from another tool (profile {rec.profile!r}, "
                        f"library {rec.library!r}); expected {EXPECTED}"
                    )
            elif isinstance(rec, RawMetadata):
                header.add(rec)
            elif isinstance(rec, Channel):
                foot, _, direction = rec.topic.rpartition("/")
                channels[rec.id] = (foot, direction)
            elif isinstance(rec, Message):
                if not announced:
                    if state.gaps:
                        raise _first_data_lost(path, state.gaps[0])
                    announced = True
                    yield header.info(rec)
                foot, direction = channels.get(rec.channel_id, ("?", "?"))
                yield CaptureMessage(foot, direction, rec.publish_time, bytes(rec.data))
    if not announced:
        if state.gaps:
            raise _first_data_lost(path, state.gaps[0])
        if header.session is None:
            raise InputFormatError(f"{path} ends before its footnav.session header; expected {EXPECTED}")
        yield header.info(None)


def read_capture_info(path: Path) -> CaptureInfo:
    """The header of a capture (reads up to its first message).

    Raises
    ------
    InputFormatError
        see :func:`iter_capture`.
    """
    for item in iter_capture(path):
        if isinstance(item, CaptureInfo):
            return item
    raise AssertionError("unreachable: iter_capture always announces the header")  # pragma: no cover


@dataclass(frozen=True, slots=True)
class CaptureSummary:
    """Counts over a whole capture (one pass)."""

    info: CaptureInfo
    truncated: bool
    first_ns: int | None
    last_ns: int | None
    rx_bytes: dict[str, int]
    events: dict[str, list[dict[str, Any]]]
    rx_sha256: dict[str, str] = field(default_factory=dict)
    """SHA-256 (hex) of each unit's device -> host bytes in capture order."""
    corrupt_at: int | None = None
    """File offset of the first damaged stretch the pass skipped (see ``ReadState``), or None."""
    gaps: tuple[Gap, ...] = ()
    """Every damaged stretch the pass skipped (file offsets); the index of a cleanly closed capture
    finds none (the replay finds them as it reads)."""

    @property
    def duration_s(self) -> float:
        if self.first_ns is None or self.last_ns is None:
            return 0.0
        return (self.last_ns - self.first_ns) / 1e9


def summarize_capture(path: Path, *, full: bool = False) -> CaptureSummary:
    """Time span, data per unit, events and truncation of a capture.

    A cleanly closed capture ends with an MCAP summary (statistics and chunk indexes): its counts
    are read from there and its events from the few chunks that hold them, without reading the
    data. A capture without one (a killed writer, a full disk) or ``full=True`` takes one pass over
    every record, which also gives ``rx_bytes`` and ``rx_sha256`` (in the indexed case ``rx_bytes``
    counts reads, not bytes).
    """
    if not full:
        indexed = _summary_from_index(path)
        if indexed is not None:
            return indexed
    state = ReadState()
    info: CaptureInfo | None = None
    first = last = None
    rx: dict[str, int] = {}
    digests: dict[str, Any] = {}
    events: dict[str, list[dict[str, Any]]] = {}
    for item in iter_capture(path, state):
        if isinstance(item, CaptureInfo):
            info = item
            continue
        if item.direction == "events":
            with contextlib.suppress(json.JSONDecodeError):
                events.setdefault(item.foot, []).append(json.loads(item.data))
            continue
        if item.direction == "rx":
            rx[item.foot] = rx.get(item.foot, 0) + len(item.data)
            digests.setdefault(item.foot, hashlib.sha256()).update(item.data)
            first = item.host_ns if first is None else first
            last = item.host_ns
    assert info is not None
    sha = {foot: d.hexdigest() for foot, d in digests.items()}
    return CaptureSummary(info, state.truncated, first, last, rx, events, sha, state.corrupt_at, tuple(state.gaps))


def _summary_from_index(path: Path) -> CaptureSummary | None:
    """The summary from the file's MCAP summary section, or None if it has none (see above)."""
    info = read_capture_info(path)  # checks magic and profile, reads the metadata
    try:
        with open(path, "rb") as f:
            if not summary_crc_ok(f):  # a damaged index: the counts come from the data instead
                return None
            f.seek(0)
            reader = make_reader(f)
            summary = reader.get_summary()
            if summary is None or summary.statistics is None:
                return None
            stats = summary.statistics
            topics = {cid: ch.topic for cid, ch in summary.channels.items()}
            rx: dict[str, int] = {}
            for cid, count in stats.channel_message_counts.items():
                foot, _, direction = topics.get(cid, "?/?").rpartition("/")
                if direction == "rx":
                    rx[foot] = rx.get(foot, 0) + count
            events: dict[str, list[dict[str, Any]]] = {}
            event_topics = [t for t in topics.values() if t.endswith("/events")]
            for _, channel, message in reader.iter_messages(topics=event_topics, log_time_order=False):
                with contextlib.suppress(json.JSONDecodeError):
                    events.setdefault(channel.topic.rpartition("/")[0], []).append(json.loads(message.data))
    except Exception:  # any doubt about the index: read the whole file instead
        return None
    offset = int(info.session.get("monotonic_to_unix_ns", "0"))
    first, last = stats.message_start_time - offset, stats.message_end_time - offset
    return CaptureSummary(info, False, first, last, rx, events)
