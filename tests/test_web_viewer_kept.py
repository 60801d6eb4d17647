"""``--web --keep-web``: the web viewer footnav started goes on serving after the session, as the
session says, until it is stopped (without ``--keep-web`` it stops with the session:
``tests/test_no_network.py``)."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
import urllib.request
from pathlib import Path


def test_a_kept_web_viewer_serves_after_the_demo_and_says_how_to_stop_it(tmp_path: Path) -> None:
    argv = [sys.executable, "-m", "footnav.app", "demo", "--web", "--keep-web", "--duration", "3", "--pace", "max"]
    proc = subprocess.run(
        [*argv, "--sessions", str(tmp_path)], check=False, capture_output=True, text=True, timeout=600
    )
    assert proc.returncode == 0, proc.stderr
    said = re.search(
        r"the web viewer keeps running \(pid (\d+), (http://127\.0\.0\.1:\d+/)\S*\);.*`kill \1`", proc.stderr
    )
    assert said is not None, proc.stderr
    pid, page = int(said.group(1)), said.group(2)
    try:
        time.sleep(1.0)  # the session has ended: its process is gone, the viewer's is not
        os.kill(pid, 0)
        with urllib.request.urlopen(page, timeout=30) as reply:
            assert reply.status == 200 and b"<html" in reply.read().lower()
    finally:
        os.kill(pid, signal.SIGTERM)


def test_keep_web_without_web_is_a_usage_error() -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "footnav.app", "demo", "--keep-web"],
        check=False,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2
    assert (
        proc.stderr.strip().splitlines()[-1]
        == "footnav: error: --keep-web keeps the web viewer of --web: give --web too"
    )
