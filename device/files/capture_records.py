"""The records of a capture file, read so that one damaged stretch costs only itself.

An MCAP file is a sequence of records ``opcode (1 byte) | length (8 bytes, little-endian) | body``.
A capture's data are zstd chunks, each with the CRC-32 of its uncompressed records. One flipped bit
inside a chunk fails that chunk's CRC (or its decompression); one in a record's length makes every
later record boundary wrong. The ``mcap`` package's stream reader stops at either, so everything
after the first bad bit used to be lost even though every later chunk was intact.

:func:`capture_records` reads the records itself and, at a record that does not decode, scans
forward for the next chunk record and resumes there. A candidate at offset ``q`` is taken only if its
fixed fields agree with each other and with the file (opcode 0x06; a body length ``L`` that fits in
the file; a compression name of ``""``, ``lz4`` or ``zstd``; a compressed length equal to
``L - 40 - len(compression)``) and its records then decompress and pass the chunk CRC, so a false
start inside compressed data is as unlikely as a CRC-32 collision. Each skipped stretch is kept as a
:class:`Gap` (file offsets); a record running past the end of the file with no chunk after it is a
file cut short (a killed writer, a full disk), not a gap.

A record whose opcode is not a chunk's but whose fields and CRC are a chunk's is a chunk with a damaged
opcode byte: it is read whole, and its offset kept in ``RecordState.repaired``.

Metadata records are returned as :class:`RawMetadata`: their strings decoded with
``surrogateescape`` (a flipped high bit is kept, not an exception) and their body bytes, which the
header checksum (``footnav.device.files.capture_header``) covers.

The reading stops at the ``DataEnd`` record: the summary after it (indexes, statistics) is not
needed to read the data; ``summary_crc_ok`` checks it where it is used.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from io import BytesIO
from typing import IO, Any, Final

from footnav.device.files.capture_schema import MCAP_MAGIC
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Header, Message, Schema
from mcap.stream_reader import get_chunk_data_stream

RECORD_SIZE_LIMIT: Final = 1 << 26
"""No record footnav writes comes near this (chunks close at 256 KiB); a larger length is corruption."""
SCAN_BLOCK: Final = 1 << 20
"""Bytes read at a time while looking for the next chunk after a damaged record."""
_CHUNK_FIXED: Final = 8 + 8 + 8 + 4 + 4 + 8
"""A chunk body's fixed fields: start and end time, uncompressed size, CRC, compression name length,
compressed length (bytes)."""
_COMPRESSIONS: Final = (b"", b"lz4", b"zstd")
_HEAD: Final = 9 + _CHUNK_FIXED + 4
"""Bytes that show whether a chunk record can start somewhere (its header, compression name included)."""


@dataclass(frozen=True, slots=True)
class Gap:
    """A stretch of a capture skipped because it did not decode.

    Attributes
    ----------
    start
        file offset of the first record that failed.
    end
        file offset where reading resumed (the next intact chunk), or the file size.
    """

    start: int
    end: int


@dataclass(frozen=True, slots=True)
class RawMetadata:
    """A ``Metadata`` record as stored.

    Attributes
    ----------
    name
        the record's name (``footnav.session``, ``footnav.unit``).
    metadata
        its keys and values in file order (strings; undecodable bytes kept as surrogates).
    body
        the record's body bytes (what the header checksum covers, but for its own entry).
    """

    name: str
    metadata: dict[str, str]
    body: bytes = field(repr=False)


@dataclass(slots=True)
class RecordState:
    """What :func:`capture_records` met (filled in as it goes)."""

    gaps: list[Gap] = field(default_factory=list)
    truncated: bool = False
    """The file ended inside a record, with no intact chunk after it."""
    bytes_read: int = 0
    size: int = 0
    repaired: list[int] = field(default_factory=list)
    """File offsets of chunks read whole although their opcode byte was damaged (nothing lost)."""

    @property
    def corrupt_at(self) -> int | None:
        """File offset of the first damaged stretch, or None."""
        return self.gaps[0].start if self.gaps else None


def _string(stream: BytesIO) -> str:
    (n,) = struct.unpack("<I", _exact(stream, 4))
    return _exact(stream, n).decode("utf-8", "surrogateescape")


def _exact(stream: BytesIO, n: int) -> bytes:
    data = stream.read(n)
    if len(data) != n:
        raise ValueError("record ends inside a field")
    return data


def parse_metadata(body: bytes) -> RawMetadata:
    """A ``Metadata`` record's body, strings kept even where a bit made them invalid UTF-8.

    Raises
    ------
    ValueError
        a length inside the record does not fit it.
    """
    stream = BytesIO(body)
    name = _string(stream)
    (size,) = struct.unpack("<I", _exact(stream, 4))
    end = stream.tell() + size
    if end != len(body):
        raise ValueError("metadata map length does not match the record")
    entries: dict[str, str] = {}
    while stream.tell() < end:
        key = _string(stream)
        entries[key] = _string(stream)
    return RawMetadata(name, entries, body)


def _decode(opcode: int, body: bytes) -> list[Any]:
    """The records one top-level record stands for (a chunk: the records inside, CRC checked)."""
    stream = ReadDataStream(BytesIO(body))
    if opcode == Opcode.CHUNK:
        chunk = Chunk.read(stream)
        if stream.count != len(body):
            raise ValueError("chunk fields do not fill the record")
        return chunk_contents(chunk)
    if opcode == Opcode.METADATA:
        try:
            return [parse_metadata(body)]
        except (ValueError, struct.error):  # a length inside it is damaged: its checksum may locate the bit
            return [RawMetadata("", {}, body)]
    readers: dict[int, Any] = {Opcode.HEADER: Header.read, Opcode.CHANNEL: Channel.read, Opcode.SCHEMA: Schema.read}
    if opcode == Opcode.MESSAGE:
        return [Message.read(stream, len(body))]
    if opcode in readers:
        return [readers[opcode](stream)]
    return []  # indexes, attachments, unknown records: nothing a replay needs


_RECORD_HEAD: Final = struct.Struct("<BQ")
_MESSAGE_HEAD: Final = struct.Struct("<HIQQ")
"""A message record's fixed fields: channel id, sequence, log time, publish time."""


def chunk_contents(chunk: Chunk) -> list[Any]:
    """The channels, schemas and messages of a chunk, in order, its CRC checked.

    As ``mcap.stream_reader.breakup_chunk``, with each message's fixed fields read by one
    ``struct.unpack_from`` on the decompressed bytes instead of a field at a time from a stream (a
    capture holds a message per read: tens of thousands a minute).

    Raises
    ------
    ValueError
        a record runs past the end of the chunk or a message is shorter than its fixed fields (also
        the decompressor's and the CRC check's exceptions).
    """
    stream, size = get_chunk_data_stream(chunk, validate_crc=True)
    data = stream.read(size)
    out: list[Any] = []
    p = 0
    while p < size:
        opcode, length = _RECORD_HEAD.unpack_from(data, p)
        p += 9
        end = p + length
        if end > size:
            raise ValueError("record runs past the end of its chunk")
        if opcode == Opcode.MESSAGE:
            if length < _MESSAGE_HEAD.size:
                raise ValueError("message record shorter than its fixed fields")
            channel_id, sequence, log_time, publish_time = _MESSAGE_HEAD.unpack_from(data, p)
            out.append(Message(channel_id, log_time, data[p + _MESSAGE_HEAD.size : end], publish_time, sequence))
        elif opcode == Opcode.CHANNEL:
            out.append(Channel.read(ReadDataStream(BytesIO(data[p:end]))))
        elif opcode == Opcode.SCHEMA:
            out.append(Schema.read(ReadDataStream(BytesIO(data[p:end]))))
        p = end
    return out


def chunk_candidate(head: bytes, at: int, size: int) -> bool:
    """Whether the bytes ``head`` (:data:`_HEAD` of them, from file offset ``at``) can start a chunk record of
    a file of ``size`` bytes (the fixed fields agree; the CRC is checked when it is decoded)."""
    if len(head) < 9 + _CHUNK_FIXED or head[0] != Opcode.CHUNK:
        return False
    (length,) = struct.unpack_from("<Q", head, 1)
    if not _CHUNK_FIXED <= length <= RECORD_SIZE_LIMIT or at + 9 + length > size:
        return False
    start_ns, end_ns, usize = struct.unpack_from("<QQQ", head, 9)
    (name_len,) = struct.unpack_from("<I", head, 9 + 28)
    if end_ns < start_ns or usize > RECORD_SIZE_LIMIT or name_len > 4 or len(head) < 9 + _CHUNK_FIXED + name_len:
        return False
    name = head[9 + 32 : 9 + 32 + name_len]
    (data_len,) = struct.unpack_from("<Q", head, 9 + 32 + name_len)
    return name in _COMPRESSIONS and data_len == length - _CHUNK_FIXED - name_len


def next_chunk(f: IO[bytes], start: int, size: int) -> int | None:
    """File offset of the first chunk candidate at or after ``start`` (see :func:`chunk_candidate`)."""
    pos = start
    while pos < size:
        f.seek(pos)
        block = f.read(SCAN_BLOCK + _HEAD)
        i = block.find(bytes((Opcode.CHUNK,)))
        while 0 <= i < min(len(block), SCAN_BLOCK):
            head = block[i : i + _HEAD]
            if chunk_candidate(head, pos + i, size):
                return pos + i
            i = block.find(bytes((Opcode.CHUNK,)), i + 1)
        pos += SCAN_BLOCK
    return None


def _data_end_after(f: IO[bytes], pos: int, size: int) -> int | None:
    """Offset of the ``DataEnd`` record right after the damaged record at ``pos`` when its length
    field is intact (the last chunk of a cleanly closed file), else None."""
    f.seek(pos + 1)
    raw = f.read(8)
    if len(raw) < 8:
        return None
    end = pos + 9 + struct.unpack("<Q", raw)[0]
    if end + 13 > size:
        return None
    f.seek(end)
    return end if f.read(9) == struct.pack("<BQ", Opcode.DATA_END, 4) else None


def _read_record(f: IO[bytes], pos: int, size: int) -> tuple[int, bytes] | None:
    """The opcode and body of the record at ``pos``; None where it runs past the end of the file.

    Raises
    ------
    ValueError
        its length is beyond any record footnav writes.
    """
    f.seek(pos)
    head = f.read(9)
    if len(head) < 9:
        return None
    opcode, length = struct.unpack("<BQ", head)
    if length > RECORD_SIZE_LIMIT:
        raise ValueError(f"record length {length}")
    if pos + 9 + length > size:
        return None
    return opcode, f.read(length)


def _misnamed_chunk(body: bytes, at: int, size: int) -> list[Any] | None:
    """The contents of the record at ``at`` when it is a chunk whose opcode byte alone is damaged (its fixed
    fields agree, as :func:`chunk_candidate` checks, and its records pass the chunk CRC); else None."""
    if not chunk_candidate(struct.pack("<BQ", Opcode.CHUNK, len(body)) + body[: _HEAD - 9], at, size):
        return None
    try:
        return _decode(Opcode.CHUNK, body)
    except Exception:  # not a chunk after all: the record is read as what its opcode says
        return None


def capture_records(f: IO[bytes], state: RecordState, *, strict: Callable[[], bool] = lambda: False) -> Iterator[Any]:
    """The records of the open MCAP file ``f`` (magic included) up to its ``DataEnd``: MCAP records,
    chunks' contents in order, :class:`RawMetadata` for metadata.

    Each damaged stretch is skipped to the next intact chunk and appended to ``state.gaps`` before
    the first record after it is yielded. ``state.bytes_read`` is the end of the last record read.

    Parameters
    ----------
    strict
        True while a damaged record must raise instead of being skipped (the caller still needs the
        file's header records).

    Raises
    ------
    ValueError
        ``strict()`` and a record did not decode (the decoder's exception is chained).
    """
    f.seek(0, 2)
    size = state.size = f.tell()
    f.seek(size - 8)
    closed = f.read(8) == MCAP_MAGIC  # a cleanly closed file ends with the magic again
    pos = 8  # after the magic
    gap_start: int | None = None
    while pos < size:
        failed = False
        records: list[Any] | None
        try:
            record = _read_record(f, pos, size)
            chunk = None if record is None or record[0] == Opcode.CHUNK else _misnamed_chunk(record[1], pos, size)
            if record is not None and chunk is not None:
                record, records = (Opcode.CHUNK, record[1]), chunk
                state.repaired.append(pos)
            else:
                records = None if record is None else _decode(*record)
        except Exception as exc:  # a corrupt record makes the MCAP and zstd decoders raise many kinds
            if strict():
                raise ValueError(f"record at byte {pos} does not decode ({type(exc).__name__}: {exc})") from exc
            record, records, failed = None, None, True
        if record is not None and records is not None:
            if gap_start is not None:
                state.gaps.append(Gap(gap_start, pos))
                gap_start = None
            pos += 9 + len(record[1])
            state.bytes_read = pos
            if record[0] == Opcode.DATA_END:
                return
            yield from records
            continue
        resume = next_chunk(f, pos + 1, size)
        if resume is None and failed:
            resume = _data_end_after(f, pos, size)
        if resume is None:
            if not failed and gap_start is None and not closed:
                state.truncated = True  # the file was cut inside this record (a killed writer)
            else:
                state.gaps.append(Gap(pos if gap_start is None else gap_start, size))
            return
        gap_start = pos if gap_start is None else gap_start
        pos = resume


def summary_crc_ok(f: IO[bytes]) -> bool:
    """Whether the summary section of a cleanly closed MCAP file passes the footer's CRC-32 (True
    when the writer recorded none)."""
    f.seek(0, 2)
    size = f.tell()
    footer_at = size - 8 - 29  # Footer: opcode, length, summary start, offsets start, CRC; then magic
    if footer_at < 8:
        return False
    f.seek(footer_at)
    footer = f.read(29)
    opcode, _, summary_start, _, stored = struct.unpack("<BQQQI", footer)
    if opcode != Opcode.FOOTER or not 8 <= summary_start <= footer_at:
        return False
    if stored == 0:
        return True
    f.seek(summary_start)
    return zlib.crc32(f.read(footer_at + 25 - summary_start)) == stored
