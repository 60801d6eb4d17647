"""Where a session's Rerun data goes: a native viewer on this machine, a .rrd file, or both.

Everything listens on 127.0.0.1 only: the viewer is started from the installed rerun-sdk wheel
(``rerun_cli/rerun``, the same version as the SDK) with ``--bind 127.0.0.1`` rather than through
``rr.spawn``, which binds 0.0.0.0. Without a display (no ``DISPLAY``/``WAYLAND_DISPLAY``) no viewer
is started — spawning one there stalls for ~11 s and loses data — and the session is saved instead.
Every viewer runs in the environment of :mod:`footnav.views.rerun_env` (no analytics, no outbound
connection, its files in a private folder, removed when the native viewer exits). A recording file
cut short (a full disk) is trimmed to its last whole message by :func:`trim_rrd`, so Rerun's readers
read it.
"""

from __future__ import annotations

import contextlib
import os
import shlex
import shutil
import signal
import socket
import subprocess
import sys
import sysconfig
import time
from collections.abc import Mapping
from datetime import datetime
from pathlib import Path

from footnav.pipeline.errors import FootnavError
from footnav.views.rerun_env import (
    VIEWER_FLAGS,
    private_folder,
    remove_folder_after,
    remove_private_folder,
    rerun_environment,
)

LOOPBACK = "127.0.0.1"
VIEWER_MEMORY_LIMIT = "25%"
"""The viewer drops its oldest data beyond this (of system RAM); its RSS is about 2–2.5× this."""
VIEWER_SERVER_MEMORY_LIMIT = "256MB"
"""Cap on the viewer's gRPC proxy buffer (default 1 GiB)."""
VIEWER_START_TIMEOUT_S = 8.0
VIEWER_GRACE_S = 1.0
"""A viewer that cannot open its window opens its port first and exits a moment later: wait this long."""


class ViewerStartError(FootnavError):
    """The Rerun viewer could not be started or did not open its port."""


def has_display(environ: Mapping[str, str] | None = None) -> bool:
    """True if a viewer window can open: ``DISPLAY`` or ``WAYLAND_DISPLAY`` set (always on macOS/Windows)."""
    env = os.environ if environ is None else environ
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(env.get("DISPLAY") or env.get("WAYLAND_DISPLAY"))


def viewer_binary() -> Path:
    """Path of the viewer executable shipped in the rerun-sdk wheel (``rerun_cli/rerun``).

    Raises
    ------
    ViewerStartError
        the wheel has no viewer binary.
    """
    import rerun_cli

    exe = Path(rerun_cli.__file__).parent / ("rerun.exe" if sys.platform == "win32" else "rerun")
    if not exe.is_file():
        raise ViewerStartError(f"the Rerun viewer is missing from the rerun-sdk install (expected {exe})")
    return exe


def _free_loopback_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((LOOPBACK, 0))
        return int(s.getsockname()[1])


def _port_open(port: int) -> bool:
    try:
        with socket.create_connection((LOOPBACK, port), timeout=0.2):
            return True
    except OSError:
        return False


def spawn_viewer(
    *,
    memory_limit: str = VIEWER_MEMORY_LIMIT,
    server_memory_limit: str = VIEWER_SERVER_MEMORY_LIMIT,
    timeout_s: float = VIEWER_START_TIMEOUT_S,
    env: Mapping[str, str] | None = None,
    folder: Path | None = None,
) -> tuple[str, subprocess.Popen[bytes]]:
    """Start a native viewer listening on 127.0.0.1 and wait until it accepts connections.

    Blocks up to ``timeout_s``: call it before the event loop starts, or through ``asyncio.to_thread``.
    The viewer runs in its own session so it outlives footnav (the user closes it). Its environment
    is ``env`` (default: inherited) made private by
    :func:`~footnav.views.rerun_env.rerun_environment` in ``folder`` (default: a new
    :func:`~footnav.views.rerun_env.private_folder`). The viewer is started through
    :func:`~footnav.views.rerun_env.remove_folder_after`: ``folder`` goes when the viewer exits,
    whenever that is (on POSIX); if the viewer fails to start, a folder made here is removed at once,
    and one given is the caller's to remove.

    Returns
    -------
    url : str
        The ``rerun+http://127.0.0.1:PORT/proxy`` URL for ``rr.GrpcSink``.
    process : subprocess.Popen[bytes]
        The viewer's process (on POSIX its ``/bin/sh`` wrapper, which exits with the viewer's code).

    Raises
    ------
    ViewerStartError
        the viewer exited or did not open its port in time.
    """
    own = folder is None
    folder = private_folder() if folder is None else folder
    port = _free_loopback_port()
    cmd = [
        str(viewer_binary()),
        "--bind", LOOPBACK,
        "--port", str(port),
        "--memory-limit", memory_limit,
        "--server-memory-limit", server_memory_limit,
        "--expect-data-soon",
        *VIEWER_FLAGS,
    ]  # fmt: skip
    proc = subprocess.Popen(
        remove_folder_after(cmd, folder),
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
        env=rerun_environment(folder, env),
    )
    try:
        _wait_for_viewer(proc, port, timeout_s, cmd[0])
    except ViewerStartError:
        if own:
            remove_private_folder(folder)
        raise
    return f"rerun+http://{LOOPBACK}:{port}/proxy", proc


def _wait_for_viewer(proc: subprocess.Popen[bytes], port: int, timeout_s: float, exe: str) -> None:
    """Return once the viewer ``proc`` listens on ``port`` and is still running :data:`VIEWER_GRACE_S`
    later; raise :class:`ViewerStartError` (its process group ended) otherwise."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise ViewerStartError(
                f"the Rerun viewer exited at start-up (code {proc.returncode}); "
                f"try running `{exe}` yourself to see why, or use --save FILE.rrd"
            )
        if _port_open(port):
            try:
                code = proc.wait(VIEWER_GRACE_S)
            except subprocess.TimeoutExpired:
                return
            raise ViewerStartError(
                f"the Rerun viewer exited right after start-up (code {code}); "
                f"try running `{exe}` yourself to see why, or use --save FILE.rrd"
            )
        time.sleep(0.05)
    _stop_group(proc)
    raise ViewerStartError(
        f"the Rerun viewer did not open port {port} within {timeout_s:.0f} s; "
        "use --save FILE.rrd and open the file later"
    )


def _stop_group(proc: subprocess.Popen[bytes], timeout_s: float = 5.0) -> None:
    """End a process started in a new session and everything in its group (a wrapper and its viewer)."""
    if os.name == "posix":
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout_s)
    else:
        stop_process(proc, timeout_s)


WEB_VIEWER_START_TIMEOUT_S = 15.0


def web_viewer_url(web_port: int, grpc_port: int) -> str:
    """The URL that opens the hosted web viewer connected to the gRPC server on ``grpc_port``."""
    from urllib.parse import quote

    return f"http://{LOOPBACK}:{web_port}/?url=" + quote(f"rerun+http://{LOOPBACK}:{grpc_port}/proxy", safe="")


def serve_web_viewer(
    *,
    server_memory_limit: str = VIEWER_SERVER_MEMORY_LIMIT,
    timeout_s: float = WEB_VIEWER_START_TIMEOUT_S,
    web_port: int | None = None,
    folder: Path,
) -> tuple[str, str, subprocess.Popen[bytes]]:
    """Host the Rerun web viewer and its gRPC proxy on 127.0.0.1 (the viewer binary, ``--serve-web``).

    ``rr.serve_web_viewer``/``rr.serve_grpc`` would bind 0.0.0.0; the CLI with ``--bind`` does not.
    Loopback is not private: any process of any user on this machine can open both ports while the
    server runs (there is no token). The server runs in its own session (its process group is the
    server alone: :func:`stop_process` ends it); it buffers at most ``server_memory_limit`` for late
    browsers. It runs in the environment of
    :func:`~footnav.views.rerun_env.rerun_environment` in ``folder``.

    Returns
    -------
    grpc_url : str
        For ``rr.GrpcSink``.
    page_url : str
        The page URL to open in a browser.
    process : subprocess.Popen[bytes]
        The server's process.

    Raises
    ------
    ViewerStartError
        it exited or did not open its ports in time.
    """
    grpc_port = _free_loopback_port()
    web_port = web_port or _free_loopback_port()
    cmd = [
        str(viewer_binary()),
        "--serve-web",
        "--bind", LOOPBACK,
        "--port", str(grpc_port),
        "--web-viewer-port", str(web_port),
        "--server-memory-limit", server_memory_limit,
    ]  # fmt: skip
    proc = subprocess.Popen(
        cmd,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
        env=rerun_environment(folder),
    )
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise ViewerStartError(
                f"the Rerun web viewer server exited at start-up (code {proc.returncode}); "
                f"try `{' '.join(cmd)}` yourself to see why, or use --save FILE.rrd"
            )
        if _port_open(grpc_port) and _port_open(web_port):
            return f"rerun+http://{LOOPBACK}:{grpc_port}/proxy", web_viewer_url(web_port, grpc_port), proc
        time.sleep(0.05)
    proc.terminate()
    raise ViewerStartError(
        f"the Rerun web viewer did not open ports {grpc_port}/{web_port} within {timeout_s:.0f} s; "
        "use --save FILE.rrd and open the file later"
    )


def stop_process(proc: subprocess.Popen[bytes], timeout_s: float = 5.0) -> None:
    """End a process footnav started (SIGTERM, then SIGKILL after ``timeout_s``) and reap it."""
    if proc.poll() is not None:
        return
    proc.terminate()
    try:
        proc.wait(timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(timeout_s)


RRD_STREAM_HEADER_BYTES = 12
"""An .rrd file starts with ``RRF2``, 4 bytes of format version and 4 of options."""
RRD_MESSAGE_HEADER_BYTES = 16
"""Each message follows: its kind and its payload length, two little-endian u64, then the payload."""


def whole_rrd_bytes(path: Path) -> int:
    """The length of a recording file up to the end of its last whole message; the file is not changed.

    The messages are walked by their headers only (:data:`RRD_MESSAGE_HEADER_BYTES`); an end marker
    (kind 0: the footer follows) ends the walk at the file's size.

    Returns
    -------
    int
        The bytes of whole messages (the file's size if it is whole, 0 if it is not a regular .rrd
        file), bytes.
    """
    try:
        size = path.stat().st_size
        if not path.is_file() or size < RRD_STREAM_HEADER_BYTES:
            return 0
        with open(path, "rb") as f:
            if f.read(4) != b"RRF2":
                return 0
            end = RRD_STREAM_HEADER_BYTES
            while end + RRD_MESSAGE_HEADER_BYTES <= size:
                f.seek(end)
                header = f.read(RRD_MESSAGE_HEADER_BYTES)
                kind, length = int.from_bytes(header[:8], "little"), int.from_bytes(header[8:], "little")
                if kind == 0:
                    return size
                if end + RRD_MESSAGE_HEADER_BYTES + length > size:
                    break
                end += RRD_MESSAGE_HEADER_BYTES + length
            return end
    except OSError:
        return 0


def trim_rrd(path: Path) -> int:
    """Cut a recording file whose writing stopped mid-message back to its last whole message
    (:func:`whole_rrd_bytes`).

    Rerun's file writer that fails (a full disk) leaves a partial message at the end, and
    ``RrdReader(path).stream()`` refuses the whole file for it ("Message payload … exceeds file
    size"); without it the file reads as one whose writer was stopped. Call it only once nothing
    writes the file any more: a writer that wrote on would write past the new end.

    Returns
    -------
    int
        The bytes kept (the file's size if it was whole, 0 if it is not a regular .rrd file).
    """
    end = whole_rrd_bytes(path)
    try:
        if 0 < end < path.stat().st_size:
            with open(path, "r+b") as f:
                f.truncate(end)
    except OSError:
        return 0
    return end


def check_writable(path: Path) -> str | None:
    """None if a recording can be written at ``path`` (the file is created), else why not, in words."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "wb"):
            pass
    except OSError as exc:
        return f"cannot write the recording to {path}: {exc.strerror or exc}"
    return None


def default_save_path(now: datetime | None = None, directory: Path | None = None) -> Path:
    """``footnav-YYYYmmdd-HHMMSS.rrd`` in ``directory`` (default: the working directory); ``-2``, ``-3`` ...
    before the suffix when a file of that name exists (another session of the same second)."""
    stamp = (now or datetime.now()).strftime("%Y%m%d-%H%M%S")
    folder = directory or Path.cwd()
    path, k = folder / f"footnav-{stamp}.rrd", 1
    while path.exists():
        k += 1
        path = folder / f"footnav-{stamp}-{k}.rrd"
    return path


def rerun_command() -> str:
    """How to call the ``rerun`` command of this install: ``rerun`` when it is the one on ``PATH``,
    else its path (relative to the working directory when inside it, e.g. ``.venv/bin/rerun``)."""
    exe = rerun_script()
    found = shutil.which("rerun")
    if not exe.is_file() or (found is not None and Path(found).resolve() == exe.resolve()):
        return "rerun"
    return _shown(exe)


def rerun_script() -> Path:
    """Where this install's ``rerun`` command is (the environment's scripts folder)."""
    return Path(sysconfig.get_path("scripts")) / ("rerun.exe" if sys.platform == "win32" else "rerun")


def _shown(path: Path) -> str:
    """``path`` quoted for the shell (``cmd`` on Windows), relative to the working directory when inside it."""
    with contextlib.suppress(ValueError):
        path = path.absolute().relative_to(Path.cwd())
    return subprocess.list2cmdline([str(path)]) if sys.platform == "win32" else shlex.quote(str(path))


def open_hint(path: Path, environ: Mapping[str, str] | None = None) -> str:
    """The command that opens the recording ``path``: the native viewer, or without a display a
    viewer in the browser (:data:`LOOPBACK` only)."""
    exe, name = rerun_command(), _shown(path)
    if has_display(environ):
        return f"view it with `{exe} {name}`"
    browser = f"{exe} --web-viewer --bind {LOOPBACK} {name}"
    return f"view it with `{exe} {name}` on a machine with a display, or here in a browser: `{browser}`"
