# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""`tofmat bench-daemon`: what each of tofmatd's profiles costs and reaches, on the simulated camera.

Per profile and number of clients: tofmatd on a 30 frames/s simulated camera, every client
subscribed; frame-to-client latency (p50, p99, from the frame's arrival in the daemon to the
client reading the event; one host, one CLOCK_MONOTONIC), the sustained processed frame rate,
frames dropped, the processing time per frame, and the accuracy against the simulator's truth:
handheld, the last label of each sweep; segmentation, the fraction of target pixels labelled
right; sorting, the label of each triggered burst.
"""

from __future__ import annotations

import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._progress import Progress
from ..client import Client, Label, LabelMap
from .live_demo import connect, start_daemon, stop_daemon

MATERIALS = "cork+pvc+wood+paper+acryl"
SCENES = {
    "handheld": f"sim:sweep,materials={MATERIALS},frames=60,gap=10",
    "segmentation": "sim:regions,materials=acryl+cork+paper,near=700,far=1000",
    "sorting": f"sim:sweep,materials={MATERIALS},frames=60,gap=10",
}
# A sorting line knows what can come down the belt: its candidates are the scene's materials.
EXTRA = {
    "segmentation": ["--candidates", "cork,paper,acryl"],
    "sorting": ["--burst", "8", "--candidates", MATERIALS.replace("+", ",")],
}


@dataclass
class ProfileRun:
    profile: str
    clients: int
    seconds: float
    events: int
    p50_ms: float
    p99_ms: float
    fps: float
    dropped: int
    process_ms: float
    accuracy: float  # percent
    accuracy_of: str


def _collect(client: Client, profile: str, until: float, out: list[tuple[float, bool | float | None]]) -> None:
    """(latency ms, correctness) per event until `until` (monotonic seconds)."""
    stream = "label_map" if profile == "segmentation" else "labels"
    client.subscribe(stream)
    last: Label | None = None
    for e in client.events(timeout=30):
        if time.monotonic() > until:
            return
        if isinstance(e, LabelMap):
            out.append((e.latency_ms, e.truth_accuracy))
        elif isinstance(e, Label):
            if profile == "handheld":
                # a sweep's outcome is its last label before the target leaves
                if e.state == "no_target":
                    ok = None if last is None else last.truth is not None and last.material == last.truth.material
                    out.append((e.latency_ms, ok))
                    last = None
                    continue
                last = e
                out.append((e.latency_ms, None))
            else:
                truth = e.truth.material if e.truth is not None else ""
                out.append((e.latency_ms, e.material == truth if truth else None))


def run_profile(table: Path, profile: str, n_clients: int, seconds: float) -> ProfileRun:
    with tempfile.TemporaryDirectory(prefix="tofmat-bench-") as tmp:
        sock = Path(tmp) / "tofmatd.sock"
        daemon = start_daemon(table, sock, SCENES[profile], Path(tmp) / "log", profile, EXTRA.get(profile))
        try:
            clients = [connect(sock, daemon) for _ in range(n_clients)]
            results: list[list[tuple[float, bool | float | None]]] = [[] for _ in clients]
            start = time.monotonic()
            until = start + seconds
            threads = [
                threading.Thread(target=_collect, args=(c, profile, until, r))
                for c, r in zip(clients, results, strict=True)
            ]
            for t in threads:
                t.start()
            control = connect(sock, daemon)
            s0 = control.status()
            while time.monotonic() < until:
                if profile != "sorting":
                    time.sleep(0.2)
                    continue
                # One item at a time: the next trigger once the burst's label has arrived.
                seen = len(results[0])
                control.trigger()
                while len(results[0]) == seen and time.monotonic() < until:
                    time.sleep(0.01)
                time.sleep(0.3)  # the belt moves the next item in
            for t in threads:
                t.join(60)
            s1 = control.status()
            elapsed = time.monotonic() - start
        finally:
            stop_daemon(daemon)
    lat = np.array([x[0] for r in results for x in r]) if any(results) else np.zeros(1)
    marks = [x[1] for x in results[0] if x[1] is not None]
    acc = float(np.mean([float(m) for m in marks])) * 100.0 if marks else float("nan")
    frames = int(s1["frames_processed"]) - int(s0["frames_processed"])
    return ProfileRun(
        profile=profile,
        clients=n_clients,
        seconds=round(elapsed, 1),
        events=len(lat),
        p50_ms=float(np.percentile(lat, 50)),
        p99_ms=float(np.percentile(lat, 99)),
        fps=frames / elapsed,
        dropped=int(s1["frames_dropped"]) - int(s0["frames_dropped"]),
        process_ms=float(s1["process_ms"]),
        accuracy=acc,
        accuracy_of={"handheld": "sweeps", "segmentation": "target pixels", "sorting": "bursts"}[profile]
        + f" (n={len(marks)})",
    )


def format_markdown(runs: list[ProfileRun]) -> str:
    lines = [
        "| profile | clients | latency p50 (ms) | p99 (ms) | frames/s | dropped | processing (ms/frame) | accuracy |",
        "|---|---:|---:|---:|---:|---:|---:|---|",
    ]
    for r in runs:
        lines.append(
            f"| {r.profile} | {r.clients} | {r.p50_ms:.1f} | {r.p99_ms:.1f} | {r.fps:.1f} | {r.dropped} | "
            f"{r.process_ms:.1f} | {r.accuracy:.1f} % of {r.accuracy_of} |"
        )
    return "\n".join(lines)


def bench_daemon(table: Path, profiles: list[str], clients: list[int], seconds: float,
                 progress: Progress | None = None) -> list[ProfileRun]:  # fmt: skip
    """Each profile with each number of clients; `progress` hears of every run."""
    for p in profiles:
        if p not in SCENES:
            raise ValueError(f"unknown profile {p!r}; one of {', '.join(SCENES)}")
    runs = []
    for p in profiles:
        for n in clients:
            r = run_profile(table, p, n, seconds)
            runs.append(r)
            if progress:
                progress(len(runs), len(profiles) * len(clients), f"{p} x{n}: {r.fps:.1f} frames/s")
    return runs
