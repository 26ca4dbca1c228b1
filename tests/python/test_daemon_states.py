# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""What tofmatd says when it cannot label (issue 33): a table whose bins miss the target's depth is
reported (an `out_of_range` label, status's `target`, the log), `latest` never serves a label from
before a reload or a reset, and a bad source is refused before the socket listens."""

from __future__ import annotations

import shutil
import signal
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from conftest import Daemon

import tofmat
from tofmat.client import Label, daemon_binary, sim_data_dir

SCENE = "sim:static,material=cork,depth=900"


def far_table(sim_table: Path, path: Path) -> Path:
    """The simulated camera's table with its bins moved to 2000-3000 mm (the scene is at 900)."""
    t = tofmat.ExemplarTable.load(sim_table)
    moved = tofmat.ExemplarTable(t.materials, t.features, tofmat.BinSpec(2000.0, 1000.0 / t.n_bins, t.n_bins), t.rows)
    moved.save(path)
    return path


def wait_for(what: Callable[[], bool], seconds: float, why: str) -> None:
    deadline = time.monotonic() + seconds
    while not what():
        assert time.monotonic() < deadline, why
        time.sleep(0.05)


def test_a_reload_that_fits_no_target_says_so(start: Callable[..., Daemon], sim_table: Path, tmp_path: Path) -> None:
    live = tmp_path / "live.tmx"
    shutil.copy(sim_table, live)
    d = start(SCENE, table=live)
    with d.client() as c:
        c.subscribe("labels")
        assert next(iter(c.labels(timeout=30))).state == "tracking"
        assert c.status()["target"]["state"] == "in_range"
        far_table(sim_table, live)
        d.proc.send_signal(signal.SIGHUP)
        wait_for(lambda: c.status()["table"]["bin_start_mm"] == 2000.0, 20, "the reload was not taken")
        # The label stream says it once, the status and the log say why, and `latest` has no label
        # of the old table.
        event = c.next_event(10.0)
        while isinstance(event, Label) and event.state == "tracking":
            event = c.next_event(10.0)
        assert isinstance(event, Label) and event.state == "out_of_range" and event.material is None, event
        target = c.status()["target"]
        assert target["state"] == "out_of_range" and abs(target["depth_mm"] - 900) < 60, target
        assert "outside the table's bins (2000 to 3000 mm)" in target["reason"], target
        latest = c.latest_label()
        assert latest is not None and latest.state == "out_of_range", latest
        assert c.status()["last_reload"]["ok"] is True
    assert "outside the table's bins" in d.log.read_text()


def test_latest_forgets_the_label_of_before_a_reset(start: Callable[..., Daemon]) -> None:
    d = start(SCENE)
    with d.client() as c:
        for _ in range(5):
            wait_for(lambda: c.latest_label() is not None, 30, "no label")
            before = c.latest_label()
            assert before is not None
            c.reset()
            after = c.latest_label()  # none yet, or one made after the reset
            assert after is None or after.frame > before.frame, (before.frame, after.frame)


def test_a_bad_source_is_refused_before_the_socket_listens(tmp_path: Path, sim_table: Path) -> None:
    # The socket's folder does not exist: had the socket been opened first, that would be the error.
    p = subprocess.run([str(daemon_binary()), "--source", f"replay:{tmp_path / 'none.tmrec'}", "--table",
                        str(sim_table), "--socket", str(tmp_path / "no" / "d.sock"), "--sim-data", str(sim_data_dir())],
                       capture_output=True, text=True, timeout=60)  # fmt: skip
    assert p.returncode != 0 and "none.tmrec" in p.stderr + p.stdout, p.stderr


@pytest.mark.parametrize(("flag", "value"), [("--top-k", "0"), ("--burst", "301"), ("--smooth", "4")])
def test_the_profiles_flags_out_of_range_are_usage_errors(tmp_path: Path, sim_table: Path, flag: str,
                                                          value: str) -> None:  # fmt: skip
    p = subprocess.run([str(daemon_binary()), "--source", SCENE, "--table", str(sim_table), "--socket",
                        str(tmp_path / "d.sock"), flag, value], capture_output=True, text=True, timeout=60)  # fmt: skip
    assert p.returncode == 2 and flag in p.stderr, (p.returncode, p.stderr)


def test_a_candidate_given_twice_is_refused(tmp_path: Path, sim_table: Path) -> None:
    # (issue 33) as the SDK's Classifier refuses it
    p = subprocess.run([str(daemon_binary()), "--source", SCENE, "--table", str(sim_table), "--socket",
                        str(tmp_path / "d.sock"), "--sim-data", str(sim_data_dir()), "--candidates", "cork,cork"],
                       capture_output=True, text=True, timeout=60)  # fmt: skip
    assert p.returncode != 0 and '"cork" is given twice' in p.stderr + p.stdout, p.stderr
