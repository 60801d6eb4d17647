"""The environment of every Rerun process footnav starts: no usage analytics, no outbound connection,
nothing written outside a private folder.

What the viewer binary of rerun-sdk 0.41 does on its own, measured in a network namespace whose only
resolver logs the names asked (``tests/test_no_network.py``):

- it sends usage analytics to ``tel.rerun.io`` unless ``$XDG_CONFIG_HOME/rerun/analytics.json`` says
  ``"analytics_enabled": false``, and it keeps that file and an analytics folder under
  ``$XDG_CONFIG_HOME`` and ``$XDG_DATA_HOME`` (by default in the user's home);
- the native viewer's welcome screen fetches the examples' list from ``app.rerun.io``
  (``--hide-welcome-screen`` stops it);
- the native viewer asks ``api.github.com`` for the latest release, with no switch to turn it off; its
  HTTP client honours the proxy variables, so a proxy at ``127.0.0.1:0`` (nothing can listen on port
  0) ends the request at once, on this machine, without a name lookup;
- the native viewer saves its layout and settings in ``$XDG_DATA_HOME/rerun`` (0.41 has no switch
  to stop it; its ``--persist-state`` takes no value).

:func:`rerun_environment` gives a process all of this: ``HOME`` and the XDG folders inside a private
folder (:func:`private_folder`, in the system's temporary folder) holding a config that turns
analytics off, the proxy variables, and ``NO_PROXY`` cleared. :data:`VIEWER_FLAGS` are the command-line
half. The Python SDK footnav runs in its own process opens no connection but to the viewers footnav
starts and writes only the files it is given (the same test); footnav never calls the SDK functions
that start a viewer or a server in-process (``rr.spawn``, ``rr.serve_grpc``, ``rr.serve_web_viewer``;
``tests/test_no_network.py`` checks the source).
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path

DEAD_PROXY = "http://127.0.0.1:0"
"""A proxy address nothing can listen on: an HTTP request sent through it fails at once, locally."""
PROXY_VARIABLES = ("HTTPS_PROXY", "https_proxy", "HTTP_PROXY", "http_proxy", "ALL_PROXY", "all_proxy")
VIEWER_FLAGS = ("--hide-welcome-screen",)
"""Flags for every native viewer footnav starts: no examples fetched."""
ANALYTICS_ID = "0" * 32
"""The id the analytics config must carry to be read; with analytics off it is never sent."""


def private_folder() -> Path:
    """A new folder, readable by this user only, for one session's Rerun processes (remove it with
    :func:`remove_private_folder`)."""
    return Path(tempfile.mkdtemp(prefix="footnav-rerun-"))


def remove_private_folder(folder: Path) -> None:
    """Remove a folder made by :func:`private_folder`, whatever it holds (errors ignored)."""
    shutil.rmtree(folder, ignore_errors=True)


_REMOVE_AFTER = 'folder=$1; shift; "$@"; code=$?; rm -rf -- "$folder"; exit $code'
"""A POSIX shell script: run the command given, then remove ``folder``, and exit with the command's
code (128 + the signal's number if a signal ended it)."""


def remove_folder_after(cmd: Sequence[str], folder: Path) -> list[str]:
    """``cmd`` wrapped so that ``folder`` is removed when the command exits, whenever that is.

    For a viewer that outlives footnav: ``/bin/sh`` runs it, waits for it and then removes its private
    folder, so a viewer still open when the session ends takes its folder with it when it closes.
    The wrapper's process is the viewer's parent (its pid is the process group's, if started in a
    new session) and exits with the viewer's code. On Windows (no ``/bin/sh``) ``cmd`` is returned
    unchanged and the folder is left to the system's temporary-folder cleaning.
    """
    if os.name != "posix":
        return list(cmd)
    return ["/bin/sh", "-c", _REMOVE_AFTER, "sh", str(folder), *cmd]


def rerun_environment(folder: Path, base: Mapping[str, str] | None = None) -> dict[str, str]:
    """The environment for a Rerun viewer process: ``base`` (default ``os.environ``) with its home and
    XDG folders in ``folder``, analytics off and outbound HTTP sent to :data:`DEAD_PROXY`.

    Writes ``folder/config/rerun/analytics.json``; the display variables and everything else of
    ``base`` are kept (and X11's ``XAUTHORITY``, which defaults to a file in the old ``HOME``).
    """
    config, data, cache, state = (folder / name for name in ("config", "data", "cache", "state"))
    analytics = config / "rerun" / "analytics.json"
    analytics.parent.mkdir(parents=True, exist_ok=True)
    analytics.write_text(
        json.dumps(
            {
                "analytics_enabled": False,
                "analytics_id": ANALYTICS_ID,
                "metadata": {},
                "config_file_path": str(analytics),
                "data_dir_path": str(data / "rerun" / "analytics"),
            }
        )
    )
    env = dict(os.environ if base is None else base)
    home = env.get("HOME")
    if "XAUTHORITY" not in env and home and (Path(home) / ".Xauthority").is_file():
        env["XAUTHORITY"] = str(Path(home) / ".Xauthority")  # X11 looks for it in HOME, which moves
    env.update(
        HOME=str(folder),
        XDG_CONFIG_HOME=str(config),
        XDG_DATA_HOME=str(data),
        XDG_CACHE_HOME=str(cache),
        XDG_STATE_HOME=str(state),
        NO_PROXY="",
        no_proxy="",
    )
    env.update(dict.fromkeys(PROXY_VARIABLES, DEAD_PROXY))
    return env


SDK_LOG_FILTER = "warn,re_log_encoding::rrd=off,re_sdk::recording_stream=off"
"""The Rust log filter of the Rerun SDK in footnav's process (``RUST_LOG``, read once, when rerun is
first imported): the SDK's own messages on a recording file that fails and on sinks that go away are
off, as footnav says those itself, in one line (:mod:`footnav.views.outputs`); other warnings show."""


def prepare_sdk_environment() -> None:
    """Set what the in-process Rerun SDK reads from the environment, before it is first imported:
    :data:`SDK_LOG_FILTER` unless ``RUST_LOG`` is set. Called once, by ``footnav.views``, which every
    footnav module that imports rerun belongs to."""
    os.environ.setdefault("RUST_LOG", SDK_LOG_FILTER)
