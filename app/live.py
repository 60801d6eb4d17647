"""``footnav live``: one unit or two (left and right foot), each with its own navigator, shown together.

Shared by ``live`` and ``demo``: the capture file (every byte, both directions, written by the unit
driver's tap before any decoding), the Rerun outputs (one recording, one ``recording_id``), the
one-line status of every foot, and link health.
"""

from __future__ import annotations

import asyncio
import dataclasses
import sys
import uuid
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from app.config import Config
from app.session import LinkHealth, SerialSessionResult, run_serial_session
from app.status import StatusLine
from device.capture import CaptureTap, CaptureWriter, UnitHeader
from device.unit import OpenShoeUnit
from pipeline.errors import DeviceError, FootnavError
from pipeline.nav_types import NavBatch
from pipeline.navigator import Navigator
from pipeline.runner import NavSink
from views.outputs import SessionViews, open_session_views

FOOT_START_OFFSET_M: dict[str, tuple[float, float, float]] = {
    "left": (0.0, 0.1, 0.0),
    "right": (0.0, -0.1, 0.0),
}
"""Where each foot's navigation origin is drawn: two feet start side by side, 0.2 m apart (each
navigator starts at its own origin; this offset is for display only)."""

UNIT_KIND = "OpenShoe/MIMU/Oblu, calibrated IMU output (0x40)"
BASE_RATE_HZ = 1000.0


def notice(text: str) -> None:
    """A one-line notice on stderr, on a fresh line (the status line may be mid-way)."""
    print(f"\nfootnav: {text}", file=sys.stderr, flush=True)


def new_session_id(kind: str, now: datetime | None = None) -> str:
    """``<kind>-YYYYmmdd-HHMMSS-<6 hex>``: the recording id and the capture file's name."""
    return f"{kind}-{(now or datetime.now()).strftime('%Y%m%d-%H%M%S')}-{uuid.uuid4().hex[:6]}"


def offset_sink(sink: NavSink, offset_m: Sequence[float]) -> NavSink:
    """``sink`` fed with positions shifted by ``offset_m`` (display only)."""
    off = np.asarray(offset_m, dtype=np.float64)

    def shifted(nav: NavBatch) -> object:
        return sink(dataclasses.replace(nav, pos_n_m=nav.pos_n_m + off))

    return shifted


def open_capture(config: Config, session_id: str, *, enabled: bool, extra: dict[str, str]) -> CaptureWriter | None:
    """Create ``<sessions_dir>/<session_id>.mcap`` if capture is on; a folder that cannot be written
    is reported and the session goes on without a capture."""
    if not enabled:
        return None
    path = Path(config["session.sessions_dir"]) / f"{session_id}.mcap"
    try:
        writer = CaptureWriter(path, session={"session_id": session_id, **extra})
    except OSError as exc:
        notice(f"cannot write the capture {path}: {exc.strerror or exc}; carrying on without a capture")
        return None
    print(f"capturing every byte to {path} (replay it with `footnav replay {path}`)", file=sys.stderr)
    return writer


def unit_header(foot: str, port: str, transport: str, config: Config, rate_divider_log2: int) -> UnitHeader:
    return UnitHeader(
        foot=foot,
        unit=UNIT_KIND,
        command_set="openshoe (2015 set, 2014 probed)",
        transport=transport,
        port=port,
        settings={
            "mode": "normal_imu",
            "rate_divider_log2": rate_divider_log2,
            "rate_hz": BASE_RATE_HZ / 2**rate_divider_log2,
            "nav_config": config.to_json(),
        },
        calibration={
            "on_unit": "factory calibration applied by the unit (calibrated output 0x40)",
            "profile": config["unit.profile"],
        },
    )


@dataclass
class FootRun:
    """One foot of a session: its navigator, its result, its sinks."""

    foot: str
    port: str
    navigator: Navigator
    result: SerialSessionResult = field(default_factory=SerialSessionResult)
    tap: CaptureTap | None = None
    health: LinkHealth | None = None
    sinks: list[NavSink] = field(default_factory=list)
    error: BaseException | None = None


def foot_sinks(
    run: FootRun, views: SessionViews | None, status: StatusLine, *, two_feet: bool, put_timeout_s: float = 0.0
) -> None:
    """Wire a foot to the views (display-offset when two feet), the status line and link health."""
    run.sinks = [status.foot(run.foot)]
    if views is not None:
        display: NavSink = views.sink(run.foot, timeout_s=put_timeout_s)
        if two_feet and run.foot in FOOT_START_OFFSET_M:
            display = offset_sink(display, FOOT_START_OFFSET_M[run.foot])
        run.health = LinkHealth(views.log_link, run.foot)
        run.sinks = [display, run.health, *run.sinks]


async def run_feet(runs: Sequence[FootRun], session: Callable[[FootRun], Awaitable[Any]]) -> None:
    """Run every foot's session at once; a foot whose unit fails is reported and the others carry on.

    Raises:
        FootnavError: every foot failed (the first error).
    """

    async def one(run: FootRun) -> None:
        try:
            await session(run)
        except (FootnavError, OSError) as exc:
            run.error = exc
            if len(runs) > 1:
                notice(f"{run.foot} foot stopped: {exc}")

    await asyncio.gather(*(one(r) for r in runs))
    errors = [r.error for r in runs if r.error is not None]
    if errors and len(errors) == len(runs):
        raise errors[0] if isinstance(errors[0], FootnavError) else DeviceError(str(errors[0]))


def finish_capture(capture: CaptureWriter | None, runs: Sequence[FootRun]) -> None:
    """Mark where each foot's live session stopped (a replay stops there too) and close the file."""
    if capture is None:
        return
    for run in runs:
        capture.event(run.foot, "end", samples=run.result.samples_received, error=str(run.error or ""))
    capture.close()
    if capture.rx_bytes == 0:  # no unit ever answered: nothing worth keeping
        capture.path.unlink(missing_ok=True)
        return
    mb = capture.path.stat().st_size / 1e6
    print(
        f"capture: {capture.path} ({mb:.1f} MB, {capture.messages} reads/writes, "
        f"{capture.write_seconds:.2f} s spent writing)",
        file=sys.stderr,
    )


@dataclass(frozen=True)
class LiveOptions:
    """What ``footnav live`` was asked for.

    Attributes:
        ports: foot name -> serial port: ``{"foot": port}`` for one unit, ``left``/``right`` for two.
    """

    ports: dict[str, str]
    config: Config
    save: Path | None = None
    viewer: bool = True
    web: bool = False
    capture: bool = True
    argv: tuple[str, ...] = ()


def run_live(opts: LiveOptions) -> int:
    """Navigate one or two connected units until Ctrl-C; returns the exit code.

    Raises:
        FootnavError: a port cannot be opened, a unit does not answer (all feet failed).
    """
    cfg = opts.config
    rate_divider = int(cfg["unit.rate_divider"])
    if not 0 <= rate_divider <= 6:
        raise FootnavError(f"rate divider must be 0..6, got {rate_divider} ({cfg.source('unit.rate_divider')})")
    rate_hz = BASE_RATE_HZ / 2**rate_divider
    feet = tuple(opts.ports)
    session_id = new_session_id("live")
    views, notes = open_session_views(
        save=opts.save, want_viewer=opts.viewer, web=opts.web, feet=feet, recording_id=session_id, notice=notice
    )
    for note in notes:
        print(note, file=sys.stderr)
    capture = open_capture(cfg, session_id, enabled=opts.capture, extra={"command": " ".join(opts.argv)})
    status = StatusLine(feet=feet)
    nav_config = cfg.nav_config()
    runs = [FootRun(foot, port, Navigator(nav_config, rate_hz=rate_hz)) for foot, port in opts.ports.items()]
    for run in runs:
        foot_sinks(run, views, status, two_feet=len(runs) > 1)
        if capture is not None:
            run.tap = capture.add_unit(unit_header(run.foot, run.port, "serial", cfg, rate_divider))

    async def session(run: FootRun) -> None:
        def opened(unit: OpenShoeUnit) -> None:
            if run.health is not None:
                run.health.stats = lambda: unit.stats

        await run_serial_session(
            run.port,
            run.navigator,
            run.sinks,
            rate_divider_log2=rate_divider,
            status=status.foot(run.foot),
            result=run.result,
            capture=run.tap,
            on_open=opened,
        )

    if views is not None:
        views.log_event(f"live session {session_id}: " + ", ".join(f"{f} on {p}" for f, p in opts.ports.items()))
    try:
        asyncio.run(run_feet(runs, session))
    except KeyboardInterrupt:
        print("\nstopped: the unit was told to stop and the recording was closed", file=sys.stderr)
    finally:
        status.finish()
        finish_capture(capture, runs)
        if views is not None:
            for note in views.close():
                notice(note)
    return 0
