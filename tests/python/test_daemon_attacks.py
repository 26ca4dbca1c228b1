# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Issue 16's attacks on tofmatd, each while a well-behaved subscriber is measured.

This runs tests/soak/daemon_attacks.py's bench for a few seconds an attack (the figures it prints are
benchmarks: `make bench-attacks`, docs/benchmarks.md) and asserts what must hold whatever the
machine's speed: the daemon lives through every attack; the subscriber keeps getting labels at the
camera's rate with no stall; the daemon's memory and log stay bounded; a new client still gets in;
and each attack gets what the daemon's rules give it (nothing, for the ones that want control).
Before issue 16's fixes a flood gave the subscriber no label for 10 s, idle connections locked
every new client out, and a reading client changed the profile.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

REPO = Path(__file__).resolve().parents[2]
HARNESS = REPO / "tests" / "soak" / "daemon_attacks.py"
SECONDS = 4

pytestmark = pytest.mark.skipif(os.geteuid() != 0, reason="the attackers run as other users: needs root (CI is root)")


@pytest.fixture(scope="module")
def bench(tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict[str, Any]]:
    out = tmp_path_factory.mktemp("attacks") / "bench.json"
    p = subprocess.run([sys.executable, str(HARNESS), "bench", "--seconds", str(SECONDS), "--json", str(out)],
                       capture_output=True, text=True, timeout=600)  # fmt: skip
    assert p.returncode == 0, p.stdout + p.stderr
    data = json.loads(out.read_text())
    assert data["exit_status"] == 0 and not data["deaths"], data["deaths"]
    rows = {r["attack"]: r for r in data["rows"]}
    print(p.stdout)  # (the table, for a failing run's log)
    return rows


# The scene gives a label for 30 of every 36 frames; a 4 s window holds 2 to 4 of its gaps (+-10 %).
LABELS_PER_FRAME = 30 / 36


def fewest_labels_per_second(camera_fps: float) -> float:
    """The least label rate a subscriber may see over a window in which the camera gave camera_fps."""
    return 0.85 * camera_fps * LABELS_PER_FRAME


ATTACKS = ["flood", "load_table", "big_folder", "second_daemon", "idle_slots", "tcp_unauth", "token_guess",
           "connect_close", "control"]  # fmt: skip


def gap_bound(stats: dict[str, Any], floor_ms: float) -> float:
    """The longest wait for a label a window may hold: floor_ms, or 50 ms past the camera's own
    longest frame interval where the camera itself came late (it renders inside tofmatd on the same
    cores; beside other work here it once took 140 ms between frames); either plus the longest time
    the harness itself was not run during that gap or the slowest label's wait (its stall witness:
    the subscriber is in the harness's process; on CI a window once waited 269 ms for a label with
    every latency in bound). A stall in serving exceeds it."""
    source = stats.get("source_gap_ms")  # (null: no two tracked frames in the window)
    camera = floor_ms if source is None else max(floor_ms, source + 50.0)
    return camera + stats["host_stall_ms"]


def figures(stats: dict[str, Any]) -> str:
    """The window's figures a gap or latency assertion turns on (pytest shortens a whole dict)."""
    keys = ("gap_ms", "source_gap_ms", "host_stall_ms", "raw_gap_ms", "max_ms", "p99_ms", "camera_fps", "rate")
    return ", ".join(f"{k} {stats.get(k)}" for k in keys)


def test_the_quiet_run_is_the_cameras_rate(bench: dict[str, dict[str, Any]]) -> None:
    quiet = bench["(quiet)"]["stats"]
    # The scene: a label for each frame with a target (30 of every 36 frames), at the rate the
    # simulated camera delivers: 30 frames/s (25 labels/s) when its renderer keeps up, less on a
    # slower machine (it renders on the same two cores: 16-27 frames/s measured here on 2026-11-28,
    # the daemon of before and after that day's change alike). So the labels are held to the
    # camera's own rate over the window (a 4 s window holds 2 to 4 of the scene's gaps: +-10 %).
    fps = quiet["camera_fps"]
    assert 10.0 <= fps <= 31.0, quiet
    assert fewest_labels_per_second(fps) <= quiet["rate"] <= 1.1 * fps * LABELS_PER_FRAME + 1.0, quiet
    assert quiet["missed_frames"] == 0, quiet
    assert quiet["gap_ms"] < gap_bound(quiet, 150.0), figures(quiet)


@pytest.mark.parametrize("attack", ATTACKS)
def test_a_subscriber_keeps_its_labels_while_the_attack_runs(bench: dict[str, dict[str, Any]], attack: str) -> None:
    quiet, row = bench["(quiet)"], bench[attack]
    s = row["stats"]
    assert not row["died"], row
    assert row["result"]["engaged"], f"{attack} never got to act: {row['headline']}"
    assert not row["changed"], f"{attack} changed the daemon's settings: {row['changed']}"
    # A label for every frame the camera gave (none missed, none dropped by the daemon), and no
    # stall (the flood stalled every subscriber for its whole 10 s before the fixes). The simulated
    # camera renders inside tofmatd on the same two cores as the attacker (and, under pytest -n 2,
    # beside another test): its own rate may sag, so the labels are held to the camera's rate over
    # the same window, and the camera to the quiet test's floor of 10 frames/s (a daemon the attack
    # starved would fall under it); docs/benchmarks.md has the measured figures.
    assert s["missed_frames"] == 0 and row["frames_dropped"] == 0, (attack, s, row["frames_dropped"])
    assert s["camera_fps"] >= 10.0, (attack, s)
    assert s["rate"] >= fewest_labels_per_second(s["camera_fps"]) - 1.0, (attack, s)
    assert s["gap_ms"] < gap_bound(s, 250.0), (attack, figures(s))
    assert s["max_ms"] < 250.0 + s["host_stall_ms"], (attack, figures(s))
    # Memory and log bounded: 240,976 warning lines in 15 s before the fixes.
    assert row["peak_rss_mb"] < quiet["peak_rss_mb"] + 32.0, (attack, row["peak_rss_mb"])
    assert row["log_lines_added"] < 120, (attack, row["log_lines_added"])
    assert row["fds_max"] <= row["fds_first"] + 48 + 16, (attack, row["fds_first"], row["fds_max"])
    # A new client gets in and has its status within 2 s, every time it tries.
    got, tried = (int(x) for x in row["fresh_client"].split(" ")[0].split("/"))
    assert got == tried and tried >= SECONDS - 1, (attack, row["fresh_client"])


def test_what_each_attack_got(bench: dict[str, dict[str, Any]]) -> None:
    counts = {name: bench[name]["result"]["counts"] for name in ATTACKS}
    server = {name: bench[name]["server"] for name in ATTACKS}
    # 1: the flood's requests are answered at its peer's rate, and the flooder is closed for not reading.
    assert server["flood"]["accepted"] >= 1
    # 2: a FIFO inside the table directory refused without waiting, every name leading outside
    # refused with one answer whether or not it exists.
    table = counts["load_table"]
    assert table.get("fifo_in:failed", 0) > 0 and "no_reply_5s" not in table and "accepted" not in table, table
    outside = ["fifo_out", "dotdot_shadow", "etc_shadow", "link_out", "link_fifo_out", "dotdot_file"]
    assert all(table.get(f"{name}:invalid_argument", 0) > 0 for name in outside), table
    # 3: a folder of 300 .npy files is not a table (255 materials at most).
    assert counts["big_folder"].get("failed", 0) > 0 and "accepted" not in counts["big_folder"], counts["big_folder"]
    # 5: no second daemon took the socket or removed it; the first answered all along.
    second = counts["second_daemon"]
    assert second["started"] == second.get("refused", 0) > 0, second
    assert not {"socket_file_replaced", "socket_file_removed", "still_running_10s"} & second.keys(), second
    assert second.get("first_answers", 0) == second["started"], second
    # 7a, 7b: another user's idle connections and unauthenticated TCP connections get their share only.
    assert server["idle_slots"]["rejected"] > 0 and server["tcp_unauth"]["rejected"] > 0
    # 7c: a guesser gets a handful of tokens looked at (250 ms, then 0.5, 1, 2 s ...), not thousands.
    assert server["token_guess"]["auth_failures"] <= 6, server["token_guess"]
    assert server["token_guess"]["auth_throttled"] > 10 * server["token_guess"]["auth_failures"]
    # 8: a reading client's control commands are all refused, on Unix and on TCP.
    accepted = {k: v for k, v in counts["control"].items() if k.endswith(":accepted")}
    assert not accepted, counts["control"]
    assert counts["control"].get("unix:permission", 0) > 0 and counts["control"].get("tcp:permission", 0) > 0
    assert server["control"]["not_permitted"] > 0


def test_the_stall_witness_sees_the_harness_stopped() -> None:
    # The bounds above forgive a stall of the harness's own process only as long as its witness saw:
    # stopped for 300 ms (SIGSTOP from outside, as a machine that does not run it), it must see that.
    spec = importlib.util.spec_from_file_location("daemon_attacks", HARNESS)
    assert spec is not None and spec.loader is not None
    harness = importlib.util.module_from_spec(spec)
    sys.modules["daemon_attacks"] = harness  # (its dataclasses look their module up)
    spec.loader.exec_module(harness)
    witness = harness.HostStallWitness()
    witness.start()
    try:
        t0 = time.monotonic()
        time.sleep(0.3)
        t1 = time.monotonic()
        pid = os.getpid()
        subprocess.run(["sh", "-c", f"kill -STOP {pid}; sleep 0.3; kill -CONT {pid}"], check=True, timeout=10)
        time.sleep(0.1)
        t2 = time.monotonic()
    finally:
        witness.stop()
    assert witness.longest_ms(t0, t1 - 0.05) < 250.0  # (running: late by scheduling only)
    assert 280.0 <= witness.longest_ms(t1, t2) < 2000.0, witness.stalls
