"""A short soak with the benchmark's own harness: ``footnav live`` on two emulated feet in child processes."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.soak import run_soak


@pytest.mark.slow
def test_two_feet_soak_captures_every_byte_and_accounts_for_every_packet(tmp_path: Path) -> None:
    r = run_soak(1.0, tmp_path, drop_rate=0.002, bit_error_rate=1e-5, rss_every_s=0.5)
    assert r.footnav_code == 130, (tmp_path / "footnav.stderr").read_text()  # stopped by SIGINT, as Ctrl-C
    for foot, f in r.feet.items():
        assert f["capture_equals_sent"], foot  # the capture holds the wire's bytes, byte for byte
        assert f["emulator_packets"] >= 60_000
        assert f["dropped_or_corrupted"] > 0  # the faults happened ...
        assert f["accounted"], f  # ... and every packet is received once or counted lost
    assert r.ok
    assert r.peak_mb < 1000  # a sanity bound; the flatness figure is the benchmark's (README)
    assert r.rrd_mb > 0
