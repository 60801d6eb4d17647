"""A session's Rerun outputs — native viewer, web viewer, .rrd file — each with its own logger thread.

Why one :class:`~footnav.views.logger.RerunLogger` per output rather than one recording stream with several
sinks: a gRPC sink whose viewer went away blocks every log call of its stream (rerun-0.41.md, section
5), which would stop the file too. Separate streams with the same ``recording_id`` keep the file
writing when a viewer dies; the dead viewer's logger is dropped with a one-line notice, and the
session and its capture carry on. The outputs merge into one recording wherever they meet.

A recording file that cannot be written (a full disk) is known within its flush period (the file's
logger waits for each flush to be written), said in one line, cut back to its last whole message so
Rerun's readers read it (at the session's end, once its logger is closed), and listed in
:data:`INCOMPLETE_RECORDINGS` (the command's exit code is then :data:`EXIT_RECORDING_INCOMPLETE`).
The web viewer's server stops with the session unless kept; a native viewer still open then removes
its private folder when it exits.
"""

from __future__ import annotations

import contextlib
import logging
import shutil
import subprocess
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr
from footnav.pipeline.errors import FootnavError
from footnav.pipeline.nav_types import ClearanceSeries, NavBatch
from footnav.views.dual_imu import DualRunView
from footnav.views.logger import FILE_FLUSH_PERIOD_S, FLUSH_PERIOD_S, RerunLogger
from footnav.views.paths import DEFAULT_FOOT
from footnav.views.rerun_env import private_folder, remove_private_folder
from footnav.views.sinks import (
    ViewerStartError,
    check_writable,
    default_save_path,
    has_display,
    open_hint,
    serve_web_viewer,
    spawn_viewer,
    stop_process,
    trim_rrd,
    whole_rrd_bytes,
)
from numpy.typing import NDArray

log = logging.getLogger(__name__)

LIVENESS_CHECK_S = 1.0
DEAD_LOGGER_CLOSE_S = 0.5
EXIT_RECORDING_INCOMPLETE = 3
"""Exit code of a session that ran but whose .rrd file could not be written to the end."""
INCOMPLETE_RECORDINGS: list[Path] = []
"""The .rrd files of this process's sessions that stopped early (the command's exit code says so)."""


@dataclass
class Output:
    """One destination of the recording.

    Attributes
    ----------
    kind
        ``viewer``, ``web`` or ``file``.
    description
        for messages (URL, pid or path).
    logger
        its logger thread.
    process
        the viewer or web server process footnav started, if any (watched for exit).
    path
        the .rrd file, for ``file`` outputs.
    folder
        the private folder of the process (:mod:`footnav.views.rerun_env`), removed once it ended (a
        native viewer still open at the session's end removes it itself when it exits).
    keep
        leave the process running when the session ends (a web viewer's server, when asked).
    incomplete
        the ``.rrd`` file could not be written to the end; it is cut back when the session closes.
    closing
        the thread closing the logger of an output dropped during the session.
    """

    kind: str
    description: str
    logger: RerunLogger
    process: subprocess.Popen[bytes] | None = None
    path: Path | None = None
    alive: bool = True
    folder: Path | None = None
    keep: bool = False
    incomplete: bool = False
    closing: threading.Thread | None = None


class SessionViews:
    """Fan-out of one session's estimates to every :class:`Output`; the same calls as RerunLogger.

    Parameters
    ----------
    outputs
        at least one.
    notice
        where one-line notices go (a viewer that died, ...).
    """

    def __init__(self, outputs: Sequence[Output], *, notice: Callable[[str], None]) -> None:
        if not outputs:
            raise ValueError("SessionViews needs at least one output")
        self.outputs = list(outputs)
        self.feet = outputs[0].logger.feet
        self.recording_id = outputs[0].logger.recording_id
        self._notice = notice
        self._next_check = 0.0

    @property
    def live(self) -> list[Output]:
        return [o for o in self.outputs if o.alive]

    def check_outputs(self) -> None:
        """Drop outputs whose viewer process exited or whose logger failed (with a notice)."""
        self._next_check = time.monotonic() + LIVENESS_CHECK_S
        for out in self.outputs:
            if not out.alive:
                continue
            reason = None
            if out.process is not None and (code := out.process.poll()) is not None:
                reason = f"the Rerun {out.kind} ({out.description}) exited (code {code})"
            elif out.logger.stats.error is not None and out.path is not None:
                reason = _file_failed(out, out.logger.stats.error)
            elif out.logger.stats.error is not None:
                reason = f"the Rerun {out.kind} output ({out.description}) failed: {out.logger.stats.error}"
            if reason is None:
                continue
            out.alive = False
            others = [o.description for o in self.outputs if o.alive]
            carry = "the session and its capture carry on"
            if others:
                carry += " and still record to " + ", ".join(others)
            self._notice(f"{reason}; {carry}")
            # its thread may be stuck in a gRPC send: close it in the background, never wait here
            out.closing = threading.Thread(
                target=out.logger.close, args=(DEAD_LOGGER_CLOSE_S,), name="footnav-drop-output", daemon=True
            )
            out.closing.start()

    def _maybe_check(self) -> None:
        if time.monotonic() >= self._next_check:
            self.check_outputs()

    def put(self, nav: NavBatch, *, foot: str = DEFAULT_FOOT, timeout_s: float = 0.0) -> bool:
        """Queue a batch on every live output; False if any of them dropped it."""
        self._maybe_check()
        ok = True
        for out in self.outputs:
            if out.alive:
                ok = out.logger.put(nav, foot=foot, timeout_s=timeout_s) and ok
        return ok

    def sink(self, foot: str = DEFAULT_FOOT, *, timeout_s: float = 0.0) -> Callable[[NavBatch], bool]:
        """A NavSink for one foot."""

        def put(nav: NavBatch) -> bool:
            return self.put(nav, foot=foot, timeout_s=timeout_s)

        return put

    def log_event(self, text: str, *, level: str = "INFO", t_s: float | None = None) -> None:
        for out in self.live:
            out.logger.log_event(text, level=level, t_s=t_s)

    def log_truth(self, pos_n_m: NDArray[np.float64], *, t_s: NDArray[np.float64], foot: str = DEFAULT_FOOT) -> None:
        for out in self.live:
            out.logger.log_truth(pos_n_m, t_s=t_s, foot=foot)

    def log_swing_clearance(self, series: ClearanceSeries, *, foot: str = DEFAULT_FOOT) -> None:
        """Whole-swing clearance values that came after the foot's last batch, on every live output."""
        for out in self.live:
            out.logger.log_swing_clearance(series, foot=foot)

    def log_dual(self, view: DualRunView, *, run: str) -> None:
        """A dual-IMU board's tracks and constraint residuals, on every live output."""
        for out in self.live:
            out.logger.log_dual(view, run=run)

    def log_link(self, **health: Any) -> None:
        """Link health on every live output (``RerunLogger.log_link``'s keywords)."""
        for out in self.live:
            out.logger.log_link(**health)

    def close(self) -> list[str]:
        """Close every live output (file footers written), cut the recording files that could not be
        written back to their last whole message once their loggers are closed, stop the web viewer's
        server unless it is kept, remove the private folders of processes that ended; returns notes on
        what did not close cleanly or was kept running."""
        self.check_outputs()
        notes = []
        for out in self.outputs:
            if out.alive and not out.logger.close():
                notes.append(f"the Rerun {out.kind} ({out.description}) did not finish in time")
            elif out.alive and out.logger.stats.error is not None and out.path is not None:
                notes.append(_file_failed(out, out.logger.stats.error))
            elif out.alive and out.logger.stats.error is not None:
                notes.append(f"the Rerun {out.kind} ({out.description}) failed: {out.logger.stats.error}")
            if out.incomplete and out.path is not None and not _trim_closed(out):
                notes.append(f"the recording file {out.path} was still being written: not cut back")
            if out.process is not None and out.kind == "web viewer" and out.keep:
                notes.append(
                    f"the web viewer keeps running (pid {out.process.pid}, {out.description}); "
                    f"any user of this machine can open it; stop it with `kill {out.process.pid}`"
                )
            elif out.process is not None and out.kind == "web viewer":
                stop_process(out.process)
            if out.folder is not None and (out.process is None or out.process.poll() is not None):
                remove_private_folder(out.folder)
        return notes

    def samples_dropped(self) -> int:
        return max(o.logger.stats.samples_dropped for o in self.outputs)


def _file_failed(out: Output, error: BaseException) -> str:
    """One line on a recording file that could not be written: why, and what it keeps (its whole
    messages, :func:`~footnav.views.sinks.whole_rrd_bytes`; the rest is cut off by :func:`_trim_closed`
    when the session closes). The output is marked incomplete and its path listed in
    :data:`INCOMPLETE_RECORDINGS`."""
    assert out.path is not None
    path = out.path
    out.incomplete = True
    if path not in INCOMPLETE_RECORDINGS:
        INCOMPLETE_RECORDINGS.append(path)
    kept = whole_rrd_bytes(path)
    try:
        full = shutil.disk_usage(path.parent).free < FULL_DISK_BYTES
    except OSError:
        full = False
    why = "no space left on its disk" if full else f"Rerun's file writer stopped ({error})"
    return f"the recording file {path} stopped: {why}; it keeps the first {kept / 1e6:.1f} MB, readable"


FULL_DISK_BYTES = 1 << 20
"""Less free space than this on a recording file's disk when its writing failed: the disk is full."""
CLOSING_WAIT_S = DEAD_LOGGER_CLOSE_S + 5.0
"""How long the session's end waits for a dropped output's logger to close, s."""


def _trim_closed(out: Output) -> bool:
    """Cut an incomplete recording file back to its last whole message
    (:func:`~footnav.views.sinks.trim_rrd`) once nothing of footnav writes it: its logger closed and
    its thread ended (the stream whose writer failed is parked, and its sink gets nothing more).
    False, the file untouched, if the logger's thread is still running."""
    assert out.path is not None
    if out.closing is not None:
        out.closing.join(CLOSING_WAIT_S)
        if out.closing.is_alive():
            return False
    if not out.logger.close(0.0):  # closed already: only says whether its thread ended
        return False
    trim_rrd(out.path)
    return True


def check_save_destination(path: Path) -> None:
    """Make sure a recording can be written at ``path`` (``--save``), before a session starts; the
    probe leaves nothing behind (a file or folders it had to create are removed again).

    Raises
    ------
    FootnavError
        ``path`` is a folder, or the file cannot be created or written (the message says why).
    """
    if path.is_dir():
        raise FootnavError(f"cannot write the recording to {path}: it is a folder; give a file name, e.g. walk.rrd")
    existed = path.exists()
    created: list[Path] = []
    try:
        missing = [d for d in path.parents if not d.exists()]
        for folder in reversed(missing):
            folder.mkdir()
            created.append(folder)
        with open(path, "ab"):
            pass
        if not existed:
            path.unlink()
    except OSError as exc:
        raise FootnavError(f"cannot write the recording to {path}: {exc.strerror or exc}") from None
    finally:
        for folder in reversed(created):
            with contextlib.suppress(OSError):
                folder.rmdir()


def open_session_views(
    *,
    save: Path | None,
    want_viewer: bool,
    web: bool = False,
    feet: Sequence[str] = (DEFAULT_FOOT,),
    recording_id: str,
    notice: Callable[[str], None],
    environ: Mapping[str, str] | None = None,
    dual_runs: Sequence[str] = (),
    rrd_footer: bool = True,
    tof: bool = False,
    truth: bool = False,
    keep_web: bool = False,
) -> tuple[SessionViews | None, list[str]]:
    """Start a session's outputs and describe them.

    ``tof``: the session has ToF units (their panels are in the layout); ``truth``: it has a ground
    truth (the error from it gets a panel). ``rrd_footer=False`` (live
    sessions, whose length is open): the ``.rrd`` file gets no footer
    index, which Rerun's file sink keeps in memory until the file closes (about 2.3 MB per minute of
    two feet at 1 kHz); the file reads like one whose writer was stopped (``RrdReader.stream()``, the
    viewer), and ``rerun rrd optimize`` adds the index.

    - ``web``: host the web viewer on 127.0.0.1 and stream to it (its URL is in the notes); its server
      stops with the session (:meth:`SessionViews.close`) unless ``keep_web``;
    - else, a viewer wanted and a display present: spawn the native viewer (127.0.0.1);
    - a viewer wanted but none could start (no display, start-up failure): save to a default file
      (reported and skipped if it cannot be written);
    - ``save``: always also that file.

    Returns
    -------
    views : SessionViews | None
        None when there is no output at all.
    notes : list[str]
        The notes describing the outputs (the web viewer's URL is in them).

    Raises
    ------
    FootnavError
        ``save`` cannot be written (:func:`check_save_destination`); nothing was started.
    """
    if save is not None:
        check_save_destination(save)
    outputs: list[Output] = []
    notes: list[str] = []

    def logger(sink: rr.GrpcSink | rr.FileSink) -> RerunLogger:
        # a file needs no live updates; fewer, larger chunks also keep the footer index small
        flush = FILE_FLUSH_PERIOD_S if isinstance(sink, rr.FileSink) else FLUSH_PERIOD_S
        return RerunLogger(
            [sink],
            recording_id=recording_id,
            feet=feet,
            dual_runs=dual_runs,
            flush_period_s=flush,
            tof=tof,
            truth=truth,
            verify_writes=isinstance(sink, rr.FileSink),
        )

    fallback = False
    if web:
        folder = private_folder()
        try:
            grpc_url, page, proc = serve_web_viewer(folder=folder)
        except ViewerStartError as exc:
            remove_private_folder(folder)
            notes.append(f"web viewer not started: {exc}")
            fallback = True
        else:
            web_out = Output("web viewer", page, logger(rr.GrpcSink(grpc_url)), proc, folder=folder, keep=keep_web)
            outputs.append(web_out)
            until = "kept after the session" if keep_web else "until the session ends; --keep-web keeps it"
            notes.append(f"web viewer (127.0.0.1 only, pid {proc.pid}, {until}): open {page}")
    elif want_viewer:
        if has_display(environ):
            folder = private_folder()  # the viewer may outlive the session: it removes the folder on exit
            try:
                url, proc = spawn_viewer(env=environ, folder=folder)
            except ViewerStartError as exc:
                remove_private_folder(folder)
                notes.append(f"viewer not started: {exc}")
                fallback = True
            else:
                outputs.append(Output("viewer", f"pid {proc.pid}", logger(rr.GrpcSink(url)), proc, folder=folder))
                notes.append(f"streaming to a Rerun viewer (pid {proc.pid}, {url})")
        else:
            notes.append("no display (neither DISPLAY nor WAYLAND_DISPLAY is set): no viewer (--web serves one)")
            fallback = True
    path = save if save is not None else (default_save_path() if fallback else None)
    if path is not None:
        problem = check_writable(path)
        if problem is not None:
            notes.append(f"{problem}; carrying on without it")
        else:
            sink = rr.FileSink(str(path), write_footer=rrd_footer)
            outputs.append(Output("recording file", str(path), logger(sink), path=path))
            notes.append(f"saving to {path}; {open_hint(path, environ)}")
    if not outputs:
        notes.append("Rerun output off (no viewer, no file)")
        return None, notes
    return SessionViews(outputs, notice=notice), notes
