# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""`tofmat demo`: tofmatd on the simulated camera, watched through the Python client.

Starts the daemon with ``--source sim:sweep`` (targets of a few materials moved by hand from 600 to
1200 mm, one after another), connects with ``tofmat.Client``, prints the label as it converges
during each sweep and the final one against the simulator's ground truth, then the accuracy, the
frame-to-client latency and the daemon's own figures, and stops the daemon.
"""

from __future__ import annotations

import signal
import subprocess
import tempfile
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..client import Client, DaemonUnavailableError, Label, daemon_binary, sim_data_dir


@dataclass
class DemoResult:
    sweeps: int = 0
    correct: int = 0  # final label of a sweep == its material
    labels: int = 0
    labels_correct: int = 0  # every label event while tracking
    latencies_ms: list[float] = field(default_factory=list)
    status: Mapping[str, object] = field(default_factory=dict)

    @property
    def accuracy(self) -> float:
        return 100.0 * self.correct / self.sweeps if self.sweeps else 0.0


def start_daemon(
    table: Path, socket: Path, source: str, log: Path, profile: str = "handheld", extra: list[str] | None = None
) -> subprocess.Popen[bytes]:
    cmd = [str(daemon_binary()), "--source", source, "--table", str(table), "--socket", str(socket),
           "--sim-data", str(sim_data_dir()), "--profile", profile, *(extra or [])]  # fmt: skip
    return subprocess.Popen(cmd, stdout=log.open("wb"), stderr=subprocess.STDOUT)


def connect(socket: Path, daemon: subprocess.Popen[bytes], timeout_s: float = 30.0) -> Client:
    """Waits for the daemon's socket (the simulator loads its profile first)."""
    deadline = time.monotonic() + timeout_s
    while True:
        if daemon.poll() is not None:
            raise RuntimeError(f"tofmatd exited with status {daemon.returncode} before it listened")
        try:
            return Client(socket)
        except DaemonUnavailableError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.1)


def stop_daemon_or_raise(daemon: subprocess.Popen[bytes], log: Path, echo: Callable[[str], None]) -> None:
    """Stops the daemon; if it did not stop cleanly, shows the end of its log and raises RuntimeError."""
    code = stop_daemon(daemon)
    if code != 0:
        echo(log.read_text(errors="replace")[-2000:])
        raise RuntimeError(f"tofmatd stopped with status {code} (log above)")


def stop_daemon(daemon: subprocess.Popen[bytes]) -> int:
    if daemon.poll() is None:
        daemon.send_signal(signal.SIGTERM)
        try:
            daemon.wait(10)
        except subprocess.TimeoutExpired:
            daemon.kill()
            daemon.wait()
    return daemon.returncode


def _describe(label: Label) -> str:
    """One line: the label, its score (Eq. (12)'s distance in mm^2, or the session matcher's score
    with its confidence) and the next two candidates."""
    others = ", ".join(f"{r.material} {r.distance:.2f}" for r in label.ranking[1:3])
    depth = f"{label.truth.depth_mm:6.0f} mm" if label.truth else ""
    # (unknown: no material explains the sweep; the nearest, for the eye)
    name = label.material or (f"unknown ({label.ranking[0].material}?)" if label.ranking else "unknown")
    if label.fit is None:  # Eq. (12)
        score = f"{label.distance:6.2f} mm^2"
    else:
        score = f"score {label.distance:7.2f} p {label.confidence or 0.0:.2f}"
    return f"frame {label.frame:5d} {depth} bins {label.bins_covered:3d}  {name:12s} {score}  ({others})"


def run_live_demo(
    table: Path,
    materials: list[str],
    frames: int,
    gap: int,
    echo: Callable[[str], None],
    classifier: str = "session",
) -> DemoResult:
    """``classifier``: tofmatd's ``--classifier`` (``session``, its default, or ``eq12``)."""
    result = DemoResult()
    with tempfile.TemporaryDirectory(prefix="tofmat-demo-") as tmp:
        socket, log = Path(tmp) / "tofmatd.sock", Path(tmp) / "tofmatd.log"
        source = f"sim:sweep,materials={'+'.join(materials)},frames={frames},gap={gap}"
        echo(f"starting tofmatd --source {source} --table {table} --classifier {classifier}")
        daemon = start_daemon(table, socket, source, log, extra=["--classifier", classifier])
        try:
            with connect(socket, daemon) as client:
                echo(
                    f"connected to {client.hello['server']} at {socket}; {len(materials)} hand-held sweeps, 600..1200 mm"
                )
                last: Label | None = None
                shown = ""
                for label in client.labels(timeout=30.0):
                    if label.state == "no_target":
                        if last is not None and last.truth is not None:
                            ok = last.material == last.truth.material
                            result.sweeps += 1
                            result.correct += ok
                            echo(f"  => {last.material or 'unknown'} after {last.bins_covered} bins; "
                                 f"truth {last.truth.material}: {'correct' if ok else 'WRONG'}")  # fmt: skip
                        last, shown = None, ""
                        if result.sweeps >= len(materials):
                            break
                        continue
                    if label.state not in ("tracking", "unknown") or label.truth is None or not label.truth.material:
                        continue
                    if last is None:
                        echo(f"sweep {result.sweeps + 1}: {label.truth.material}")
                    last = label
                    result.labels += 1
                    result.labels_correct += label.material == label.truth.material
                    result.latencies_ms.append(label.latency_ms)
                    if label.material != shown or label.bins_covered % 50 == 0:
                        echo("  " + _describe(label))
                        shown = label.material or ""
                result.status = client.status()
        finally:
            stop_daemon_or_raise(daemon, log, echo)
    lat = np.array(result.latencies_ms) if result.latencies_ms else np.zeros(1)
    s = result.status
    echo("")
    echo(f"accuracy: {result.correct}/{result.sweeps} sweeps labelled right at the end ({result.accuracy:.0f} %); "
         f"{result.labels_correct}/{result.labels} labels while tracking")  # fmt: skip
    echo(f"latency frame -> client: p50 {np.percentile(lat, 50):.1f} ms, p99 {np.percentile(lat, 99):.1f} ms "
         f"over {len(result.latencies_ms)} labels")  # fmt: skip
    echo(f"daemon: {s.get('frames_processed')} frames processed, {s.get('frames_dropped')} dropped, "
         f"{s.get('process_ms', 0.0):.2f} ms per frame (profile {s.get('profile')}, backend {s.get('backend')})")  # fmt: skip
    return result


__all__ = ["DemoResult", "connect", "run_live_demo", "start_daemon", "stop_daemon"]
