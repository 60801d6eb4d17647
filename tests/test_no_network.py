"""Issue 30: footnav and every Rerun process it starts make no name lookup and no connection outside
loopback, send no usage analytics and write nothing outside the folders they are given.

The commands run in a network namespace of their own (``unshare -rnm``, as root, the way CI runs:
``.ci/run``) whose only interface is loopback and whose resolver is a logger on 127.0.0.1:53 (a
``resolv.conf`` bind-mounted over ``/etc/resolv.conf``): every name asked is logged and refused, and
``strace -f -e trace=connect`` logs every connection tried, by footnav and by the viewer processes it
starts. ``HOME`` and ``TMPDIR`` are empty folders that must stay empty; the output folder must hold the
expected files only. The same probe, run on the bare viewer with an analytics config in ``HOME``, sees
``tel.rerun.io``, ``app.rerun.io`` and ``api.github.com`` asked (the issue's finding).

This module is also the probe: ``python tests/test_no_network.py SPEC.json`` inside the namespace.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any

import pytest

HERE = Path(__file__).resolve()
FOOTNAV = [sys.executable, "-m", "footnav.app"]
RERUN_CLI = Path(sys.executable).with_name("rerun")


# ------------------------------------------------------------------ the probe (inside the namespace)


def _dns_name(packet: bytes) -> str:
    """The first question's name of a DNS query (RFC 1035 section 4.1)."""
    labels, i = [], 12
    while i < len(packet) and packet[i]:
        n = packet[i]
        labels.append(packet[i + 1 : i + 1 + n].decode("ascii", "replace"))
        i += 1 + n
    return ".".join(labels)


def _refused(query: bytes) -> bytes:
    """The answer REFUSED (rcode 5) to ``query``: its id and question, no records."""
    flags = 0x8000 | (query[2] & 0x78) << 8 | 5
    return query[:2] + flags.to_bytes(2, "big") + query[4:6] + bytes(6) + query[12:]


def _resolver(names: list[str]) -> None:
    """Log and refuse every query sent to 127.0.0.1:53 (UDP), for ever (a daemon thread)."""
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    udp.bind(("127.0.0.1", 53))

    def serve() -> None:
        while True:
            data, addr = udp.recvfrom(4096)
            names.append(_dns_name(data))
            udp.sendto(_refused(data), addr)

    threading.Thread(target=serve, daemon=True).start()


def _traced_child(strace: subprocess.Popen[bytes]) -> int:
    """The pid of the command strace started (its first child)."""
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        for task in Path(f"/proc/{strace.pid}/task").iterdir():
            children = (task / "children").read_text().split()
            if children:
                return int(children[0])
        time.sleep(0.05)
    raise RuntimeError("strace started no command")


def _live_web(step: dict[str, Any], strace: subprocess.Popen[bytes], log: Path) -> dict[str, Any]:
    """Open the page ``footnav live --web`` prints (and the viewer's wasm), then Ctrl-C footnav."""
    deadline = time.monotonic() + 120
    url = None
    while url is None and time.monotonic() < deadline and strace.poll() is None:
        found = re.search(r"open (http://127\.0\.0\.1:\d+/\S+)", log.read_text())
        url = found.group(1) if found else None
        time.sleep(0.2)
    assert url is not None, log.read_text()
    base = url.split("/?")[0]
    fetched = {
        path: len(urllib.request.urlopen(base + path, timeout=30).read()) for path in ("/", "/re_viewer_bg.wasm")
    }
    time.sleep(step.get("walk_s", 4.0))
    os.kill(_traced_child(strace), signal.SIGINT)
    strace.wait(120)
    port = int(base.rsplit(":", 1)[1])
    with socket.socket() as s:
        still_served = s.connect_ex(("127.0.0.1", port)) == 0
    return {"fetched": fetched, "served_after": still_served}


def probe(spec_path: Path) -> None:
    """Run the steps of ``spec_path`` (JSON) in this namespace and write what each asked and tried."""
    spec = json.loads(spec_path.read_text())
    subprocess.run(["ip", "link", "set", "lo", "up"], check=True)
    work = Path(tempfile.mkdtemp(dir=spec["scratch"]))
    (work / "resolv.conf").write_text("nameserver 127.0.0.1\n")
    subprocess.run(["mount", "--bind", str(work / "resolv.conf"), "/etc/resolv.conf"], check=True)
    names: list[str] = []
    _resolver(names)
    results = []
    for i, step in enumerate(spec["steps"]):
        trace, log = work / f"connect-{i}.txt", work / f"log-{i}.txt"
        server = None
        argv = list(step["argv"])
        if step.get("emulated_unit"):
            from footnav.device.emulator.motion.gait import simulate_walk
            from footnav.device.emulator.serving.pty import PtyShoeServer

            walk = simulate_walk("rectangle", 60.0, seed=1)
            server = PtyShoeServer(walk.t_s, walk.acc_b_mps2, walk.gyr_b_radps, record=False)
            server.__enter__()
            argv = [server.port if a == "{port}" else a for a in argv]
        asked = len(names)
        with open(log, "w") as out:
            strace = subprocess.Popen(
                ["strace", "-f", "-qq", "-e", "trace=connect", "-o", str(trace), *argv],
                stdout=out,
                stderr=subprocess.STDOUT,
                env=spec["env"],
                cwd=spec["cwd"],
            )
            extra = _live_web(step, strace, log) if step.get("emulated_unit") else {}
            code = strace.wait(600)
        if server is not None:
            server.__exit__(None, None, None)
        inet = [line for line in trace.read_text().splitlines() if "AF_INET" in line]
        results.append({"code": code, "names": names[asked:], "connects": inet, "log": log.read_text(), **extra})
    Path(spec["result"]).write_text(json.dumps(results))


# ------------------------------------------------------------------ the tests


def _outbound(connects: list[str]) -> list[str]:
    """Connections tried to anything but loopback (IPv4 127.0.0.0/8, IPv6 ::1)."""
    loopback = re.compile(r'inet_addr\("127\.|inet_pton\(AF_INET6, "::1"')
    return [c for c in connects if not loopback.search(c)]


def _in_namespace(tmp: Path, steps: list[dict[str, Any]], env_extra: dict[str, str]) -> list[dict[str, Any]]:
    """Run ``steps`` through the probe in a fresh network and mount namespace; their results."""
    if shutil.which("unshare") is None:
        pytest.skip("no unshare on this machine: the test needs a network namespace of its own")
    for tool in ("strace", "ip"):
        assert shutil.which(tool), f"{tool} is needed inside the namespace (apt-get install strace iproute2)"
    scratch = tmp / "probe"
    scratch.mkdir()
    spec = {
        "steps": steps,
        "scratch": str(scratch),
        "result": str(tmp / "result.json"),
        "cwd": str(tmp / "out"),
        "env": {
            **{
                k: v
                for k, v in os.environ.items()
                if not k.startswith("XDG_") and k not in ("DISPLAY", "WAYLAND_DISPLAY")
            },
            **env_extra,
        },
    }
    (tmp / "spec.json").write_text(json.dumps(spec))
    proc = subprocess.run(
        ["unshare", "-rnm", sys.executable, str(HERE), str(tmp / "spec.json")],
        capture_output=True,
        text=True,
        timeout=900,
        check=False,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return list(json.loads((tmp / "result.json").read_text()))


def _files(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[list[dict[str, Any]], Path, Path, Path]:
    """demo (headless, saving a .rrd), replay and export of its capture, and live --web against the
    emulated unit, in one namespace, with an empty HOME and TMPDIR."""
    tmp = tmp_path_factory.mktemp("no-network")
    home, tmpdir, out = tmp / "home", tmp / "tmpdir", tmp / "out"
    for folder in (home, tmpdir, out):
        folder.mkdir()
    steps = [
        {"argv": [*FOOTNAV, "demo", "--duration", "10", "--pace", "max", "--save", "demo.rrd", "--sessions", "s"]},
        {"argv": ["sh", "-c", 'exec "$@" s/*.mcap --no-viewer --save replay.rrd', "sh", *FOOTNAV, "replay"]},
        {"argv": ["sh", "-c", 'exec "$@" s/*.mcap -o track.csv', "sh", *FOOTNAV, "export"]},
        {
            "argv": [*FOOTNAV, "live", "--port", "{port}", "--web", "--sessions", "live"],
            "emulated_unit": True,
            "walk_s": 4.0,
        },
    ]
    results = _in_namespace(tmp, steps, {"HOME": str(home), "TMPDIR": str(tmpdir)})
    return results, home, tmpdir, out


def test_no_name_is_looked_up_and_nothing_is_connected_to_outside_loopback(
    runs: tuple[list[dict[str, Any]], Path, Path, Path],
) -> None:
    results, _, _, _ = runs
    demo, replay, export, live = results
    for name, result in (("demo", demo), ("replay", replay), ("export", export)):
        assert result["code"] == 0, (name, result["log"])
    assert live["code"] == 130, live["log"]  # Ctrl-C
    for result in results:
        assert result["names"] == [], result["names"]
        assert _outbound(result["connects"]) == [], result["connects"]
    assert live["fetched"]["/re_viewer_bg.wasm"] > 1_000_000  # the web viewer was served and loaded
    assert any("127.0.0.1" in c for c in live["connects"])  # footnav streamed to it, on loopback


def test_the_web_viewer_stops_with_the_session(runs: tuple[list[dict[str, Any]], Path, Path, Path]) -> None:
    live = runs[0][3]
    assert "until the session ends" in live["log"]
    assert live["served_after"] is False


def test_nothing_is_written_outside_the_folders_named(runs: tuple[list[dict[str, Any]], Path, Path, Path]) -> None:
    _, home, tmpdir, out = runs
    assert _files(home) == [] and list(tmpdir.iterdir()) == []
    files = _files(out)
    assert {f.split("/")[0] for f in files} == {"demo.rrd", "replay.rrd", "track.csv", "s", "live"}
    assert len(files) == 5  # one capture each in s/ (demo) and live/


def test_the_bare_viewer_looks_up_outside_servers_and_footnavs_environment_stops_it(tmp_path: Path) -> None:
    """The viewer with a user's analytics config looks up Rerun's or GitHub's servers (which of them
    within its 15 s depends on timing: analytics are sent in batches); with ``rerun_environment`` and
    the viewer flags footnav uses it looks up none and writes nothing to HOME."""
    from footnav.views.rerun_env import VIEWER_FLAGS, private_folder, rerun_environment
    from footnav.views.sinks import viewer_binary

    if not Path("/usr/share/vulkan/icd.d/lvp_icd.x86_64.json").exists():
        pytest.skip("the headless native viewer needs software Vulkan (mesa-vulkan-drivers)")
    home, out = tmp_path / "home", tmp_path / "out"
    (home / ".config" / "rerun").mkdir(parents=True)
    out.mkdir()
    (home / ".config" / "rerun" / "analytics.json").write_text(
        json.dumps({"analytics_enabled": True, "analytics_id": "1" * 32, "metadata": {},
                    "config_file_path": str(home / ".config/rerun/analytics.json"),
                    "data_dir_path": str(home / ".local/share/rerun/analytics")})
    )  # fmt: skip
    viewer = ["timeout", "15", str(viewer_binary()), "--headless", "--bind", "127.0.0.1", "--port", "9876"]
    folder = private_folder()
    try:
        quiet = rerun_environment(folder, {"HOME": str(home), "PATH": os.environ["PATH"]})
        steps = [
            {"argv": viewer},
            {"argv": ["env", "-i", *[f"{k}={v}" for k, v in quiet.items()], *viewer, *VIEWER_FLAGS]},
        ]
        bare, footnavs = _in_namespace(tmp_path, steps, {"HOME": str(home)})
        (folder / "data").mkdir(exist_ok=True)
        analytics_data = _files(folder / "data")  # none: the config footnav writes was read
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    assert set(bare["names"]) & {"tel.rerun.io", "app.rerun.io", "api.github.com"}  # the probe sees lookups
    assert footnavs["names"] == [] and _outbound(footnavs["connects"]) == []
    assert analytics_data == []


if __name__ == "__main__":
    probe(Path(sys.argv[1]))
