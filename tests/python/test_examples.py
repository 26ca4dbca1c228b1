# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The scripts of examples/, each run as a user would run it: a subprocess against tofmatd on the
simulated camera (started by conftest's `start` fixture), or on the real database for the one that
needs no daemon. Each must do its job, stop by itself, and fail on an unreachable daemon or a
missing file with one line on stderr and a non-zero status, never a traceback.
"""

from __future__ import annotations

import os
import re
import struct
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO, Daemon
from conftest import SIM_TABLE_MATERIALS as MATERIALS

EXAMPLES = REPO / "examples"
STATIC_ACRYL = "sim:static,material=acryl,depth=850,realtime=0"


def run(script: str, *args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(EXAMPLES / script), *args], capture_output=True, text=True,
                          timeout=60, cwd=REPO, env={**os.environ, **(env or {})})  # fmt: skip


def ok(p: subprocess.CompletedProcess[str]) -> str:
    assert p.returncode == 0, f"exit {p.returncode}\n{p.stdout}\n{p.stderr}"
    return p.stdout


def assert_one_line_error(p: subprocess.CompletedProcess[str], text: str) -> None:
    assert p.returncode == 1, f"exit {p.returncode}\n{p.stdout}\n{p.stderr}"
    assert "Traceback" not in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert text in p.stderr, p.stderr


def listening(d: Daemon) -> str:
    d.client().close()
    return str(d.socket)


def test_watch_labels(start: Callable[..., Daemon]) -> None:
    address = listening(start(STATIC_ACRYL))
    out = ok(run("watch_labels.py", "--address", address, "--count", "5"))
    lines = re.findall(r"^frame +\d+: (\w+) [\d.]+ mm\^2, runner-up (\w+) [\d.]+ mm\^2.* \[truth (\w+)\]$", out, re.M)
    assert len(lines) == 5, out
    for material, runner_up, truth in lines:
        assert material == truth == "acryl" and runner_up in MATERIALS and runner_up != material
    # The address also comes from $TOFMAT_SOCKET, as for tofmat.Client.
    out = ok(run("watch_labels.py", "--count", "1", env={"TOFMAT_SOCKET": address}))
    assert len(re.findall(r"^frame .*acryl", out, re.M)) == 1, out


def test_segmentation_map(start: Callable[..., Daemon], tmp_path: Path) -> None:
    d = start("sim:regions,materials=acryl+cork+paper,near=700,far=1000,realtime=0", "--candidates", "cork,paper,acryl")
    address = listening(d)
    png = tmp_path / "map.png"
    out = ok(run("segmentation_map.py", "--address", address, "--png", str(png)))
    width, height, size = map(int, re.search(r"(\d+) x (\d+) = (\d+) pixels", out).groups())  # type: ignore[union-attr]
    counts = {name: int(n) for name, n in re.findall(r"^  (\S+(?: label\))?) +(\d+) +[\d.]+ %$", out, re.M)}
    assert (width, height, size) == (512, 424, 512 * 424) and sum(counts.values()) == size, out
    assert set(counts) == {"cork", "paper", "acryl", "(no label)"} and min(counts.values()) > 0, out
    assert "profile handheld -> segmentation" in out and "profile back to handheld" in out
    head = png.read_bytes()[:24]  # the PNG signature, then the IHDR chunk: width and height
    assert head[:8] == b"\x89PNG\r\n\x1a\n" and struct.unpack(">II", head[16:24]) == (512, 424)
    with d.client() as c:
        assert c.status()["profile"] == "handheld"
    # Without Pillow (which matplotlib needs too) the map is counted all the same and the PNG said not saved.
    hide = tmp_path / "hide"
    (hide / "PIL").mkdir(parents=True)
    (hide / "PIL" / "__init__.py").write_text("raise ImportError('hidden by the test')\n")
    out = ok(run("segmentation_map.py", "--address", address, "--png", str(tmp_path / "no.png"),
                 env={"PYTHONPATH": str(hide)}))  # fmt: skip
    assert "not saved: it needs Pillow" in out and not (tmp_path / "no.png").exists()
    assert_one_line_error(run("segmentation_map.py", "--address", address, "--expect"), "not segmentation")


def test_corrected_points(start: Callable[..., Daemon], tmp_path: Path) -> None:
    d = start("sim:regions,materials=acryl+cork+paper,near=700,far=1000,realtime=0", "--candidates", "cork,paper,acryl")
    out = ok(run("corrected_points.py", "--address", listening(d), "--npy", str(tmp_path / "pts")))
    rows = {m: (int(n), float(a), float(b), float(c)) for m, n, a, b, c in
            re.findall(r"^(\w+) +(\d+) +([\d.]+)mm +([\d.]+)mm +([+-][\d.]+)mm$", out, re.M)}  # fmt: skip
    assert sorted(rows) == ["acryl", "cork", "paper"], out
    for name, (n, measured, corrected, correction) in rows.items():
        assert n > 20_000 and abs(measured - corrected - correction) < 1.0, (name, out)
        assert 5.0 < abs(correction) < 100.0, (name, out)  # each material's own distortion, taken off
    points, labels = np.load(tmp_path / "pts_points.npy"), np.load(tmp_path / "pts_labels.npy")
    assert points.shape == (len(labels), 3) and len(labels) == sum(r[0] for r in rows.values())
    with d.client() as c:
        assert c.status()["profile"] == "handheld"  # switched back
    assert_one_line_error(run("corrected_points.py", "--address", str(tmp_path / "none.sock")), "none.sock")


def test_sorting_trigger(start: Callable[..., Daemon]) -> None:
    d = start(STATIC_ACRYL)
    address = listening(d)
    out = ok(run("sorting_trigger.py", "--address", address, "--count", "2", "--burst", "4"))
    decisions = re.findall(r"^trigger (\d+): (final|mixed|no_target) (\w+), distance .* \[truth (\w+)\]$", out, re.M)
    assert [(int(n), state) for n, state, _, _ in decisions] == [(1, "final"), (2, "final")], out
    assert all(material == truth == "acryl" for _, _, material, truth in decisions), out
    with d.client() as c:
        assert c.status()["profile"] == "handheld"
    assert_one_line_error(run("sorting_trigger.py", "--address", address, "--expect"), "not sorting")


@pytest.mark.parametrize("material", ["cork", "pvc"])
def test_classify_saved_query(db_dir: Path, real_tmx: Path, tmp_path: Path, material: str) -> None:
    query = tmp_path / "q.npy"
    out = ok(
        run("classify_saved_query.py", str(db_dir), "--make-demo-query", str(query), "--material", material,
            "--method", "eq12")
    )  # fmt: skip
    assert re.search(rf"^  1\. {material} +0\.0000 mm\^2  p ", out, re.M), out  # its own curve: distance 0
    q = np.load(query)
    assert q.shape == (2, 200) and np.isfinite(q).sum() == 20
    out = ok(run("classify_saved_query.py", str(real_tmx), str(query), "--top", "3"))  # the int16 table file
    ranking = re.findall(r"^  \d\. (\w+) ", out, re.M)
    assert len(ranking) == 3 and ranking[0] == material, out  # the session matcher, the default
    assert re.search(rf"^{material}: score .* confidence 0\.\d\d$", out, re.M), out


@pytest.mark.parametrize("script", ["watch_labels.py", "segmentation_map.py", "sorting_trigger.py"])
def test_an_unreachable_daemon_is_one_line(script: str, tmp_path: Path) -> None:
    p = run(script, "--address", str(tmp_path / "nobody.sock"))
    assert_one_line_error(p, "cannot connect to tofmatd")
    assert p.stdout == ""


def test_classify_saved_query_refuses_bad_files_in_one_line(db_dir: Path, tmp_path: Path) -> None:
    assert_one_line_error(run("classify_saved_query.py", str(tmp_path / "none.tmx"), "q.npy"), "none.tmx")
    wrong = tmp_path / "wrong.npy"
    np.save(wrong, np.zeros((3, 3), np.float32))
    assert_one_line_error(run("classify_saved_query.py", str(db_dir), str(wrong)), "shape (3, 3)")
    assert_one_line_error(run("classify_saved_query.py", str(db_dir), str(tmp_path / "none.npy")), "none.npy")
