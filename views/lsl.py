"""A session's estimates on Lab Streaming Layer (``--lsl``): for LabRecorder (XDF files), MNE-LSL,
and any pylsl/liblsl client.

Streams (the channels and their units are also in each stream's XML description,
``desc/channels/channel/label|unit|type``, with the frame, the foot and the unit in ``desc``):

- ``footnav <foot> navigation``, one per foot, type ``MoCap``, ``double64``, one sample per
  navigated sample at the unit's rate (nominal rate 0 for a unit's stepwise output), 14 channels:
  ``pos_x pos_y pos_z`` (m) and ``vel_x vel_y vel_z`` (m/s) in the navigation frame (right-handed,
  z up, origin where this foot started: each foot its own, without the side-by-side offset the
  viewer draws two feet with), ``quat_w quat_x quat_y quat_z`` (body to navigation, scalar first),
  ``stance`` (1: the zero-velocity detector declared the foot still, else 0), and ``sigma_x sigma_y
  sigma_z`` (m), the square roots of the diagonal of ``NavBatch.pos_cov_n_m2``.
- ``footnav gait events``, one per session, type ``Markers``, ``string``, irregular rate, 8
  channels ``event foot t_unit_s duration_s length_m x_m y_m z_m`` (empty where it does not apply):
  ``stance_start`` where a step lands (``NavBatch.step_onsets``; duration: the swing before it),
  ``stance_end`` at the first swing sample (duration: the stance it ends), and ``stride`` at the
  footfall that completes a stride (length and duration as in the viewer's stride table,
  :mod:`footnav.views.strides`); x y z is the foot's position at the event, m.

Clock: every sample and event is stamped ``t_unit_s + offset_s``, where ``t_unit_s`` is the unit's
own clock (``NavBatch.t_s``) and ``offset_s = pylsl.local_clock() - t_unit_s`` is taken once, at the
foot's first sample, and kept for the session: intervals between time stamps are the unit's, and the
first sample is stamped with the time it reached the outlet (latency included). Each foot has its own
offset (two units, two clocks). A replay maps the same way and runs at its own pace, so at ``--speed
max`` the time stamps run ahead of ``local_clock()``. ``source_id`` is ``footnav:<identity>:<foot>``,
the identity being the unit's port or ``ble:NAME|ADDRESS`` as given (``footnav.app.feet.lsl_identity``;
``emulator`` in the demo, ``replay:...`` in a replay): the same unit on the same port keeps its id, so
LabRecorder picks a stream up again. The outlets exist before the unit is found, and an id cannot change,
so ``ble:`` alone (the first unit found) gets ``ble:first-found``, whichever unit answers.

pylsl is imported by :func:`open_lsl` only, when ``--lsl`` is given; pushing never blocks (liblsl
queues up to ``max_buffered_s`` of data per consumer and sends it from its own threads).
"""

from __future__ import annotations

import asyncio
import math
import os
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from footnav.pipeline.errors import FootnavError
from footnav.pipeline.gait.events import step_onsets
from footnav.pipeline.nav_types import NavBatch
from footnav.views.strides import StrideTable
from numpy.typing import NDArray

STATE_CHANNELS: tuple[tuple[str, str, str], ...] = (
    ("pos_x", "m", "PositionX"),
    ("pos_y", "m", "PositionY"),
    ("pos_z", "m", "PositionZ"),
    ("vel_x", "m/s", "VelocityX"),
    ("vel_y", "m/s", "VelocityY"),
    ("vel_z", "m/s", "VelocityZ"),
    ("quat_w", "1", "OrientationW"),
    ("quat_x", "1", "OrientationX"),
    ("quat_y", "1", "OrientationY"),
    ("quat_z", "1", "OrientationZ"),
    ("stance", "bool", "Stance"),
    ("sigma_x", "m", "PositionSigmaX"),
    ("sigma_y", "m", "PositionSigmaY"),
    ("sigma_z", "m", "PositionSigmaZ"),
)
"""(label, unit, type) of each channel of a foot's navigation stream, in order."""
EVENT_CHANNELS: tuple[tuple[str, str, str], ...] = (
    ("event", "", "Marker"),
    ("foot", "", "Foot"),
    ("t_unit_s", "s", "UnitTime"),
    ("duration_s", "s", "Duration"),
    ("length_m", "m", "StrideLength"),
    ("x_m", "m", "PositionX"),
    ("y_m", "m", "PositionY"),
    ("z_m", "m", "PositionZ"),
)
"""(label, unit, type) of each channel of the gait event stream; values as text, empty when absent."""
FRAME = "navigation frame: right-handed, z up, origin at this foot's start position"
CHUNK_SAMPLES = 1024
"""A batch is pushed in chunks of at most this many samples (a recording's replay is one batch)."""
MAX_BUFFERED_S = 360
"""liblsl's default: how much data an outlet keeps for a consumer that lags, s."""
WAIT_SLICE_S = 0.2
"""``--lsl-wait`` waits in slices of at most this long, s: Ctrl-C (checked between slices) acts within one."""
CLOSE_LINGER_S = 1.0
"""On close, with consumers connected, the time given to liblsl to send what is queued, s."""
INSTALL_HINT = "pip install 'footnav[lsl]'"
LIBLSL_CONFIGS = ("lsl_api.cfg", "~/lsl_api/lsl_api.cfg", "/etc/lsl_api/lsl_api.cfg")
"""Where liblsl looks for its configuration file (after ``$LSLAPICFG``)."""
QUIET_LIBLSL = "[log]\nlevel = -2\n"
"""liblsl's configuration when the user has none: its defaults, logging errors only."""

Row = tuple[float, int, list[str]]
"""An event: unit time, order among events at the same time, and its channels' text."""


@dataclass(frozen=True)
class LslRequest:
    """What ``--lsl`` asked for.

    Attributes
    ----------
    wait_s
        ``--lsl-wait``: before the first sample, wait up to this long for every stream to have a
        consumer, s (0: do not wait; a consumer that connects later gets the data from then on).
    identity
        the unit identity for ``source_id`` (None: each foot's port).
    """

    wait_s: float = 0.0
    identity: str | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.wait_s) and self.wait_s >= 0):
            raise ValueError(f"LslRequest.wait_s must be a finite time >= 0, s; got {self.wait_s}")


@dataclass(frozen=True)
class LslFoot:
    """One foot's navigation stream: ``foot``; ``identity`` (port, BLE name, ``emulator``); ``unit``
    (the unit's name, for ``desc``); ``rate_hz``, its nominal sample rate (0: irregular)."""

    foot: str
    identity: str
    unit: str
    rate_hz: float


def lsl_feet(
    request: LslRequest | None,
    identities: Mapping[str, str],
    *,
    units: str | Mapping[str, str],
    rates: Mapping[str, float],
) -> list[LslFoot] | None:
    """The feet's streams for ``--lsl`` (None without it): foot -> identity (``request.identity`` if
    set), the unit's name (one for all feet, or per foot) and nominal rate, Hz."""
    if request is None:
        return None
    return [
        LslFoot(
            foot,
            request.identity or identity,
            units if isinstance(units, str) else units[foot],
            rates[foot],
        )
        for foot, identity in identities.items()
    ]


def source_id(identity: str, foot: str) -> str:
    """``footnav:<identity>:<foot>``: the same unit on the same port gets the same id every session."""
    return f"footnav:{identity}:{foot}"


def _fmt(value: float | None, digits: int) -> str:
    return "" if value is None or not np.isfinite(value) else f"{value:.{digits}f}"


class _FootEvents:
    """The gait events of one foot's batches, fed in order (module docstring)."""

    def __init__(self, foot: str) -> None:
        self.foot = foot
        self._table = StrideTable((foot,))
        self._last_stance: bool | None = None
        self._stance_from: float | None = None
        self._swing_from: float | None = None

    def rows(self, nav: NavBatch) -> list[Row]:
        """Events of ``nav`` in time order (its ``step_onsets`` filled, or found from its stance flags)."""
        t, pos = nav.t_s, nav.pos_n_m
        stance = np.asarray(nav.stance, dtype=bool)
        onsets = nav.step_onsets if nav.step_onsets is not None else step_onsets(stance, self._last_stance)
        before = np.empty_like(stance)
        before[0] = stance[0] if self._last_stance is None else self._last_stance
        before[1:] = stance[:-1]
        ends = np.flatnonzero(before & ~stance)
        self._last_stance = bool(stance[-1])
        rows: list[Row] = []
        marks = sorted([(int(k), 0) for k in ends] + [(int(k), 1) for k in onsets])
        for k, kind in marks:
            tk = float(t[k])
            if kind == 0:
                duration = None if self._stance_from is None else tk - self._stance_from
                self._swing_from = tk
                rows.append((tk, 0, self._row("stance_end", tk, duration, None, pos[k])))
            else:
                duration = None if self._swing_from is None else tk - self._swing_from
                self._stance_from = tk
                rows.append((tk, 1, self._row("stance_start", tk, duration, None, pos[k])))
        done = len(self._table.strides(self.foot))
        self._table.update(self.foot, nav)
        for s in self._table.strides(self.foot)[done:]:
            k = min(int(np.searchsorted(t, s.t_s)), len(nav) - 1)
            rows.append((s.t_s, 2, self._row("stride", s.t_s, s.duration_s, s.length_m, pos[k])))
        rows.sort(key=lambda r: (r[0], r[1]))
        return rows

    def _row(
        self, event: str, t_s: float, duration_s: float | None, length_m: float | None, pos: NDArray[np.float64]
    ) -> list[str]:
        return [
            event,
            self.foot,
            _fmt(t_s, 6),
            _fmt(duration_s, 4),
            _fmt(length_m, 4),
            *(_fmt(float(v), 4) for v in pos),
        ]


class LslOutlets:
    """A session's LSL outlets (made by :func:`open_lsl`): a navigation stream per foot, one event stream.

    Parameters
    ----------
    pylsl
        the imported pylsl module.
    feet
        the feet's streams.
    max_buffered_s
        what each outlet keeps for a lagging consumer, s.
    """

    def __init__(self, pylsl: Any, feet: Sequence[LslFoot], *, max_buffered_s: int = MAX_BUFFERED_S) -> None:
        self._lsl = pylsl
        self.state: dict[str, Any] = {}
        for f in feet:
            info = pylsl.StreamInfo(
                f"footnav {f.foot} navigation",
                "MoCap",
                len(STATE_CHANNELS),
                f.rate_hz,
                pylsl.cf_double64,
                source_id(f.identity, f.foot),
            )
            _describe(info, STATE_CHANNELS, {"foot": f.foot, "unit": f.unit, "identity": f.identity, "frame": FRAME})
            self.state[f.foot] = pylsl.StreamOutlet(info, max_buffered=max_buffered_s)
        identity = "+".join(dict.fromkeys(f.identity for f in feet))
        info = pylsl.StreamInfo(
            "footnav gait events",
            "Markers",
            len(EVENT_CHANNELS),
            pylsl.IRREGULAR_RATE,
            pylsl.cf_string,
            source_id(identity, "events"),
        )
        _describe(info, EVENT_CHANNELS, {"feet": " ".join(f.foot for f in feet), "identity": identity, "frame": FRAME})
        self.events: Any = pylsl.StreamOutlet(info, max_buffered=max_buffered_s)
        """The gait event outlet (None once closed)."""
        self.offset_s: dict[str, float] = {}
        """foot -> LSL time minus unit time, s, fixed at the foot's first sample."""
        self.samples: dict[str, int] = dict.fromkeys(self.state, 0)
        self.events_sent = 0
        self._trackers = {foot: _FootEvents(foot) for foot in self.state}

    def put(self, nav: NavBatch, *, foot: str) -> bool:
        """Push a batch of one foot's estimates (and the gait events in it) with mapped time stamps."""
        n = len(nav)
        if n == 0:
            return True
        if foot not in self.offset_s:
            self.offset_s[foot] = float(self._lsl.local_clock()) - float(nav.t_s[0])
        offset = self.offset_s[foot]
        sigma = np.sqrt(np.clip(np.diagonal(nav.pos_cov_n_m2, axis1=1, axis2=2), 0.0, None))
        chunk = np.empty((n, len(STATE_CHANNELS)), dtype=np.float64)
        chunk[:, 0:3] = nav.pos_n_m
        chunk[:, 3:6] = nav.vel_n_mps
        chunk[:, 6:10] = nav.quat_nb_wxyz
        chunk[:, 10] = nav.stance
        chunk[:, 11:14] = sigma
        stamps = nav.t_s + offset
        outlet = self.state[foot]
        for a in range(0, n, CHUNK_SAMPLES):
            outlet.push_chunk(chunk[a : a + CHUNK_SAMPLES], stamps[a : a + CHUNK_SAMPLES].tolist())
        self.samples[foot] += n
        for t_s, _, row in self._trackers[foot].rows(nav):
            self.events.push_sample(row, t_s + offset)
            self.events_sent += 1
        return True

    def sink(self, foot: str) -> Callable[[NavBatch], bool]:
        """A NavSink for one foot."""

        def put(nav: NavBatch) -> bool:
            return self.put(nav, foot=foot)

        return put

    def _outlets(self) -> dict[str, Any]:
        """Stream name -> outlet, every stream of the session."""
        outlets = {f"footnav {foot} navigation": o for foot, o in self.state.items()}
        if self.events is not None:
            outlets["footnav gait events"] = self.events
        return outlets

    def missing_consumers(self) -> list[str]:
        """The names of the streams that have no consumer now."""
        return [name for name, o in self._outlets().items() if not o.have_consumers()]

    def _slices(self, timeout_s: float, slice_s: float, notice: Callable[[str], None]) -> Iterator[tuple[Any, float]]:
        """The waits of :meth:`wait_for_consumers`: (an outlet that has no consumer, how long to wait for it, s),
        each at most ``slice_s``, until every stream has a consumer or ``timeout_s`` has passed.

        Raises
        ------
        ValueError
            ``timeout_s`` is not a finite time >= 0.
        """
        if not (math.isfinite(timeout_s) and timeout_s >= 0):
            raise ValueError(f"the wait for LSL consumers must be a finite time >= 0, s; got {timeout_s}")
        notice(f"LSL: waiting up to {timeout_s:g} s for a consumer of {', '.join(self._outlets())}")
        deadline = time.monotonic() + timeout_s
        while (missing := self.missing_consumers()) and (left := deadline - time.monotonic()) > 0:
            yield self._outlets()[missing[0]], min(slice_s, left)

    def _told(self, timeout_s: float, notice: Callable[[str], None]) -> bool:
        missing = self.missing_consumers()
        if missing:
            notice(f"LSL: no consumer of {', '.join(missing)} after {timeout_s:g} s; streaming anyway")
        return not missing

    def wait_for_consumers(
        self, timeout_s: float, *, notice: Callable[[str], None], slice_s: float = WAIT_SLICE_S
    ) -> bool:
        """Wait up to ``timeout_s`` (finite, s) until every stream has a consumer; False (and a notice) if some
        have none. liblsl's wait is a C call that Ctrl-C cannot break into, so it is made in slices of at
        most ``slice_s``: a KeyboardInterrupt arrives within one slice."""
        for outlet, wait_s in self._slices(timeout_s, slice_s, notice):
            outlet.wait_for_consumers(wait_s)  # returns as soon as a consumer connects
        return self._told(timeout_s, notice)

    async def wait_for_consumers_async(
        self, timeout_s: float, *, notice: Callable[[str], None], slice_s: float = WAIT_SLICE_S
    ) -> bool:
        """:meth:`wait_for_consumers` on the event loop: it polls every ``slice_s`` without blocking the loop,
        and a cancelled task (Ctrl-C in ``asyncio.run``) stops at once, leaving no thread behind."""
        for _, wait_s in self._slices(timeout_s, slice_s, notice):
            await asyncio.sleep(wait_s)
        return self._told(timeout_s, notice)

    def close(self) -> None:
        """Destroy the outlets (consumers see the streams end), after giving queued data time to go out;
        once (later calls do nothing)."""
        outlets = [*self.state.values(), *([] if self.events is None else [self.events])]
        if any(o.have_consumers() for o in outlets):
            time.sleep(CLOSE_LINGER_S)
        self.state.clear()
        self.events = None
        del outlets  # the last references: liblsl destroys each outlet with its Python object

    def summary(self) -> str:
        """One line: what went out."""
        feet = ", ".join(f"{foot} {n}" for foot, n in self.samples.items())
        return f"LSL: samples streamed: {feet}; gait events: {self.events_sent}"


def _describe(info: Any, channels: Sequence[tuple[str, str, str]], fields: dict[str, str]) -> None:
    """Channel labels, units and types, and ``fields``, into a stream's XML description."""
    desc = info.desc()
    for key, value in fields.items():
        desc.append_child_value(key, value)
    desc.append_child("acquisition").append_child_value("manufacturer", "footnav")
    chans = desc.append_child("channels")
    for label, unit, kind in channels:
        ch = chans.append_child("channel")
        ch.append_child_value("label", label)
        ch.append_child_value("unit", unit)
        ch.append_child_value("type", kind)


def import_pylsl() -> Any:
    """The pylsl module (its liblsl loaded).

    Raises
    ------
    FootnavError
        pylsl is not installed or cannot load liblsl (the message says how to install it).
    """
    try:
        import pylsl
    except ImportError:
        raise FootnavError(f"--lsl needs pylsl (Lab Streaming Layer), which is not installed: {INSTALL_HINT}") from None
    except RuntimeError as exc:  # pylsl without a loadable liblsl
        raise FootnavError(f"--lsl: pylsl cannot load liblsl ({exc}); reinstall it: {INSTALL_HINT}") from None
    if not any(Path(p).expanduser().is_file() for p in LIBLSL_CONFIGS) and not os.environ.get("LSLAPICFG"):
        # no configuration of the user's: liblsl's INFO lines would break into the status line
        pylsl.set_config_content(QUIET_LIBLSL)
    return pylsl


def open_lsl(feet: Sequence[LslFoot], *, max_buffered_s: int = MAX_BUFFERED_S) -> LslOutlets:
    """Create the session's outlets (they are discoverable from now on).

    Raises
    ------
    FootnavError
        pylsl is missing (:func:`import_pylsl`), or liblsl refused to create an outlet.
    """
    pylsl = import_pylsl()
    try:
        return LslOutlets(pylsl, feet, max_buffered_s=max_buffered_s)
    except (RuntimeError, OSError) as exc:
        raise FootnavError(f"--lsl: could not create the LSL outlets: {exc}") from None
