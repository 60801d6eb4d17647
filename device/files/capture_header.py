"""The checksum of a capture's header records, and what a damaged header value becomes.

A capture's ``footnav.session`` and ``footnav.unit`` records (MCAP ``Metadata``: the host clock
offset, the output mode, the rate, the navigator settings) lie outside the data chunks, so MCAP's
chunk CRCs do not cover them. :func:`sealed` appends one more entry, ``crc32``: eight hex digits of
the CRC-32 (zlib, IEEE 802.3 polynomial) of the record's body as MCAP stores it up to that entry
(name, map length, every key and value with their length prefixes). CRC-32 detects every error of
up to three bits in a record of this size (Hamming distance 4 up to 2974 bits, 3 up to 91 607
bits; Koopman 2002) and costs microseconds; a cryptographic hash would add nothing against
accidental damage.

:func:`verify` checks a record read from a file. On a mismatch it looks for the one bit whose flip
restores the checksum (every bit of the body tried, about 20 000 CRCs of 2.5 kB for a unit record,
~100 ms, only for a damaged record); where there is one, the damaged field is named down to the key
of the settings JSON that holds the bit (``settings.nav_config.detector.threshold``), and the
other fields, whose bytes are intact, are read as recorded. :func:`apply_policy` then decides per
field: a value the replay can do without or recover is replaced by its default with a warning
naming it; a value that decides how the unit's bytes are decoded is a named error. The damaged
value itself is never used. Records without the entry (captures written before it) are read as
before, checked by the schema alone (``footnav.device.files.capture_schema``).
"""

from __future__ import annotations

import json
import re
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from footnav.device.files.capture_records import RawMetadata, parse_metadata
from footnav.pipeline.errors import InputFormatError

CRC_KEY: Final = "crc32"
_TRAILER: Final = 4 + len(CRC_KEY) + 4 + 8
"""Bytes of the checksum entry: key length, key, value length, 8 hex digits."""
JSON_KEYS: Final = ("settings", "calibration")
"""Unit record values that are JSON text: damage is located down to one of their keys."""
UNIT_DEFAULTS: Final = {"unit": "", "command_set": "", "transport": "", "port": "", "calibration": "{}"}
"""Unit record fields that only describe the unit: a damaged one is replaced by this."""
SETTING_DEFAULTS: Final = {
    "rate_hz": "the default, 1000 Hz (the replay measures the rate from the unit's own clock)",
    "nav_config": "the configuration in force (defaults, config file, command line) instead of the recorded "
    "navigator settings: the estimates may differ from the live session's",
    "model": "no model (it only names the unit)",
    "stance": "the default, inertial (give --stance to choose)",
}
"""Settings a replay can do without, and what it uses instead; any other damaged setting decides how
the unit's bytes are decoded and is an error."""
SESSION_REQUIRED: Final = ("format_version",)
RECOVERED: Final = {"monotonic_to_unix_ns": "taken from the messages' own time stamps (log time - host time)"}


def _string(text: str) -> bytes:
    data = text.encode("utf-8", "surrogateescape")
    return struct.pack("<I", len(data)) + data


def _body(name: str, metadata: dict[str, str]) -> bytes:
    """A metadata record's body as MCAP stores it, its map length counting the checksum entry."""
    entries = b"".join(_string(k) + _string(v) for k, v in metadata.items())
    return _string(name) + struct.pack("<I", len(entries) + _TRAILER) + entries


def sealed(name: str, metadata: dict[str, str]) -> dict[str, str]:
    """``metadata`` with its checksum entry appended (written last, so it covers all before it)."""
    body = _body(name, {k: v for k, v in metadata.items() if k != CRC_KEY})
    return {**metadata, CRC_KEY: f"{zlib.crc32(body):08x}"}


@dataclass(frozen=True, slots=True)
class Damage:
    """A header field holding a bit that fails the record's checksum.

    Attributes
    ----------
    key
        the record's key (``settings``, ``monotonic_to_unix_ns``).
    path
        the field down to the JSON key holding the bit (``settings.rate_hz``).
    reads
        the damaged text around the bit, as read.
    """

    key: str
    path: str
    reads: str


@dataclass(frozen=True, slots=True)
class Verified:
    """A header record after its checksum: the values to use, the damage found, a note."""

    name: str
    metadata: dict[str, str]
    damage: Damage | None = None
    note: str | None = None
    """A mismatch that could not be located, or a damaged checksum entry (values used as read)."""


def _one_bit_apart(a: bytes, b: bytes) -> bool:
    return len(a) == len(b) and sum(bin(x ^ y).count("1") for x, y in zip(a, b, strict=True)) == 1


def _flipped_bit(data: bytes, want: int) -> int | None:
    """The bit (``8 * byte + bit``) of ``data`` whose flip gives CRC-32 ``want``, or None."""
    buf = bytearray(data)
    for i in range(len(buf)):
        for bit in range(8):
            buf[i] ^= 1 << bit
            if zlib.crc32(buf) == want:
                return 8 * i + bit
            buf[i] ^= 1 << bit
    return None


def _spans(body: bytes) -> Iterator[tuple[str, int, int, int]]:
    """(key, start, value start, end) of each entry of a metadata body."""
    pos = 4 + struct.unpack_from("<I", body, 0)[0] + 4
    while pos < len(body):
        start = pos
        (n,) = struct.unpack_from("<I", body, pos)
        key = body[pos + 4 : pos + 4 + n].decode("utf-8", "surrogateescape")
        pos += 4 + n
        (m,) = struct.unpack_from("<I", body, pos)
        yield key, start, pos + 4, pos + 4 + m
        pos += 4 + m


def _nodes(value: Any, path: tuple[str, ...] = ()) -> Iterator[tuple[tuple[str, ...], bool]]:
    """Every node of a JSON value below the top: (path, whether it is a key's name)."""
    if isinstance(value, dict):
        for k, v in value.items():
            yield (*path, k), True
            yield (*path, k), False
            yield from _nodes(v, (*path, k))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield (*path, str(i)), False
            yield from _nodes(v, (*path, str(i)))


def _replaced(value: Any, path: tuple[str, ...], *, key: bool) -> Any:
    """``value`` with the node at ``path`` (or its key's name) replaced by a marker."""
    if not path:
        return "\x00marker"
    head, rest = path[0], path[1:]
    if isinstance(value, dict):
        if key and not rest:
            return {("\x00marker" if k == head else k): v for k, v in value.items()}
        return {k: (_replaced(v, rest, key=key) if k == head else v) for k, v in value.items()}
    return [(_replaced(v, rest, key=key) if str(i) == head else v) for i, v in enumerate(value)]


def json_path_at(text: str, at: int) -> str:
    """The JSON key path (``nav_config.detector.threshold``) of the smallest value or key name of the
    JSON ``text`` (as ``json.dumps`` wrote it) that holds character ``at``; ``""`` for the whole."""
    try:
        value = json.loads(text)
    except (json.JSONDecodeError, RecursionError):
        return ""
    if json.dumps(value) != text:
        return ""
    best, best_len = "", len(text) + 1
    shortest = len(text)
    for path, is_key in _nodes(value):
        other = json.dumps(_replaced(value, path, key=is_key))
        start = next((i for i, (a, b) in enumerate(zip(text, other, strict=False)) if a != b), shortest)
        tail = next((i for i, (a, b) in enumerate(zip(text[::-1], other[::-1], strict=False)) if a != b), shortest)
        end = len(text) - tail
        if start <= at < end and end - start < best_len:
            best, best_len = ".".join(path), end - start
    return best


def _text(data: bytes) -> str:
    return data.decode("utf-8", "replace")


def _locate(body: bytes, bit: int) -> tuple[str, Damage | None]:
    """The corrected record's name and the damaged field that holds ``bit`` of ``body`` (None: the bit
    is in the record's name or size, and every value is intact)."""
    fixed = _fixed(body, bit)
    at = bit // 8
    raw = parse_metadata(fixed)
    for key, start, value_at, end in _spans(fixed):
        if not start <= at < end:
            continue
        if at < value_at:  # its name or a length
            return raw.name, Damage(key, key, _text(body[value_at:end][:32]))
        reads = _text(body[max(value_at, at - 16) : min(end, at + 16)])
        path = key
        if key in JSON_KEYS:
            sub = json_path_at(raw.metadata[key], len(fixed[value_at:at].decode("utf-8", "surrogateescape")))
            path = f"{key}.{sub}" if sub else key
        return raw.name, Damage(key, path, reads)
    return raw.name, None


def verify(raw: RawMetadata) -> Verified:
    """Check a header record against its checksum entry (see the module docstring)."""
    body, values = raw.body, dict(raw.metadata)
    trailer = body[-_TRAILER:] if len(body) > _TRAILER else b""
    layout_ok = trailer[:9] == _string(CRC_KEY) and trailer[9:13] == struct.pack("<I", 8)
    digits = trailer[13:].decode("ascii", "replace")
    if not (layout_ok and re.fullmatch(r"[0-9a-f]{8}", digits)):
        stray = [k for k in values if k == CRC_KEY or _one_bit_apart(k.encode(errors="surrogateescape"), b"crc32")]
        if not stray:
            return Verified(raw.name, values)  # written before header checksums
        for k in stray:
            del values[k]
        return Verified(raw.name, values, note="its checksum entry is itself damaged; its values are checked by range")
    values.pop(CRC_KEY, None)
    protected, stored = body[:-_TRAILER], int(digits, 16)
    actual = zlib.crc32(protected)
    if actual == stored:
        return Verified(raw.name, values)
    if _one_bit_apart(struct.pack("<I", actual), struct.pack("<I", stored)) or _one_bit_apart(
        digits.encode(), f"{actual:08x}".encode()
    ):
        return Verified(raw.name, values, note="its checksum entry is itself damaged (the values are intact)")
    bit = _flipped_bit(protected, stored)
    if bit is None:
        return Verified(raw.name, values, note="it fails its CRC-32 check in more than one bit")
    name, damage = _locate(body, bit)
    intact = parse_metadata(_fixed(body, bit)).metadata
    intact.pop(CRC_KEY, None)
    if damage is None:
        return Verified(name, intact, note="one bit of its name or size fails its CRC-32 check (the values are intact)")
    return Verified(name, intact, damage)


def _fixed(body: bytes, bit: int) -> bytes:
    fixed = bytearray(body)
    fixed[bit // 8] ^= 1 << (bit % 8)
    return bytes(fixed)


def apply_policy(path: Path, record: Verified, label: str) -> tuple[dict[str, str], list[str]]:
    """The values to use of a verified header record, and the warnings to give (see the module
    docstring). ``label`` names the record in messages (``unit 'foot'``, ``session``).

    Raises
    ------
    InputFormatError
        the damaged field decides how the unit's bytes are decoded, or names the unit.
    """
    values = dict(record.metadata)
    where = f"{path}: capture metadata: {label}"
    if record.note is not None:
        return values, [f"{where}: {record.note}"]
    damage = record.damage
    if damage is None:
        return values, []
    said = f"{damage.path} fails the header's CRC-32 check (one bit differs; it reads {damage.reads!r})"
    unit = record.name == "footnav.unit"
    if unit and damage.key in UNIT_DEFAULTS:
        values[damage.key] = UNIT_DEFAULTS[damage.key]
        return values, [f"{where}: {said}: left out (it only describes the unit)"]
    if unit and damage.key == "settings" and damage.path != "settings":
        setting = damage.path.split(".")[1]
        if setting in SETTING_DEFAULTS:
            settings = json.loads(values["settings"])
            settings.pop(setting, None)
            values["settings"] = json.dumps(settings)
            return values, [f"{where}: {said}: using {SETTING_DEFAULTS[setting]}"]
    if not unit and damage.key and damage.key not in SESSION_REQUIRED:
        values.pop(damage.key, None)
        how = RECOVERED.get(damage.key, "left out (it only describes the session)")
        return values, [f"{where}: {said}: {how}"]
    raise InputFormatError(
        f"{where}: {said}; this value decides how the capture is read, so it cannot be replaced by a "
        "default; expected a footnav capture whose header is intact"
    )
