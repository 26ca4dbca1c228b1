# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Learned classifiers (docs/learned-models.md): the features and the ONNX graph against the NumPy
reference, `tofmat train`, the model contract's checks, the C++ fixture, and tofmatd running a model
through onnxruntime (on aarch64 too: `make cross-test` runs the board tests under qemu 10)."""

from __future__ import annotations

import math
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import Daemon

import tofmat
from tofmat.client import Label, daemon_binary
from tofmat.learn import LearnedClassifier, ModelContract
from tofmat.learn.export import Network
from tofmat.learn.features import features
from tofmat.learn.train import check_export, train, training_set

REPO = Path(__file__).resolve().parents[2]
FIXTURE = REPO / "tests" / "cpp" / "data" / "onnx"
DEPS = REPO / "build" / "deps" / "onnxruntime" / "lib"


def onnxruntime_library(aarch64: bool = False) -> Path:
    """The fetched library (mk/fetch-deps.sh onnxruntime, run by `make setup`) of an architecture."""
    lib = DEPS / ("aarch64" if aarch64 else "x86_64") / "libonnxruntime.so.1"
    assert lib.exists(), f"{lib} is missing: run mk/fetch-deps.sh onnxruntime"
    return lib


def the_daemons_library() -> Path:
    """The library for the tofmatd under test: aarch64's under `make cross-test`."""
    return onnxruntime_library(aarch64=bool(os.environ.get("TOFMAT_DAEMON_AARCH64")))


@pytest.fixture(scope="module")
def small_model(real_table: tofmat.ExemplarTable, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Any]:
    """A small network trained for the real table (a few seconds)."""
    t = train(real_table, sessions_per_material=5, hidden=(32,), max_epochs=30)
    path = tmp_path_factory.mktemp("model") / "small.onnx"
    path.write_bytes(t.onnx)
    return path, t


# --- the model and its export ---------------------------------------------------------------------


def test_the_fixture_is_what_its_script_writes(tmp_path: Path, db_dir: Path) -> None:
    p = subprocess.run([sys.executable, str(FIXTURE / "make_fixture.py"), str(db_dir), str(tmp_path)],
                       capture_output=True, text=True, timeout=120)  # fmt: skip
    assert p.returncode == 0, p.stderr
    # The models and the queries are seeded numbers written as they are: the same bytes anywhere.
    for name in ("tiny_mlp.onnx", "queries.npy", "saturated.onnx", "logits.onnx", "nan.onnx", "short.onnx"):
        assert (tmp_path / name).read_bytes() == (FIXTURE / name).read_bytes(), name
    # The reference probabilities come out of NumPy's matrix products, whose last bit depends on the
    # CPU the BLAS kernel was chosen for (CI machines differ by 1 ulp): equal to 1e-12, far inside
    # the 1e-5 that tofmatd's onnxruntime path is held to against them.
    got, want = np.load(tmp_path / "expected.npy"), np.load(FIXTURE / "expected.npy")
    assert got.dtype == want.dtype and got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=0.0)


def test_onnxruntime_computes_the_reference_network(real_table: tofmat.ExemplarTable) -> None:
    model = LearnedClassifier(FIXTURE / "tiny_mlp.onnx", real_table)
    q = np.load(FIXTURE / "queries.npy")
    want = np.load(FIXTURE / "expected.npy")
    got = model.probabilities(q)
    assert got.shape == want.shape == (8, 29)
    np.testing.assert_allclose(got, want, atol=2e-6)
    np.testing.assert_allclose(got.sum(axis=1), 1.0, atol=1e-6)
    # One at a time is the same as in a batch; a (R, B) query is the same as a flat one.
    np.testing.assert_allclose(model.probabilities(q[3].reshape(2, 200)), want[3:4], atol=2e-6)


def test_features_compare_the_query_with_every_curve() -> None:
    # Two materials, two rows, six bins; the second lacks bin 5 of row 0.
    t = np.array([[[0, 1, 2, 3, 4, 5], [5, 5, 5, 5, 5, 5]], [[0, 2, 4, 6, 8, np.nan], [1, 1, 1, 1, 1, 1]]],
                 dtype=np.float32)  # fmt: skip
    q = np.full((1, 2, 6), np.nan, dtype=np.float32)
    q[0, 0, 3:6] = [6.0, 7.0, 8.0]  # material 0's row 0 moved by +3 mm
    q[0, 1, 4] = 5.0
    f = features(q, t)[0]
    shape, offset, cover = f[:4].reshape(2, 2), f[4:8].reshape(2, 2), f[8:12].reshape(2, 2)
    np.testing.assert_allclose(shape[0], [0.0, 0.0], atol=1e-6)  # the right curve's shape, both rows
    np.testing.assert_allclose(offset[0], [3 / 5, 0.0], atol=1e-6)
    # Material 1 over bins 3 and 4 of row 0 (it lacks 5): differences 0 and -1, mean -0.5, variance 0.25.
    np.testing.assert_allclose(shape[1], [np.log(1.25), 0.0], atol=1e-6)
    np.testing.assert_allclose(offset[1], [-0.5 / 5, 4 / 5], atol=1e-6)
    np.testing.assert_allclose(cover, [[3 / 3, 1 / 3], [2 / 3, 1 / 3]], atol=1e-6)
    np.testing.assert_allclose(f[12:], [np.log(3.0), 4 / 6], atol=1e-6)  # 3 bins, centred on bin 4
    # A session's offset on a row moves only that row's offset feature.
    moved = features(q + np.array([2.0, 0.0], dtype=np.float32)[None, :, None], t)[0]
    np.testing.assert_allclose(np.delete(moved, [4, 6]), np.delete(f, [4, 6]), atol=1e-5)
    np.testing.assert_allclose(moved[[4, 6]], f[[4, 6]] + 2 / 5, atol=1e-5)


def test_train_exports_a_model_that_matches_the_network(
    small_model: tuple[Path, Any], real_table: tofmat.ExemplarTable
) -> None:
    path, t = small_model
    assert t.check_max_abs < 1e-4
    assert t.samples == 29 * 5 * 15 and 1 <= t.epochs <= 30
    model = LearnedClassifier(path, real_table)
    assert replace(model.contract, temperatures=()) == ModelContract.of_table(real_table)
    # The confidence's temperatures, fitted on the evaluation's tuning split, travel in the model.
    assert [n for n, _ in model.contract.temperatures] == [1.0, 3.0, 10.0, 30.0, 100.0]
    assert all(0 < t < 1000 for _, t in model.contract.temperatures)
    # On queries it never saw (another seed), the export still equals the network.
    queries, truth = training_set(real_table, 2, seed=99)
    assert check_export(t.onnx, t.network, queries, real_table) < 1e-4
    # A handful of training sessions already beats chance (1 in 29) on sessions it never saw.
    accuracy = float(np.mean(np.argmax(model.probabilities(queries), axis=1) == truth))
    assert accuracy > 2 / 29, accuracy  # twice chance (0.09 with these settings; 150 sessions give 0.5)


def test_training_adds_simulator_sessions(real_table: tofmat.ExemplarTable) -> None:
    names = ["cork", "paper", "wood"]
    idx = [real_table.materials.index(n) for n in names]
    three = tofmat.ExemplarTable(names, real_table.features[idx], real_table.bins, real_table.rows)
    curves_only, truth_only = training_set(three, 1)
    both, truth = training_set(three, 1, sim_sessions_per_material=1)
    assert len(curves_only) == 3 * 15 and np.array_equal(both[: len(curves_only)], curves_only, equal_nan=True)
    rendered = truth[len(truth_only) :]
    # One rendered session per material, one sweep of each length (a sweep with no valid frame is none).
    assert 3 * 12 <= len(rendered) <= 3 * 15 and set(rendered.tolist()) == {0, 1, 2}
    assert all(np.isfinite(q).any() for q in both[len(curves_only) :])
    odd = tofmat.ExemplarTable(["cork", "unobtainium"], real_table.features[idx[:2]], real_table.bins, real_table.rows)
    with pytest.raises(ValueError, match="no material unobtainium"):
        training_set(odd, 1, sim_sessions_per_material=1)


def test_a_model_runs_only_with_its_table(small_model: tuple[Path, Any], real_table: tofmat.ExemplarTable,
                                          tmp_path: Path) -> None:  # fmt: skip
    path, _ = small_model
    names = real_table.materials
    two = tofmat.ExemplarTable(names[:2], real_table.features[:2], real_table.bins, real_table.rows)
    with pytest.raises(ValueError, match="trained for the materials"):
        LearnedClassifier(path, two)
    moved = real_table.features.copy()
    moved[3, 0, 100] += 0.25
    with pytest.raises(ValueError, match="curves are not the ones"):
        LearnedClassifier(path, tofmat.ExemplarTable(names, moved, real_table.bins, real_table.rows))
    with pytest.raises(ValueError, match="not an ONNX model"):
        (tmp_path / "junk.onnx").write_bytes(b"not a model")
        LearnedClassifier(tmp_path / "junk.onnx")
    # An ONNX model without the contract's metadata is not a tofmat model.
    import onnx

    m = onnx.load(str(path))
    del m.metadata_props[:]
    (tmp_path / "bare.onnx").write_bytes(m.SerializeToString())
    with pytest.raises(ValueError, match="not a tofmat model"):
        LearnedClassifier(tmp_path / "bare.onnx")
    with pytest.raises(ValueError, match="elements"):
        LearnedClassifier(path).probabilities(np.zeros(7, dtype=np.float32))
    with pytest.raises(ValueError, match="infinite"):
        LearnedClassifier(path).probabilities(np.full(400, np.inf, dtype=np.float32))
    # Stiff: a finite element so large that float32's squares overflow is refused; at the bound
    # every probability is finite.
    q = np.full(400, np.nan, dtype=np.float32)
    q[[10, 210]] = -3e38
    with pytest.raises(ValueError, match="beyond"):
        LearnedClassifier(path).probabilities(q)
    q[[10, 210]] = 1e6
    assert np.isfinite(LearnedClassifier(path).probabilities(q)).all()


def test_the_contract_refuses_another_major_version() -> None:
    meta = ModelContract(("cork", "wood"), 2, (600.0, 3.0, 200)).metadata()
    assert ModelContract.from_metadata(meta).materials == ("cork", "wood")
    assert ModelContract.from_metadata({**meta, "tofmat.contract": "1.9"}).version == "1.9"
    with pytest.raises(ValueError, match=r"runs 1\.x"):
        ModelContract.from_metadata({**meta, "tofmat.contract": "2.0"})
    with pytest.raises(ValueError, match="malformed"):
        ModelContract.from_metadata({**meta, "tofmat.bins": "600 3"})


def test_classify_ranks_and_renormalises(real_table: tofmat.ExemplarTable) -> None:
    model = LearnedClassifier(FIXTURE / "tiny_mlp.onnx", real_table)
    q = np.load(FIXTURE / "queries.npy")[2]
    p = np.load(FIXTURE / "expected.npy")[2]
    ranking = model.classify(q)
    assert ranking[0][0] == real_table.materials[int(np.argmax(p))]
    assert math.isclose(sum(v for _, v in ranking), 1.0, abs_tol=1e-6)
    some = model.classify(q, ["cork", "wood"])
    total = p[real_table.materials.index("cork")] + p[real_table.materials.index("wood")]
    assert {n for n, _ in some} == {"cork", "wood"}
    assert math.isclose(dict(some)["cork"], p[real_table.materials.index("cork")] / total, rel_tol=1e-5)


def test_export_refuses_what_it_cannot_write() -> None:
    class Fake:
        activation = "tanh"
        classes_ = np.arange(3)

    with pytest.raises(ValueError, match="relu"):
        Network.from_sklearn(Fake(), np.zeros((3, 1, 1), dtype=np.float32), np.zeros(3), np.ones(3))
    Fake.activation = "relu"
    Fake.classes_ = np.array([0, 2, 3])
    with pytest.raises(ValueError, match="every material"):
        Network.from_sklearn(Fake(), np.zeros((3, 1, 1), dtype=np.float32), np.zeros(3), np.ones(3))


# --- tofmat train -----------------------------------------------------------------------------------


def run_cli(*args: object) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "tofmat", *map(str, args)], capture_output=True, text=True,
                          timeout=600)  # fmt: skip


def test_tofmat_train_writes_a_checked_model(real_tmx: Path, tmp_path: Path) -> None:
    out = tmp_path / "m.onnx"
    p = run_cli("train", "--table", real_tmx, "-o", out, "--sessions", "2", "--hidden", "8", "--epochs", "5")
    assert p.returncode == 0, p.stderr
    assert "export matches the network to" in p.stdout and "29 materials" in p.stdout
    assert LearnedClassifier(out, tofmat.ExemplarTable.load(real_tmx)).materials[0] == "acryl"
    before = out.read_bytes()
    p = run_cli("train", "--table", real_tmx, "-o", out, "--sessions", "2")
    assert p.returncode != 0 and "exists" in p.stderr and out.read_bytes() == before
    for bad in (["--hidden", "0"], ["--hidden", "a,b"], ["--sessions", "0"]):
        p = run_cli("train", "--table", real_tmx, "-o", tmp_path / "x.onnx", *bad)
        assert p.returncode == 2, (bad, p.stderr)
    assert not (tmp_path / "x.onnx").exists()
    p = run_cli("train", "--table", real_tmx, "-o", tmp_path / "no" / "such" / "m.onnx")
    assert p.returncode != 0 and "is not a folder" in p.stderr
    assert list(tmp_path.iterdir()) == [out]  # no temporary file left behind


def test_tofmat_evaluate_reports_the_model(small_model: tuple[Path, Any], db_dir: Path, tmp_path: Path) -> None:
    # (small_model was trained on the database's folder: its unquantised curves are the model's table)
    path, _ = small_model
    p = run_cli("evaluate", "--source", "curves", "--table", db_dir, "--sessions", "1", "--model", path, "--json")
    assert p.returncode == 0, p.stderr
    import json

    rows = json.loads(p.stdout)[0]["rows"]
    onnx = [r for r in rows if r["method"] == "onnx"]
    assert {r["split"] for r in onnx} == {"tune", "test"}
    for r in onnx:
        assert set(r["accuracy"]) == {"1", "3", "10", "30", "100"} and r["us_per_query"] > 0
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"junk")
    p = run_cli("evaluate", "--source", "curves", "--table", db_dir, "--sessions", "1", "--model", junk)
    assert p.returncode == 2 and "not an ONNX model" in p.stderr
    p = run_cli("evaluate", "--source", "sim", "--model", path)
    assert p.returncode == 2 and "trained for none of the evaluated tables" in p.stderr


def test_the_models_confidence_holds_when_sessions_move_more(
    small_model: tuple[Path, Any], real_table: tofmat.ExemplarTable, db_dir: Path
) -> None:
    # The temperatures train() stores are the Brier fit raised until no tuning label is wrong with a
    # confidence of 0.9 or more at 0 to 2 times the session spread (as the exemplar matchers').
    from tofmat.evaluation.confidence import fit_temperatures, probabilities
    from tofmat.evaluation.run import LENGTHS, SPLIT_SEEDS, TAIL_SCALES, calibrated_json
    from tofmat.evaluation.sessions import CurveSessions, calibrated_model, draw_queries, scaled_model

    path, t = small_model
    stored = dict(t.contract.temperatures)
    library, device = calibrated_json()
    base = calibrated_model(library, real_table)
    raised = 0
    for scale in TAIL_SCALES:
        q = draw_queries(CurveSessions(real_table, scaled_model(base, scale), device, library), list(LENGTHS), 10,
                         SPLIT_SEEDS["tune"])  # fmt: skip
        with np.errstate(divide="ignore"):
            scores = -np.log(t.network.probabilities(q.queries))
        if scale == 1.0:
            brier = fit_temperatures(scores, q.truth, q.lengths)
            assert all(stored[float(n)] >= brier[n] * (1 - 1e-9) for n in brier)
            raised = sum(stored[float(n)] > brier[n] * 1.5 for n in brier)
        for n in LENGTHS:
            sel = q.lengths == n
            p = probabilities(scores[sel], stored[float(n)])
            wrong = (np.argmax(p, axis=1) != q.truth[sel]) & (p.max(axis=1) >= 0.9)
            assert not wrong.any(), (scale, n, int(wrong.sum()))
    assert raised >= 1  # the Brier fit alone was too sharp somewhere
    # `tofmat evaluate --session-scales ... --model`: the model's rows beside the exemplar matchers', on
    # the test split (never tuned on), with its own temperatures.
    p = run_cli("evaluate", "--source", "curves", "--table", db_dir, "--session-scales", "0,2", "--sessions", "3",
                "--model", path, "--json")  # fmt: skip
    assert p.returncode == 0, p.stderr
    import json

    rows = json.loads(p.stdout)
    assert [(r["scale"], r["method"]) for r in rows] == [
        (s, m) for s in (0.0, 2.0) for m in ("eq12", "session", "onnx")
    ]
    for r in rows:
        assert r["queries"] == {str(n): 87 for n in LENGTHS}
        assert max(r["confidently_wrong"].values()) <= 3.5, r  # at most 3 of a length's 87 labels
    p = run_cli("evaluate", "--source", "curves", "--table", db_dir, "--session-scales", "2", "--model", path,
                "--model", path)  # fmt: skip
    assert p.returncode == 2 and "one --model" in p.stderr


def test_tofmat_evaluate_reports_a_model_on_the_simulators_table(tmp_path: Path, small_model: tuple[Path, Any]) -> None:
    # A simulated table of three materials, a model trained for it on simulator sweeps too, and the
    # simulator source evaluated against that table.
    table, model = tmp_path / "sim3.tmx", tmp_path / "sim3.onnx"
    recorded = run_cli("sim", "table", "--materials", "cork,paper,wood", "--calibration-sessions", "0", "-o", table)
    assert recorded.returncode == 0, recorded.stderr
    p = run_cli("train", "--table", table, "-o", model, "--sessions", "3", "--sim-sessions", "1", "--hidden", "16",
                "--epochs", "10")  # fmt: skip
    assert p.returncode == 0, p.stderr
    p = run_cli("evaluate", "--source", "sim", "--sim-table", table, "--sim-sessions", "1", "--model", model,
                "--json")  # fmt: skip
    assert p.returncode == 0, p.stderr
    import json

    (result,) = json.loads(p.stdout)
    assert result["materials"] == 3
    assert {(r["method"], r["split"]) for r in result["rows"]} >= {("onnx", "tune"), ("onnx", "test")}
    p = run_cli("evaluate", "--source", "sim", "--sim-table", table, "--sim-materials", "cork", "--model", model)
    assert p.returncode == 2 and "leave out --sim-materials" in p.stderr
    # At other session spreads and angles, beside the exemplar matchers, with its own temperatures.
    p = run_cli("evaluate", "--source", "sim", "--sim-table", table, "--sim-sessions", "1", "--session-scales", "0,2",
                "--yaws", "0", "--model", model, "--json")  # fmt: skip
    assert p.returncode == 0, p.stderr
    rows = json.loads(p.stdout)
    assert [(r["scale"], r["yaw_deg"], r["method"]) for r in rows] == [
        (s, 0.0, m) for s in (0.0, 2.0) for m in ("eq12", "session", "onnx")
    ]
    assert all(0.0 <= r["confidently_wrong"]["100"] <= 100.0 and r["queries"]["100"] == 3 for r in rows)
    # A model of other curves (the real table's) is refused for it, before anything is rendered.
    p = run_cli("evaluate", "--source", "sim", "--sim-table", table, "--session-scales", "2", "--model", small_model[0])
    assert p.returncode == 2 and str(small_model[0]) in p.stderr


# --- tofmatd ---------------------------------------------------------------------------------------


def onnx_flags(model: Path = FIXTURE / "tiny_mlp.onnx") -> list[str]:
    return ["--classifier", f"onnx:{model}", "--onnxruntime-library", str(the_daemons_library())]


@pytest.mark.board
def test_tofmatd_labels_with_a_model(start: Callable[..., Daemon], db_dir: Path) -> None:
    # The fixture was written for the database's folder (tofmatd reads it as a table too).
    d = start("sim:sweep,materials=cork+wood,frames=10,gap=3", *onnx_flags(), table=db_dir)
    materials = sorted(p.stem for p in db_dir.glob("*.npy"))
    with d.client() as c:
        s = c.status()
        assert s["classifier"] == "onnx" and s["model"] == str(FIXTURE / "tiny_mlp.onnx") and not s["open_set"]
        labels: list[Label] = []
        for e in c.labels(timeout=120):
            if e.state == "tracking":
                labels.append(e)
            if len(labels) == 8:
                break
    for e in labels:
        assert e.material in materials and e.fit is None and e.valid > 0
        # The confidence is the model's probability of the label over the candidates: exp(-distance).
        assert e.confidence is not None and math.isclose(e.confidence, math.exp(-e.distance), rel_tol=1e-6)
        assert [r.distance for r in e.ranking] == sorted(r.distance for r in e.ranking)
        assert e.ranking[0].material == e.material


@pytest.mark.board
def test_the_sorting_profile_labels_bursts_with_a_model(start: Callable[..., Daemon], db_dir: Path) -> None:
    # The sorting profile matches each burst and each of its frames (two matchers, one loaded model).
    d = start("sim:static,material=cork,depth=850,realtime=0", "--profile", "sorting", "--burst", "4", *onnx_flags(),
              table=db_dir)  # fmt: skip
    materials = sorted(p.stem for p in db_dir.glob("*.npy"))
    with d.client() as c:
        assert c.status()["classifier"] == "onnx"
        c.subscribe("labels")
        for _ in range(2):
            n = c.trigger()
            label = next(c.labels(timeout=60))
            assert label.trigger == n and label.state in ("final", "mixed"), label
            assert label.material in materials and label.confidence is not None


def _replay_labels(binary: Path, library: Path, recording: Path, table: Path, tmp_path: Path) -> list[Any]:
    """The labels of the second whole loop of a lossless replay through a model."""
    tmp_path.mkdir(exist_ok=True)
    sock, log = tmp_path / f"{binary.name}.sock", tmp_path / f"{binary.name}.log"
    cmd = [str(binary), "--source", f"replay:{recording},loop=1,pace=0", "--table", str(table), "--socket",
           str(sock), "--classifier", f"onnx:{FIXTURE / 'tiny_mlp.onnx'}", "--onnxruntime-library", str(library)]  # fmt: skip
    d = Daemon(subprocess.Popen(cmd, stdout=log.open("wb"), stderr=subprocess.STDOUT), sock, log)
    out: list[Any] = []
    try:
        with d.client() as c:
            loops, last = 0, -1
            for e in c.labels(timeout=300):
                if e.frame < last:
                    loops += 1
                    if loops == 3:
                        return out
                last = e.frame
                if loops == 2:
                    out.append((e.frame, e.state, e.material, e.valid, e.bins_covered, e.distance,
                                [(r.material, r.distance) for r in e.ranking]))  # fmt: skip
    finally:
        assert d.stop() == 0, log.read_text()
    raise AssertionError("unreachable")


@pytest.mark.board
def test_a_replay_through_a_model_gives_the_x86_labels(tmp_path: Path, db_dir: Path) -> None:
    # Under `make cross-test` daemon_binary() is the aarch64 tofmatd (under qemu 10) with aarch64's
    # onnxruntime, the reference the x86 one with x86's: the same recorded frames must give the same
    # labels, and probabilities equal to float32 rounding (the two libraries' kernels differ).
    rec = tmp_path / "two.tmrec"
    p = run_cli("record", "--source", "sim:sweep,materials=cork+pvc,frames=8,gap=2,realtime=0", "-o", rec,
                "--frames", "20")  # fmt: skip
    assert p.returncode == 0, p.stderr
    reference = Path(tofmat.client.__file__).parent / "bin" / "tofmatd"
    ours = _replay_labels(daemon_binary(), the_daemons_library(), rec, db_dir, tmp_path / "ours")
    theirs = _replay_labels(reference, onnxruntime_library(), rec, db_dir, tmp_path / "theirs")
    assert len(ours) == len(theirs) == 16 + 2
    for a, b in zip(ours, theirs, strict=True):
        assert a[:5] == b[:5]
        assert math.isclose(a[5], b[5], rel_tol=1e-4, abs_tol=1e-4)
        assert [m for m, _ in a[6]] == [m for m, _ in b[6]]
        assert all(math.isclose(x, y, rel_tol=1e-4, abs_tol=1e-4) for (_, x), (_, y) in zip(a[6], b[6], strict=True))


def test_a_table_the_model_does_not_fit_is_refused_on_reload(start: Callable[..., Daemon], db_dir: Path,
                                                            tmp_path: Path) -> None:  # fmt: skip
    served = tmp_path / "db"
    shutil.copytree(db_dir, served)
    d = start("sim:sweep,materials=cork+wood,frames=10,gap=3", *onnx_flags(), table=served)
    with d.client() as c:
        assert len(c.status()["table"]["materials"]) == 29
        for npy in served.glob("*.npy"):
            if npy.stem not in ("cork", "wood"):
                npy.unlink()
        d.proc.send_signal(signal.SIGHUP)
        deadline = time.monotonic() + 30
        while (s := c.status()).get("last_reload") is None:
            assert time.monotonic() < deadline, "no reload reported"
            time.sleep(0.1)
        assert s["last_reload"]["ok"] is False
        assert "the model knows 29 materials, the table 2" in s["last_reload"]["error"]
        assert s["classifier"] == "onnx" and len(s["table"]["materials"]) == 29  # the old table serves
        assert any(e.state == "tracking" for _, e in zip(range(60), c.labels(timeout=60), strict=False))


def test_tofmatd_refuses_a_table_with_other_curves(tmp_path: Path, real_tmx: Path) -> None:
    # The fixture was trained on the database's folder; the imported .tmx holds its curves quantised.
    sock = tmp_path / "s.sock"
    cmd = [str(daemon_binary()), "--source", "sim", "--socket", str(sock), "--table", str(real_tmx), *onnx_flags()]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert p.returncode != 0 and "curves are not the ones the model was trained on" in p.stdout + p.stderr


def test_tofmatd_refuses_a_model_it_cannot_run(tmp_path: Path, real_tmx: Path, db_dir: Path) -> None:
    def refusal(*args: object) -> str:
        cmd = [str(daemon_binary()), "--source", "sim", "--socket", str(tmp_path / "s.sock"), *map(str, args)]
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
        assert p.returncode != 0, p.stdout
        return p.stdout + p.stderr

    lib = str(the_daemons_library())
    assert "no such file" in refusal("--table", real_tmx, "--classifier", f"onnx:{tmp_path}/none.onnx",
                                     "--onnxruntime-library", lib).lower()  # fmt: skip
    assert "cannot load" in refusal("--table", real_tmx, "--classifier", f"onnx:{FIXTURE}/tiny_mlp.onnx",
                                    "--onnxruntime-library", tmp_path / "libnone.so").lower()  # fmt: skip
    two = tmp_path / "two.tmx"
    t = tofmat.ExemplarTable.load(real_tmx)
    tofmat.ExemplarTable(t.materials[:2], t.features[:2], t.bins, t.rows).save(two)
    assert "the model knows 29 materials, the table 2" in refusal(
        "--table", two, "--classifier", f"onnx:{FIXTURE}/tiny_mlp.onnx", "--onnxruntime-library", lib
    )
    assert "--open-set" in refusal("--table", real_tmx, "--classifier", f"onnx:{FIXTURE}/tiny_mlp.onnx",
                                   "--onnxruntime-library", lib, "--open-set")  # fmt: skip
    assert "onnx:FILE" in refusal("--table", real_tmx, "--classifier", "onnx:")
