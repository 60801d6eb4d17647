"""A picture of a recording as the Rerun viewer shows it: the viewer shipped with rerun-sdk, run
headless (software Vulkan, e.g. Mesa's lavapipe), opens an ``.rrd`` with its default blueprint and
saves a PNG.

``rerun --headless --screenshot-to`` shoots before the recording has loaded (empty plots), so the
viewer is driven through its control API (``rerun.experimental.ViewerClient``): open the file, wait
until its data reaches the recording's last time, give the views a few frames, then take the picture.
"""

from __future__ import annotations

import shutil
import socket
import subprocess
import tempfile
import time
from pathlib import Path

from footnav.views.rerun_env import VIEWER_FLAGS, rerun_environment
from footnav.views.sinks import LOOPBACK, viewer_binary

LAVAPIPE_ICD = Path("/usr/share/vulkan/icd.d/lvp_icd.x86_64.json")
"""Mesa's software Vulkan driver on Debian/Ubuntu x86-64 (package ``mesa-vulkan-drivers``)."""
SETTLE_S = 3.0
"""Frames the views get after the data has loaded, s."""
STABLE_S = 2.0
"""Without a known end, the data has loaded when the timeline's end has not moved for this long, s."""


class ScreenshotError(RuntimeError):
    """The headless viewer did not start, load the recording or save the picture."""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind((LOOPBACK, 0))
        return int(s.getsockname()[1])


def screenshot(
    rrd: Path,
    png: Path,
    *,
    end_s: float | None = None,
    size: tuple[int, int] = (1600, 900),
    timeout_s: float = 90.0,
    settle_s: float = SETTLE_S,
) -> None:
    """Render ``rrd`` in a headless viewer and save it to ``png``.

    Parameters
    ----------
    rrd
        the recording.
    png
        where to save the picture.
    end_s
        the recording's last time on its first timeline, s: the picture is taken once the viewer has
        loaded this far (None: once that timeline has stopped growing for :data:`STABLE_S`).
    size
        window width and height, pixels.
    timeout_s
        how long the viewer may take to start and load, s.
    settle_s
        how long the views get after the data has loaded, s (the viewer's start-up notices fade
        after about 10 s).

    Raises
    ------
    ScreenshotError
        the viewer did not come up or load the recording within ``timeout_s``.
    """
    from rerun.experimental import ViewerClient

    port = _free_port()
    home = tempfile.mkdtemp(prefix="footnav-viewer-")  # a fresh viewer: no saved layout or settings
    env = rerun_environment(Path(home))
    cmd = [str(viewer_binary()), "--headless", "--bind", LOOPBACK, "--port", str(port)]
    cmd += ["--window-size", f"{size[0]}x{size[1]}", *VIEWER_FLAGS]
    viewer = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    try:
        deadline = time.monotonic() + timeout_s
        client = None
        while client is None and time.monotonic() < deadline:
            try:
                client = ViewerClient.connect(f"rerun+http://{LOOPBACK}:{port}/proxy")
            except Exception:
                time.sleep(0.3)
        if client is None:
            raise ScreenshotError(f"the headless viewer did not come up within {timeout_s:.0f} s")
        client.open(str(rrd))
        last_end, since = -1, time.monotonic()
        while True:
            recs = client.get_state().recordings
            end = (recs[0].timelines[0].end or 0) if recs and recs[0].timelines else 0
            if end != last_end:
                last_end, since = end, time.monotonic()
            if end > 0 and (end >= (end_s - 0.1) * 1e9 if end_s is not None else time.monotonic() - since > STABLE_S):
                break
            if time.monotonic() > deadline:
                raise ScreenshotError(f"the viewer did not load {rrd} within {timeout_s:.0f} s")
            time.sleep(0.3)
        time.sleep(settle_s)
        while True:  # the viewer's own deadline per request is short for software rendering on a busy machine
            try:
                client.save_screenshot(str(png))
                break
            except TimeoutError:
                if time.monotonic() > deadline:
                    raise ScreenshotError(f"the viewer did not render {rrd} within {timeout_s:.0f} s") from None
    finally:
        viewer.terminate()
        try:
            viewer.wait(20)
        except subprocess.TimeoutExpired:
            viewer.kill()
            viewer.wait()
        shutil.rmtree(home, ignore_errors=True)
