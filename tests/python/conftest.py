# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Shared fixtures of the Python test suite.

The real Kinect v2 database (29 materials) is the ground truth of the project: tests that
need it take the `db_dir` fixture, which FAILS (never skips) when the folder is missing so a
mis-configured CI run cannot pass silently.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import tofmat
from tofmat.client import Label, daemon_binary, sim_data_dir

REPO = Path(__file__).resolve().parents[2]
DEFAULT_DB_DIR = REPO.parent / "shared" / "data" / "tanaka2017_kinect2_db"


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers",
        "board: a daemon test that `make cross-test` also runs against the aarch64 tofmatd under qemu "
        "(TOFMAT_DAEMON=tests/cross/tofmatd-qemu)",
    )


@pytest.fixture(scope="session")
def db_dir() -> Path:
    """Folder of the real database: $TOFMAT_DB_DIR, else <repo>/../shared/data/tanaka2017_kinect2_db."""
    env = os.environ.get("TOFMAT_DB_DIR")
    path = Path(env) if env else DEFAULT_DB_DIR
    if not path.is_dir():
        pytest.fail(
            f"real database folder not found: {path} "
            f"({'from TOFMAT_DB_DIR' if env else 'default; set TOFMAT_DB_DIR to override'})",
            pytrace=False,
        )
    if not any(path.glob("*.npy")):
        pytest.fail(f"real database folder {path} holds no .npy file", pytrace=False)
    return path


@pytest.fixture(scope="session")
def db_files(db_dir: Path) -> dict[str, Path]:
    """material name -> .npy file of the real database."""
    return {p.stem: p for p in sorted(db_dir.glob("*.npy"))}


@pytest.fixture(scope="session")
def real_table(db_dir: Path) -> tofmat.ExemplarTable:
    return tofmat.ExemplarTable.from_npy_dir(db_dir)


@pytest.fixture(scope="session")
def real_clf(real_table: tofmat.ExemplarTable) -> tofmat.Classifier:
    return tofmat.Classifier(real_table, backend="float", method="eq12")


@pytest.fixture(scope="session")
def real_tmx(real_table: tofmat.ExemplarTable, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The real database saved once as a .tmx table file (read-only use: copy before damaging)."""
    path = tmp_path_factory.mktemp("tmx") / "tanaka2017.tmx"
    real_table.save(path)
    return path


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20170721)


# --- tofmatd: the simulated camera's table, and daemons started and stopped per test ---------

SIM_TABLE_MATERIALS = ["cork", "paper", "acryl", "pvc", "wood", "plaster", "mdf", "polystyrene"]


@pytest.fixture(scope="session")
def sim_table(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The simulated camera's own table of a few materials (tofmat sim table)."""
    from tofmat.sim import Renderer, load_device, load_library
    from tofmat.sim.table import database_bins, simulated_table

    r = Renderer(load_device(), load_library(), 1)
    t = simulated_table(r, SIM_TABLE_MATERIALS, database_bins())
    path = tmp_path_factory.mktemp("simtable") / "sim.tmx"
    t.save(str(path))
    return path


class Daemon:
    def __init__(self, proc: subprocess.Popen[bytes], socket_path: Path, log: Path) -> None:
        self.proc, self.socket, self.log = proc, socket_path, log

    def client(self, **kw: Any) -> tofmat.Client:
        deadline = time.monotonic() + 30.0
        while True:
            assert self.proc.poll() is None, f"tofmatd exited: {self.log.read_text()}"
            try:
                return tofmat.Client(self.socket, **kw)
            except tofmat.DaemonUnavailableError:
                assert time.monotonic() < deadline, "tofmatd did not listen within 30 s"
                time.sleep(0.05)

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            self.proc.wait(20)
        return self.proc.returncode


@pytest.fixture
def start(tmp_path: Path, sim_table: Path) -> Iterator[Callable[..., Daemon]]:
    started: list[Daemon] = []

    def _start(
        source: str, *args: str, table: Path | None = None, name: str = "d", socket_dir: Path | None = None
    ) -> Daemon:
        sock, log = (socket_dir or tmp_path) / f"{name}.sock", tmp_path / f"{name}.log"
        cmd = [str(daemon_binary()), "--source", source, "--table", str(table or sim_table), "--socket", str(sock),
               "--sim-data", str(sim_data_dir()), *args]  # fmt: skip
        d = Daemon(subprocess.Popen(cmd, stdout=log.open("wb"), stderr=subprocess.STDOUT), sock, log)
        started.append(d)
        return d

    yield _start
    for d in started:
        assert d.stop() == 0, f"tofmatd did not stop cleanly:\n{d.log.read_text()}"


def final_labels(client: tofmat.Client, sweeps: int, timeout: float = 60.0) -> list[Label]:
    """The last label (tracking, or unknown) of each of the next `sweeps` complete sweeps."""
    out: list[Label] = []
    last: Label | None = None
    started = False
    for label in client.labels(timeout=timeout):
        if label.state == "no_target":
            if started and last is not None:
                out.append(last)
                if len(out) == sweeps:
                    return out
            started, last = True, None  # sweeps counted from the first gap: whole sweeps only
        elif label.state in ("tracking", "unknown"):
            last = label
    raise AssertionError("unreachable")
