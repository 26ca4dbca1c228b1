"""Shared fixtures of the Python test suite.

The real Kinect v2 database (29 materials) is the ground truth of the project: tests that
need it take the `db_dir` fixture, which FAILS (never skips) when the folder is missing so a
mis-configured CI run cannot pass silently.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

import tofmat

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
    return tofmat.Classifier(real_table, backend="float")


@pytest.fixture(scope="session")
def real_tmx(real_table: tofmat.ExemplarTable, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The real database saved once as a .tmx table file (read-only use: copy before damaging)."""
    path = tmp_path_factory.mktemp("tmx") / "tanaka2017.tmx"
    real_table.save(path)
    return path


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20170721)
