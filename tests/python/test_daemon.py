# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""tofmatd end to end: the daemon on the simulated camera, the Python client over its socket.

Every test starts its own tofmatd (the binary shipped in the SDK) on a fresh socket and stops it
with SIGTERM, asserting a clean exit. Sources run with realtime=0 (frames as fast as the simulator
renders them), so nothing here waits on a 30 frames/s clock; timeouts are generous and only bound
a hung test.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import re
import shutil
import signal
import socket
import struct
import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import SIM_TABLE_MATERIALS as MATERIALS
from conftest import Daemon, final_labels

import tofmat
from tofmat.client import DeviceEvent, Label, LabelMap, daemon_binary, sim_data_dir


def sweep(materials: list[str], frames: int = 30, gap: int = 6, extra: str = "") -> str:
    return f"sim:sweep,materials={'+'.join(materials)},frames={frames},gap={gap},realtime=0{extra}"


# --- the main job --------------------------------------------------------------------------


@pytest.mark.board
def test_handheld_labels_match_the_simulators_truth(start: Callable[..., Daemon]) -> None:
    # (Not paper: plaster is its twin in the simulated camera's table, 0.18 mm rms apart, under
    # the live query's noise; tofmat bench-targets counts such labels as right among separable.)
    d = start(sweep(["cork", "polystyrene", "acryl", "pvc"]))
    with d.client() as c:
        labels = final_labels(c, 4)
        for label in labels:
            assert label.truth is not None and label.material == label.truth.material, label
            # One bin a frame (the region's surface at its mean depth): a 30-frame sweep of 600 mm.
            assert label.profile == "handheld" and label.bins_covered >= 25
            distances = [r.distance for r in label.ranking]
            assert distances == sorted(distances) and len(label.ranking) == 5
            assert label.ranking[0].material == label.material and label.distance == distances[0]
            assert label.latency_ms >= 0.0
            assert label.simulated  # a simulated source says so in every label
            # Protocol 1.7: a calibrated confidence, and the session matcher's fit (known: no unknown).
            assert label.confidence is not None and 0.0 < label.confidence <= 1.0
            assert label.fit is not None and math.isfinite(label.fit)
        assert sorted(label.material for label in labels) == ["acryl", "cork", "polystyrene", "pvc"]
        s = c.status()
        assert s["profile"] == "handheld" and s["backend"] == "fixed" and s["device"]["state"] == "streaming"
        assert s["classifier"] == "session"  # the default, as the SDK's Classifier
        assert s["simulated"] is True
        assert s["frames_processed"] > 0 and s["processing_errors"] == 0


def test_float_backend_agrees(start: Callable[..., Daemon]) -> None:
    d = start(sweep(["paper", "wood"]), "--backend", "float")
    with d.client() as c:
        assert c.status()["backend"] == "float"
        for label in final_labels(c, 2):
            assert label.truth is not None and label.material == label.truth.material


def test_the_eq12_classifier_labels_the_sweeps(start: Callable[..., Daemon]) -> None:
    # The simulator's table against its own sweeps (one session): the paper's Eq. (12), asked for
    # by name, is right too; it reports itself in status, its distance is the mean squared
    # difference (mm^2), and it has no noise model: no fit.
    d = start(sweep(["cork", "acryl"]), "--classifier", "eq12")
    with d.client() as c:
        s = c.status()
        assert s["classifier"] == "eq12" and s["backend"] == "fixed"
        for label in final_labels(c, 2):
            assert label.truth is not None and label.material == label.truth.material
            distances = [r.distance for r in label.ranking]
            assert distances == sorted(distances) and label.distance == distances[0] and label.distance >= 0.0
            assert label.confidence is not None and 0.0 < label.confidence <= 1.0
            assert label.fit is None


def test_the_open_set_calls_a_material_no_candidate_explains_unknown(start: Callable[..., Daemon]) -> None:
    # Copper swept against cork and paper only: whole sweeps end unknown (material none, index -1,
    # the nearest still ranked); without --open-set (the default) the nearest is the label.
    d = start(sweep(["copper"]), "--classifier", "session", "--open-set", "--candidates", "cork,paper")
    with d.client() as c:
        assert c.status()["open_set"] is True
        finals = final_labels(c, 2)
        for f in finals:
            assert f.state == "unknown" and f.material is None and f.index == -1, f
            assert {r.material for r in f.ranking} == {"cork", "paper"} and f.fit is not None and f.fit > 5
    closed = start(sweep(["copper"]), "--classifier", "session", "--candidates", "cork,paper", name="closed")
    with closed.client() as c:
        assert c.status()["open_set"] is False
        assert all(label.state != "unknown" for label in itertools.islice(c.labels(timeout=60), 60))


def test_the_session_matcher_learns_its_session_from_finished_sweeps(start: Callable[..., Daemon]) -> None:
    # The default: the simulated camera against its own table, a session that did not move. Each finished
    # sweep (the target leaving) teaches the learner; status reports it (protocol 1.10; where the
    # session moved, 1.12), and a reset with session=True starts the session again, a plain reset
    # does not.
    d = start(sweep(["cork", "polystyrene", "pvc"]))
    with d.client() as c:
        assert c.hello["minor"] >= 12
        start_state = c.status()["session"]
        # A session starts leaning on the calibration's own spread (scale 1).
        w = start_state["weights"]
        assert start_state["scales"][0] == 0.0 and start_state["scales"][w.index(max(w))] == 1.0
        labels = final_labels(c, 4)
        assert all(label.material == label.truth.material for label in labels if label.truth), labels
        learned = c.status()["session"]
        assert learned["sweeps"] >= 4
        assert learned["weights"][0] > 0.9 and learned["scale"] < 0.1, learned  # no session change
        assert abs(sum(learned["weights"]) - 1.0) < 1e-9
        # Where it moved: a row offset and two drift terms per table row, learned (not the zeros a
        # session starts with) and small (the simulated session did not move).
        rows = len(learned["offsets_mm"])
        assert rows == 2 and len(learned["drift_mm"]) == rows and all(len(d) == 2 for d in learned["drift_mm"])
        assert any(o != 0.0 for o in learned["offsets_mm"]), learned
        assert all(abs(o) < 1.0 for o in learned["offsets_mm"]), learned
        assert start_state["offsets_mm"] == [0.0] * rows
        c.reset()
        assert c.status()["session"]["sweeps"] >= learned["sweeps"]
        c.reset(session=True)
        again = c.status()["session"]
        assert again["sweeps"] < learned["sweeps"] and again["weights"][0] < 0.5
        if again["sweeps"] == 0:
            assert again["offsets_mm"] == [0.0] * rows
        with pytest.raises(tofmat.CommandError) as e:
            c._call("reset", {"session": "yes"})
        assert e.value.code == "invalid_argument" and "session" in str(e.value)
    plain = start(sweep(["cork"]), "--no-session-learning", name="plain")
    with plain.client() as c:
        assert "session" not in c.status()
    eq12 = start(sweep(["cork"]), "--classifier", "eq12", name="eq12")
    with eq12.client() as c:
        assert "session" not in c.status()


def test_depth_images_of_the_roi(start: Callable[..., Daemon]) -> None:
    d = start("sim:static,material=cork,depth=900,realtime=0")
    with d.client() as c:
        img = c.depth("combined", timeout=30)
        assert img.depth_mm.flags.writeable and img.depth_mm.dtype == np.float32
        assert img.depth_mm.shape == (48, 48) and (img.x0, img.y0) == (232, 188)
        # The camera's depth of cork is distorted by its subsurface scattering, by tens of mm at most.
        assert abs(float(np.nanmedian(img.depth_mm)) - 900.0) < 60.0
        img80 = c.depth("80", timeout=30)
        assert img80.kind == "80" and np.isfinite(img80.depth_mm).mean() > 0.9


# --- many clients, bad clients ---------------------------------------------------------------


@pytest.mark.board
def test_eight_clients_at_once(start: Callable[..., Daemon]) -> None:
    d = start(sweep(["cork", "paper"], frames=40, gap=4))
    clients = [d.client() for _ in range(8)]
    frames: list[set[int]] = [set() for _ in clients]
    for c in clients:
        c.subscribe("labels")

    def collect(i: int) -> None:
        for label in clients[i].labels(timeout=30):
            frames[i].add(label.frame)
            if len(frames[i]) >= 15:
                return

    threads = [threading.Thread(target=collect, args=(i,)) for i in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert all(len(f) >= 15 for f in frames)
    assert set.intersection(*frames), "the clients should see the same frames"
    s = clients[0].status()
    assert s["clients"]["clients"] == 8
    for c in clients:
        c.close()


def raw_connect(path: Path) -> socket.socket:
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.settimeout(10)
    s.connect(str(path))
    return s


def read_until_closed(s: socket.socket) -> bytes:
    data = b""
    while True:
        chunk = s.recv(65536)
        if not chunk:
            return data
        data += chunk


@pytest.mark.board
def test_garbage_closes_only_that_connection(start: Callable[..., Daemon]) -> None:
    d = start(sweep(["cork"], frames=30, gap=4))
    with d.client() as good:
        good.subscribe("labels")
        bad = raw_connect(d.socket)
        bad.sendall(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n")
        data = read_until_closed(bad)  # the daemon closes it (after its hello)
        assert data[:4] == b"TMAT"
        bad.close()
        assert next(good.labels(timeout=30)).frame >= 0
        assert good.status()["clients"]["protocol_errors"] >= 1


def test_oversized_length_is_refused_without_waiting_for_it(start: Callable[..., Daemon]) -> None:
    d = start(sweep(["cork"]))
    with d.client() as good:
        bad = raw_connect(d.socket)
        bad.sendall(b"TMAT" + struct.pack("<HBBI", 1, 2, 0, 0xFFFFFFF0))  # a 4 GB request
        read_until_closed(bad)
        assert good.status()["clients"]["protocol_errors"] >= 1


def test_client_killed_mid_message(start: Callable[..., Daemon], tmp_path: Path) -> None:
    d = start(sweep(["paper"], frames=30, gap=4))
    with d.client() as good:
        good.subscribe("labels")
        # Half a request, then the connection dies.
        half = raw_connect(d.socket)
        meta = json.dumps({"id": 1, "cmd": "hello", "args": {"protocol": 1}}).encode()
        msg = b"TMAT" + struct.pack("<HBBI", 1, 2, 0, 4 + len(meta)) + struct.pack("<I", len(meta)) + meta
        half.sendall(msg[: len(msg) // 2])
        half.close()
        # A subscribed client process killed while the daemon writes to it.
        script = (
            "import tofmat,sys\n"
            f"c = tofmat.Client({str(d.socket)!r}); c.subscribe('labels', 'depth:combined')\n"
            "print('ready', flush=True)\n"
            "import time; time.sleep(60)\n"
        )
        p = subprocess.Popen(["python3", "-c", script], stdout=subprocess.PIPE)
        assert p.stdout is not None and p.stdout.readline().strip() == b"ready"
        time.sleep(0.3)
        p.kill()
        p.wait()
        seen = [label.frame for label in itertools.islice(good.labels(timeout=30), 10)]
        assert len(seen) == 10
        assert good.status()["clients"]["clients"] == 1


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def test_tcp_needs_the_token(start: Callable[..., Daemon], tmp_path: Path) -> None:
    token = "s3cret-token-0123456789"
    (tmp_path / "token").write_text(token + "\n")
    (tmp_path / "token").chmod(0o600)
    port = free_port()
    d = start(sweep(["cork"]), "--tcp", f"127.0.0.1:{port}", "--token-file", str(tmp_path / "token"))
    with d.client() as local:  # the Unix socket needs none
        assert local.hello["auth_required"] is False
    address = f"127.0.0.1:{port}"
    with pytest.raises(tofmat.AuthenticationError):
        tofmat.Client(address)
    # The address waits before its next token is looked at (250 ms after one wrong token, then 500 ms).
    with pytest.raises(tofmat.AuthenticationError, match="too many wrong tokens"):
        tofmat.Client(address, token=token)
    time.sleep(0.3)
    with pytest.raises(tofmat.AuthenticationError, match="must send the daemon's token"):
        tofmat.Client(address, token="wrong-token-0123456789")
    time.sleep(0.6)
    with tofmat.Client(address, token=token) as c:
        assert c.hello["auth_required"] is True and c.role == "read"
        clients = c.status()["clients"]
        assert clients["auth_failures"] == 2 and clients["auth_throttled"] == 1


def test_tcp_readers_cannot_lock_the_control_token_out(start: Callable[..., Daemon], tmp_path: Path) -> None:
    # (issue 33) With a control token, reading hellos hold at most --max-tcp-clients less 4 slots
    # (half of it when fewer): the control token still gets in and controls.
    for name, token in (("read", "read-token-0123456789"), ("control", "control-token-0123456789")):
        (tmp_path / name).write_text(token + "\n")
        (tmp_path / name).chmod(0o600)
    port = free_port()
    d = start(sweep(["cork"]), "--tcp", f"127.0.0.1:{port}", "--token-file", str(tmp_path / "read"),
              "--control-token-file", str(tmp_path / "control"), "--max-tcp-clients", "8",
              "--max-clients-per-peer", "16")  # fmt: skip
    d.client().close()  # (listening)
    address = f"127.0.0.1:{port}"
    readers: list[tofmat.Client] = []
    refused = 0
    for _ in range(6):
        try:
            readers.append(tofmat.Client(address, token="read-token-0123456789", reconnect=False))
        except tofmat.DaemonUnavailableError as e:
            assert "kept for the control token" in str(e)
            refused += 1
    assert (len(readers), refused) == (4, 2)
    with tofmat.Client(address, token="control-token-0123456789", reconnect=False) as c:
        assert c.role == "control"
        c.reset()
        assert c.status()["clients"]["tcp_readers"] == 4
    for r in readers:
        r.close()


def test_tcp_without_a_token_file_is_refused_at_start(tmp_path: Path, sim_table: Path) -> None:
    p = subprocess.run([str(daemon_binary()), "--table", str(sim_table), "--socket", str(tmp_path / "s"),
                        "--tcp", "127.0.0.1:7020"], capture_output=True, text=True, timeout=30)  # fmt: skip
    assert p.returncode != 0 and "token" in p.stderr


@pytest.mark.board
def test_unplug_and_replug(start: Callable[..., Daemon]) -> None:
    d = start(sweep(["cork"], frames=30, gap=0, extra=",unplug_at=15,replug_ms=300"))
    with d.client() as c:
        c.subscribe("device", "labels")
        states: list[str] = []
        after: list[int] = []
        for e in c.events(timeout=30):
            if isinstance(e, DeviceEvent):
                states.append(e.state)
            elif isinstance(e, Label) and "disconnected" in states and states[-1] == "streaming":
                after.append(e.frame)
                if len(after) >= 5:
                    break
        assert "disconnected" in states and states[-1] == "streaming"
        s = c.status()
        assert s["source_counters"]["disconnects"] == 1 and s["source_counters"]["opens"] == 2


@pytest.mark.board
def test_sighup_with_a_corrupt_table_keeps_the_old_one(start: Callable[..., Daemon], sim_table: Path,
                                                       tmp_path: Path) -> None:  # fmt: skip
    table = tmp_path / "live.tmx"
    table.write_bytes(sim_table.read_bytes())
    d = start(sweep(["paper", "cork"]), table=table)
    with d.client() as c:
        before = c.status()["table"]["materials"]
        table.write_bytes(b"TMX1 this is not a table" * 10)
        d.proc.send_signal(signal.SIGHUP)
        deadline = time.monotonic() + 10
        while (c.status()["last_reload"] or {}).get("ok") is not False:
            assert time.monotonic() < deadline, "the reload was not reported"
            time.sleep(0.05)
        s = c.status()
        assert s["table"]["materials"] == before and "not" not in s["last_error"]
        assert next(c.labels(timeout=30)).state in ("tracking", "no_target")
        # A good table is taken on the next SIGHUP.
        t = tofmat.ExemplarTable.load(sim_table)
        keep = [t.index_of(m) for m in ("cork", "paper")]
        tofmat.ExemplarTable(["cork", "paper"], t.features[keep], t.bins, t.rows).save(str(table))
        d.proc.send_signal(signal.SIGHUP)
        while (c.status()["last_reload"] or {}).get("ok") is not True:
            assert time.monotonic() < deadline + 10
            time.sleep(0.05)
        assert c.status()["table"]["materials"] == ["cork", "paper"]


# --- commands and profiles --------------------------------------------------------------------


def test_commands_refuse_bad_input_and_keep_serving(
    start: Callable[..., Daemon], tmp_path: Path, sim_table: Path
) -> None:
    d = start(sweep(["cork"]))
    with d.client() as c:
        with pytest.raises(tofmat.CommandError) as e:
            c.set_roi(500, 0, 600, 10)
        assert e.value.code == "invalid_argument" and "x1" in str(e.value)
        with pytest.raises(tofmat.CommandError) as e:
            c.set_roi(300, 0, 200, 10)
        assert "empty or outside" in str(e.value)
        with pytest.raises(tofmat.CommandError):
            c.set_profile("juggling")
        with pytest.raises(tofmat.CommandError):
            c.set_candidates(["unobtainium"])
        with pytest.raises(tofmat.CommandError) as e:
            c.trigger()
        assert "sorting" in str(e.value)
        with pytest.raises(tofmat.CommandError) as e:
            c._call("dance")
        assert e.value.code == "unknown_command"
        (sim_table.parent / "junk.tmx").write_bytes(b"\0" * 100)  # (in the table directory)
        with pytest.raises(tofmat.CommandError) as e:
            c.load_table("junk.tmx")
        assert e.value.code == "failed"
        with pytest.raises(ValueError):
            c.subscribe("everything")
        s = c.status()
        assert s["profile"] == "handheld" and s["roi"] == [232, 188, 280, 236] and s["candidates"] == []
        c.set_candidates(["cork", "paper"])
        c.set_roi(200, 160, 312, 264)
        c.reset()
        s = c.status()
        assert s["candidates"] == ["cork", "paper"] and s["roi"] == [200, 160, 312, 264]
        label = next(lb for lb in c.labels(timeout=30) if lb.state == "tracking")
        assert {r.material for r in label.ranking} <= {"cork", "paper"}


@pytest.mark.board
def test_sorting_profile_labels_a_burst_per_trigger(start: Callable[..., Daemon]) -> None:
    # One depth, a few frames: m = 1 in effect, so a material whose curve no other one shares there.
    d = start("sim:static,material=acryl,depth=850,realtime=0", "--profile", "sorting", "--burst", "6")
    with d.client() as c:
        c.subscribe("labels")
        n = c.trigger()
        label = next(c.labels(timeout=30))
        assert label.trigger == n and label.state == "final" and label.material == "acryl"
        assert label.truth is not None and label.truth.material == "acryl"
        m = c.trigger(burst=3)
        assert m == n + 1
        assert next(c.labels(timeout=30)).trigger == m


@pytest.mark.board
def test_segmentation_label_map(start: Callable[..., Daemon]) -> None:
    # Three targets side by side at 700, 850 and 1000 mm (the regions scene's 3 x 1 grid).
    d = start("sim:regions,materials=acryl+cork+paper,near=700,far=1000,realtime=0", "--profile", "segmentation",
              "--candidates", "cork,paper,acryl")  # fmt: skip
    with d.client() as c:
        m = c.label_map(timeout=60)
        assert isinstance(m, LabelMap) and m.labels.shape == (424, 512) and m.labels.dtype == np.uint8
        assert m.labels.flags.writeable  # the caller's own copy
        assert sorted(m.materials) == ["acryl", "cork", "paper"]  # the candidates, in table order
        assert set(np.unique(m.labels)) <= {0, 1, 2, LabelMap.NO_LABEL}
        # One position per pixel (m = 1) is the weakest feature (the paper's 57 %): most pixels, not all.
        assert m.truth_accuracy is not None and m.truth_accuracy > 0.7
        for material, (x0, x1) in zip(("acryl", "cork", "paper"), ((16, 168), (180, 332), (344, 496)), strict=True):
            region = m.labels[32:204, x0:x1]
            labelled = region[region != LabelMap.NO_LABEL]
            assert np.bincount(labelled).argmax() == m.materials.index(material)
        assert (m.labels[:20] == LabelMap.NO_LABEL).all()  # nothing there: no label


def test_config_file_has_the_flags_keys(start: Callable[..., Daemon], tmp_path: Path) -> None:
    cfg = tmp_path / "tofmatd.toml"
    cfg.write_text('profile = "sorting"\nburst = 4\ncandidates = ["cork", "paper"]\nlog-level = "warn"\n')
    d = start("sim:static,material=cork,realtime=0", "--config", str(cfg))
    with d.client() as c:
        s = c.status()
        assert s["profile"] == "sorting" and s["candidates"] == ["cork", "paper"]


def test_bad_flags_are_refused(tmp_path: Path, sim_table: Path) -> None:
    base = [str(daemon_binary()), "--table", str(sim_table), "--socket", str(tmp_path / "s")]
    for args, word in ((["--profile", "nope"], "profile"), (["--source", "usb"], "source"),
                       (["--roi", "1,2,3"], "roi"), (["--candidates", "unobtainium"], "unobtainium"),
                       (["--source", "sim:sweep,materials=unobtainium"], "unobtainium"),
                       (["--log-level", "usb=debug"], "log category"), (["--log-level", "loud"], "log level"),
                       (["--classifier", "eq12", "--session-learning"], "--classifier session")):  # fmt: skip
        p = subprocess.run(base + args, capture_output=True, text=True, timeout=30)
        assert p.returncode != 0 and word in (p.stderr + p.stdout).lower(), (args, p.stderr)
    p = subprocess.run([str(daemon_binary()), "--table", str(tmp_path / "missing.tmx"), "--socket",
                        str(tmp_path / "s")], capture_output=True, text=True, timeout=30)  # fmt: skip
    assert p.returncode != 0 and "missing.tmx" in p.stderr


def test_log_levels_by_category(start: Callable[..., Daemon]) -> None:
    d = start("sim:static,material=cork,realtime=0", "--log-level", "server=debug,profile=info,*=warn")
    with d.client() as c:
        c.set_profile("segmentation")
        c.set_profile("handheld")
    d.stop()
    lines = d.log.read_text().splitlines()
    said = [line.split(" ", 2)[2] for line in lines]  # (after the date and the time)
    assert any(s.startswith("debug server: client 1 (") and "hello done, protocol 1." in s for s in said), said
    assert "info profile: profile segmentation" in said and "info profile: profile handheld" in said, said
    assert any(s.startswith("warning daemon: the source is SIMULATED") for s in said), said
    # Below the others' level (warn): the daemon's start and the source's states are not written.
    assert not any(" serving: " in s or s.startswith("info kinect: device") for s in said), said


# --- the client's errors and reconnection -----------------------------------------------------


def test_client_errors(tmp_path: Path) -> None:
    with pytest.raises(tofmat.DaemonUnavailableError):
        tofmat.Client(tmp_path / "nobody.sock")
    # A peer that accepts and never speaks; one that speaks another protocol version.
    silent = socket.socket(socket.AF_UNIX)
    silent.bind(str(tmp_path / "silent.sock"))
    silent.listen()
    with pytest.raises(tofmat.DaemonTimeoutError):
        tofmat.Client(tmp_path / "silent.sock", timeout=0.3)
    future = socket.socket(socket.AF_UNIX)
    future.bind(str(tmp_path / "future.sock"))
    future.listen()

    def serve() -> None:
        conn, _ = future.accept()
        meta = b'{"protocol":2}'
        conn.sendall(b"TMAT" + struct.pack("<HBBI", 2, 1, 0, 4 + len(meta)) + struct.pack("<I", len(meta)) + meta)
        time.sleep(1)
        conn.close()

    t = threading.Thread(target=serve)
    t.start()
    with pytest.raises(tofmat.ProtocolVersionError):
        tofmat.Client(tmp_path / "future.sock", timeout=5)
    t.join()
    assert issubclass(tofmat.DaemonUnavailableError, ConnectionRefusedError)
    assert issubclass(tofmat.AuthenticationError, tofmat.ClientError)


def test_client_reconnects_after_the_daemon_restarts(start: Callable[..., Daemon]) -> None:
    d1 = start(sweep(["cork"]), name="same")
    c = d1.client(reconnect_timeout=30.0)
    it = c.labels(timeout=30)
    first = next(it)
    assert d1.stop() == 0
    d2 = start(sweep(["paper"], frames=30, gap=0), name="same")
    later = next(lb for lb in it if lb.truth is not None and lb.truth.material == "paper")
    assert c.reconnects == 1 and later.frame >= 0 and first.frame >= 0
    c.close()
    assert d2.proc.poll() is None


# --- recordings -------------------------------------------------------------------------------


@pytest.mark.board
def test_record_and_replay(start: Callable[..., Daemon], tmp_path: Path, sim_table: Path) -> None:
    rec = tmp_path / "acryl.tmrec"
    p = subprocess.run(["python3", "-m", "tofmat", "record", "--source", "sim:static,material=acryl,depth=800,realtime=0",
                        "-o", str(rec), "--frames", "4"], capture_output=True, text=True, timeout=120)  # fmt: skip
    assert p.returncode == 0, p.stderr
    header = 8 + 12 + 3 * 512 * 424 * 4 + 9 * 4  # with the camera's intrinsics (flags bit 1)
    assert rec.stat().st_size == header + 4 * (20 + 9 * 512 * 424 * 2)
    assert rec.read_bytes()[16] == 0b11  # simulated, and the intrinsics follow the P0 tables
    d = start(f"replay:{rec},loop=1")
    with d.client() as c:
        label = next(lb for lb in c.labels(timeout=30) if lb.state == "tracking")
        assert label.material == "acryl" and label.truth is None  # a replay knows no truth
        # ... but a recording of the simulator stays simulated when it is played back.
        assert label.simulated
        s = c.status()
        assert s["source_counters"]["frames"] >= 1 and s["simulated"] is True
        assert s["source"].startswith("replay of a simulated recording")
    # A recording cut short in its header is refused with the reason.
    (tmp_path / "cut.tmrec").write_bytes(rec.read_bytes()[:1000])
    p = subprocess.run([str(daemon_binary()), "--source", f"replay:{tmp_path / 'cut.tmrec'}", "--table",
                        str(sim_table), "--socket", str(tmp_path / "s")], capture_output=True, text=True,
                       timeout=30)  # fmt: skip
    assert p.returncode != 0 and "shorter than its header" in p.stderr


def test_load_table_reads_only_regular_files_inside_the_table_directory(start: Callable[..., Daemon], tmp_path: Path,
                                                                         sim_table: Path) -> None:  # fmt: skip
    # issue 16, cases 2 and 3. The table directory is the folder of --table (sim_table's own folder).
    tables = tmp_path / "tables"
    tables.mkdir()
    (tables / "sim.tmx").write_bytes(sim_table.read_bytes())
    secret = tmp_path / "secret.tmx"
    secret.write_bytes(sim_table.read_bytes())
    (tables / "link.tmx").symlink_to(secret)
    os.mkfifo(tables / "fifo.tmx")
    many = tables / "many"
    many.mkdir()
    for i in range(256):
        np.save(many / f"m{i:03}.npy", np.zeros((2, 4), np.float32))
    d = start("sim:static,material=cork,realtime=0", table=tables / "sim.tmx")
    with d.client() as c:
        # Outside the directory: the same refusal whether the file exists or not.
        texts = []
        for name in (
            str(secret),
            str(tmp_path / "nothing.tmx"),
            "../secret.tmx",
            "../nothing.tmx",
            "link.tmx",
            "/etc/shadow",
        ):
            with pytest.raises(tofmat.CommandError) as e:
                c.load_table(name)
            assert e.value.code == "invalid_argument" and "not in the table directory" in str(e.value), str(e.value)
            texts.append(str(e.value).replace(name, "NAME"))
        assert len(set(texts)) == 1, texts
        # A FIFO is refused at once (it would block a plain open for ever), and the daemon serves on.
        t0 = time.monotonic()
        with pytest.raises(tofmat.CommandError) as e:
            c.load_table("fifo.tmx")
        assert e.value.code == "failed" and "regular file" in str(e.value) and time.monotonic() - t0 < 2.0
        # 256 materials: more than a label map can index, refused before any file is read.
        with pytest.raises(tofmat.CommandError) as e:
            c.load_table("many")
        assert "at most 255" in str(e.value)
        assert sorted(c.load_table("sim.tmx")) == sorted(MATERIALS)  # inside: loads


def test_a_corrupt_recording_fails_the_source_not_the_daemon(start: Callable[..., Daemon], tmp_path: Path) -> None:
    # issue 16, case 4: each corruption is an error in status (device state "failed", with the
    # reason) and in the log; the daemon keeps serving and stops cleanly (the fixture checks exit 0).
    rec = tmp_path / "good.tmrec"
    p = subprocess.run(["python3", "-m", "tofmat", "record", "--source", "sim:static,material=acryl,depth=800,realtime=0",
                        "-o", str(rec), "--frames", "3"], capture_output=True, text=True, timeout=120)  # fmt: skip
    assert p.returncode == 0, p.stderr
    data = rec.read_bytes()
    header, frame = 8 + 12 + 3 * 512 * 424 * 4 + 9 * 4, 20 + 9 * 512 * 424 * 2  # (the intrinsics' 36 bytes)
    marker = bytearray(data)
    marker[header + frame : header + frame + 4] = b"XXXX"  # the second frame's marker
    late = bytearray(data)
    late[header + frame + 12 : header + frame + 20] = (10**15).to_bytes(8, "little")  # its time: 11 days on
    cases = {"marker": (bytes(marker), "bad marker"), "time": (bytes(late), "not within 10 s"),
             "empty": (data[:header], "holds no frame")}  # fmt: skip
    for name, (content, reason) in cases.items():
        path = tmp_path / f"{name}.tmrec"
        path.write_bytes(content)
        d = start(f"replay:{path},loop=1,pace=1", name=name)
        with d.client() as c:
            deadline = time.monotonic() + 30
            while (s := c.status())["device"]["state"] != "failed":
                assert time.monotonic() < deadline, f"{name}: {s['device']}"
                time.sleep(0.05)
            assert reason in s["device"]["message"], s["device"]
        assert d.proc.poll() is None, f"{name}: tofmatd exited\n{d.log.read_text()}"
        assert reason in d.log.read_text()


def _request_bytes(request_id: int, cmd: str, args: dict[str, Any] | None = None) -> bytes:
    meta = json.dumps({"id": request_id, "cmd": cmd, "args": args or {}}).encode()
    return b"TMAT" + struct.pack("<HBBI", 1, 2, 0, 4 + len(meta)) + struct.pack("<I", len(meta)) + meta


def _stop_seconds(d: Daemon) -> float:
    """SIGTERM, and how long the daemon takes to exit (cleanly)."""
    t0 = time.monotonic()
    d.proc.send_signal(signal.SIGTERM)
    assert d.proc.wait(20) == 0, d.log.read_text()
    return time.monotonic() - t0


def test_sigterm_ends_the_daemon_within_a_second(start: Callable[..., Daemon], tmp_path: Path,
                                                 sim_table: Path) -> None:  # fmt: skip
    # issue 16: every blocking wait wakes on stop: a paced replay waiting 9 s for its next frame,
    # the camera missing (the retry loop), a reload whose table file became a FIFO, a client
    # pipelining requests without reading and a subscriber that does not read.
    rec = tmp_path / "slow.tmrec"
    p = subprocess.run(["python3", "-m", "tofmat", "record", "--source", "sim:static,material=acryl,depth=800,realtime=0",
                        "-o", str(rec), "--frames", "2"], capture_output=True, text=True, timeout=120)  # fmt: skip
    assert p.returncode == 0, p.stderr
    data = bytearray(rec.read_bytes())
    header, frame = 8 + 12 + 3 * 512 * 424 * 4, 20 + 9 * 512 * 424 * 2
    data[header + frame + 12 : header + frame + 20] = (9 * 10**9).to_bytes(8, "little")  # the second frame 9 s on
    rec.write_bytes(bytes(data))
    times: dict[str, float] = {}

    d = start(f"replay:{rec},pace=1", name="replay")
    with d.client() as c:
        while c.status()["source_counters"].get("frames", 0) < 1:
            time.sleep(0.05)
    time.sleep(0.3)  # (waiting for the second frame now)
    times["replay waiting 9 s"] = _stop_seconds(d)

    d = start("kinect", name="camera")
    with d.client() as c:
        assert c.status()["device"]["state"] in ("opening", "disconnected")
    times["camera missing"] = _stop_seconds(d)

    table = tmp_path / "reload.tmx"
    shutil.copy(sim_table, table)
    d = start("sim:static,material=cork,realtime=1", table=table, name="fifo")
    d.client().close()
    table.unlink()
    os.mkfifo(table)
    d.proc.send_signal(signal.SIGHUP)
    with d.client() as c:
        deadline = time.monotonic() + 10
        while not (r := c.status()["last_reload"]):
            assert time.monotonic() < deadline, "the reload did not end"
            time.sleep(0.05)
        assert r["ok"] is False and "regular file" in r["error"], r
    times["after a reload from a FIFO"] = _stop_seconds(d)

    d = start("sim:static,material=cork,realtime=1", name="clients")
    with d.client() as c:
        c.status()
    flood, mute = raw_connect(d.socket), raw_connect(d.socket)
    flood.sendall(_request_bytes(1, "hello", {"protocol": 1}))
    mute.sendall(_request_bytes(1, "hello", {"protocol": 1}) + _request_bytes(2, "subscribe", {"streams": ["labels"]}))
    flood.setblocking(False)
    burst = b"".join(_request_bytes(10 + k, "status") for k in range(64))
    for _ in range(200):
        try:
            flood.send(burst)
        except (BlockingIOError, ConnectionError):
            break
    times["a flood and a mute subscriber"] = _stop_seconds(d)
    flood.close()
    mute.close()
    assert all(t < 1.0 for t in times.values()), times


def _one_replay_loop(binary: Path, recording: Path, table: Path, tmp_path: Path, profile: str) -> list[Any]:
    """Every event of the second whole loop of a lossless replay (pace=0: no frame dropped), without
    timestamps: label fields, or a label map's bytes. (The first loop may start before the client listens.)"""
    sock, log = tmp_path / f"{binary.name}-{profile}.sock", tmp_path / f"{binary.name}-{profile}.log"
    cmd = [str(binary), "--source", f"replay:{recording},loop=1,pace=0", "--table", str(table), "--socket",
           str(sock), "--profile", profile]  # fmt: skip
    d = Daemon(subprocess.Popen(cmd, stdout=log.open("wb"), stderr=subprocess.STDOUT), sock, log)
    out: list[Any] = []
    try:
        with d.client() as c:
            c.subscribe("labels" if profile == "handheld" else "label_map")
            loops, last = 0, -1
            for e in c.events(timeout=300):
                assert isinstance(e, (Label, LabelMap))
                if e.frame < last:  # the replay went round again
                    loops += 1
                    if loops == 3:
                        return out
                last = e.frame
                if loops == 2 and isinstance(e, Label):
                    out.append((e.frame, e.state, e.material, e.index, e.distance, e.valid, e.bins_covered,
                                e.ranking, e.simulated))  # fmt: skip
                elif loops == 2 and isinstance(e, LabelMap):
                    out.append((e.frame, e.materials, e.labels.tobytes(), e.simulated))
    finally:
        assert d.stop() == 0, log.read_text()
    raise AssertionError("unreachable")


@pytest.mark.board
@pytest.mark.parametrize("profile", ["handheld", "segmentation"])
def test_a_replay_gives_the_same_labels_bit_for_bit_on_every_build(tmp_path: Path, sim_table: Path,
                                                                   profile: str) -> None:  # fmt: skip
    # Under `make cross-test` daemon_binary() is the aarch64 tofmatd (qemu) and the reference the x86 one
    # shipped in the SDK: the fixed-point path (NEON there, AVX2 or scalar here) and everything around it
    # must give the same labels from the same recorded frames. Natively both are the x86 daemon, and the
    # test asserts that a lossless replay is deterministic.
    rec = tmp_path / "two.tmrec"
    # (16 frames a sweep: 15 bins, what tells cork from wood, 0.2-0.7 mm apart, one bin a frame.)
    scene = "sim:sweep,materials=cork+pvc,frames=16,gap=3,realtime=0" if profile == "handheld" else \
        "sim:regions,materials=acryl+cork+paper,realtime=0"  # fmt: skip
    frames = 38 if profile == "handheld" else 3
    p = subprocess.run(["python3", "-m", "tofmat", "record", "--source", scene, "-o", str(rec), "--frames",
                        str(frames)], capture_output=True, text=True, timeout=120)  # fmt: skip
    assert p.returncode == 0, p.stderr
    reference = Path(tofmat.client.__file__).parent / "bin" / "tofmatd"
    ours = _one_replay_loop(daemon_binary(), rec, sim_table, tmp_path, profile)
    theirs = _one_replay_loop(reference, rec, sim_table, tmp_path, profile)
    assert ours == theirs
    if profile == "handheld":
        assert len(ours) == 32 + 2  # every target frame labelled, and one no_target per gap
        # The last label of each sweep (before its no_target) is the material swept; earlier ones converge.
        finals = [ours[i - 1][2] for i, e in enumerate(ours) if e[1] == "no_target" and i > 0]
        assert sorted(finals) == ["cork", "pvc"] and all(e[-1] for e in ours)
    else:
        assert len(ours) == frames and all(e[-1] for e in ours)


def test_without_a_source_the_daemon_uses_the_camera(tmp_path: Path, sim_table: Path) -> None:
    # A box that was misconfigured must never serve simulated labels: no --source means the Kinect
    # (none is attached here, so it says so and keeps trying), never the simulator.
    sock, log = tmp_path / "cam.sock", tmp_path / "cam.log"
    proc = subprocess.Popen([str(daemon_binary()), "--table", str(sim_table), "--socket", str(sock)],
                            stdout=log.open("wb"), stderr=subprocess.STDOUT)  # fmt: skip
    d = Daemon(proc, sock, log)
    try:
        with d.client() as c:
            deadline = time.monotonic() + 30
            while (s := c.status())["device"]["state"] != "disconnected":
                assert time.monotonic() < deadline, s
                time.sleep(0.1)
            assert s["source"].startswith("Kinect v2") and s["simulated"] is False
            assert s["device"]["message"] and s["frames_processed"] == 0
    finally:
        assert d.stop() == 0, log.read_text()


def test_simulator_data_is_found_beside_the_installed_program(tmp_path: Path, sim_table: Path) -> None:
    # A package installs tofmatd in <prefix>/sbin and the simulator's data in <prefix>/share/tofmat/sim;
    # nothing of the build machine is compiled in, so a lone copy of the program asks for --sim-data.
    if daemon_binary().read_bytes()[:4] != b"\x7fELF":
        pytest.fail(f"{daemon_binary()} is not the program itself (a wrapper): run this test natively")
    prefix = tmp_path / "usr"
    (prefix / "sbin").mkdir(parents=True)
    shutil.copy2(daemon_binary(), prefix / "sbin" / "tofmatd")
    shutil.copytree(sim_data_dir(), prefix / "share" / "tofmat" / "sim")
    sock, log = tmp_path / "inst.sock", tmp_path / "inst.log"
    proc = subprocess.Popen([str(prefix / "sbin" / "tofmatd"), "--source", "sim:static,material=cork,realtime=0",
                             "--table", str(sim_table), "--socket", str(sock)],
                            stdout=log.open("wb"), stderr=subprocess.STDOUT)  # fmt: skip
    d = Daemon(proc, sock, log)
    try:
        with d.client() as c:
            assert c.status()["simulated"] is True
            assert next(iter(c.labels(timeout=30))).simulated
    finally:
        assert d.stop() == 0, log.read_text()
    lone = tmp_path / "lone"
    lone.mkdir()
    shutil.copy2(daemon_binary(), lone / "tofmatd")
    p = subprocess.run([str(lone / "tofmatd"), "--source", "sim", "--table", str(sim_table), "--socket",
                        str(tmp_path / "lone.sock")], capture_output=True, text=True, timeout=30)  # fmt: skip
    assert p.returncode == 1 and "--sim-data" in p.stderr, p.stderr


def test_the_shipped_example_config_parses(start: Callable[..., Daemon]) -> None:
    example = Path(__file__).resolve().parents[2] / "firmware" / "daemon" / "tofmatd.toml"
    # It parses and the daemon runs with it; its source (kinect) loses to the flag's. (Its profile
    # and backend are the defaults, so they show nothing: test_config_file_has_the_flags_keys
    # checks that a file's keys take effect.)
    d = start("sim:static,material=cork,realtime=0", "--config", str(example))
    with d.client() as c:
        s = c.status()
        assert s["profile"] == "handheld" and s["backend"] == "fixed" and s["source"].startswith("simulated")


def test_every_flag_is_in_the_man_pages_and_the_example_config() -> None:
    # The references a user reads (tofmatd(8), tofmatd.toml(5), the shipped example) name every
    # flag tofmatd has; --help is the program's own list.
    repo = Path(__file__).resolve().parents[2]
    out = subprocess.run([str(daemon_binary()), "--help"], capture_output=True, text=True, timeout=30).stdout
    flags = set(re.findall(r"--([a-z][a-z0-9-]+)", out)) - {"help", "version"}
    assert {"control-group", "idle-timeout", "max-clients-per-peer", "control-token-file"} <= flags
    man8 = (repo / "docs" / "man" / "tofmatd.8").read_text().replace("\\-", "-")
    man5 = (repo / "docs" / "man" / "tofmatd.toml.5").read_text().replace("\\-", "-")
    example = (repo / "firmware" / "daemon" / "tofmatd.toml").read_text()
    for flag in sorted(flags):
        assert f"--{flag}" in man8, f"--{flag} is not in tofmatd(8)"
        if flag != "config":
            assert f".B {flag}\n" in man5, f"{flag} is not a key in tofmatd.toml(5)"
            assert re.search(rf"^#? ?{flag} = ", example, re.M), f"{flag} is not in the example config"


def test_watch_and_status_on_the_command_line(start: Callable[..., Daemon]) -> None:
    d = start(sweep(["paper"], frames=30, gap=4))
    d.client().close()  # listening
    p = subprocess.run(["python3", "-m", "tofmat", "watch", "--address", str(d.socket), "--count", "8"],
                       capture_output=True, text=True, timeout=120)  # fmt: skip
    assert p.returncode == 0, p.stderr
    lines = [ln for ln in p.stdout.splitlines() if ln.startswith("frame")]
    assert len(lines) == 8 and any("[truth paper]" in ln for ln in lines)
    assert "mm^2" in p.stdout or "(no target)" in p.stdout
    # For a program: one JSON object a line, the daemon first, then each label with the protocol's fields.
    p = subprocess.run(["python3", "-m", "tofmat", "watch", "--address", str(d.socket), "--count", "5", "--json"],
                       capture_output=True, text=True, timeout=120)  # fmt: skip
    assert p.returncode == 0, p.stderr
    objects = [json.loads(line) for line in p.stdout.splitlines()]
    assert objects[0]["event"] == "daemon" and objects[0]["profile"] == "handheld" and objects[0]["minor"] >= 9
    labels = [o for o in objects if o["event"] == "label"]
    assert len(labels) == 5 and all(o["profile"] == "handheld" and o["simulated"] for o in labels)
    assert all(isinstance(o["frame"], int) and isinstance(o["ranking"], list) for o in labels)
    assert any(o["truth"] and o["truth"]["material"] == "paper" for o in labels)
    p = subprocess.run(["python3", "-m", "tofmat", "status", "--address", str(d.socket)], capture_output=True,
                       text=True, timeout=60)  # fmt: skip
    assert p.returncode == 0 and json.loads(p.stdout)["profile"] == "handheld"
    p = subprocess.run(["python3", "-m", "tofmat", "watch", "--address", str(d.socket) + ".nobody"],
                       capture_output=True, text=True, timeout=60)  # fmt: skip
    assert p.returncode == 1 and "cannot connect" in p.stderr


def test_a_folder_of_npy_curves_is_a_table_with_the_databases_bins(start: Callable[..., Daemon], db_dir: Path) -> None:
    d = start("sim:static,material=cork,realtime=0", table=db_dir)
    expected = tofmat.ExemplarTable.from_npy_dir(db_dir)
    with d.client() as c:
        t = c.status()["table"]
        assert t["materials"] == expected.materials and t["bins"] == expected.bins.count
        assert t["bin_start_mm"] == expected.bins.start_mm
        assert abs(t["bin_width_mm"] - expected.bins.width_mm) < 1e-12


def test_the_live_demo_runs_either_classifier(sim_table: Path) -> None:
    # `tofmat demo --classifier`: tofmatd is started with it, says so in status, and the sweeps end right.
    from tofmat.tools.live_demo import run_live_demo

    for classifier in ("eq12", "session"):
        lines: list[str] = []
        r = run_live_demo(sim_table, ["cork", "acryl"], 40, 6, echo=lines.append, classifier=classifier)
        assert r.sweeps == 2 and r.correct == 2, lines
        assert r.status["classifier"] == classifier
        assert f"--classifier {classifier}" in lines[0]
        # Eq. (12)'s distance is in mm^2; the session matcher's score comes with its confidence.
        shown = [line for line in lines if line.startswith("  frame")]
        assert shown and all(("mm^2" in line) == (classifier == "eq12") for line in shown), lines
