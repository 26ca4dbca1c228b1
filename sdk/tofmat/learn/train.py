# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Training a learned classifier on new capture sessions of a table's curves (:mod:`..evaluation.sessions`:
the session model with the calibration's spreads), drawn on the tuning side only: its seeds are not
the evaluation's test seed, so ``tofmat evaluate --model`` tests it on sessions it never saw.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .. import ExemplarTable
from .._extras import require
from .._progress import Progress
from ..evaluation.sessions import CurveSessions, calibrated_model, draw_queries
from .export import Network, to_onnx
from .features import features
from .model import ModelContract

TRAIN_SEED = 3003  # the tuning side's training draws (docs/evaluation.md: tune 1001, test 2002)
# Sweep lengths of the training draws, spread evenly in log length over what the box sees.
TRAIN_LENGTHS = (1, 2, 3, 4, 6, 8, 10, 13, 17, 23, 30, 40, 55, 75, 100)


@dataclass(frozen=True)
class Trained:
    network: Network
    contract: ModelContract
    samples: int
    epochs: int
    seconds: float
    validation_accuracy: float  # on the held-back tenth of the training draws (early stopping's)
    onnx: bytes
    check_max_abs: float  # largest |p_onnx - p_reference| on the check queries


def training_set(
    table: ExemplarTable,
    sessions_per_material: int,
    seed: int = TRAIN_SEED,
    sim_sessions_per_material: int = 0,
    progress: Progress | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(queries (N, R, B) float32, truth (N,)) on the tuning side: the table's curves in new
    sessions of the session model, and ``sim_sessions_per_material`` simulator sweeps rendered in
    new sessions (:mod:`..evaluation.sim_sessions`: other target angles than the table's, which the
    curves' session model lacks), against this table."""
    from ..evaluation.run import calibrated_json

    library, device = calibrated_json()
    cs = CurveSessions(table, calibrated_model(library, table), device, library)
    lengths = [n for n in TRAIN_LENGTHS if n <= table.n_bins]
    q = draw_queries(cs, lengths, sessions_per_material, seed)
    if sim_sessions_per_material == 0:
        return q.queries, q.truth
    from ..evaluation.sim_sessions import SimSessions, sim_session_model

    ss = SimSessions(None, sim_session_model(library), progress=progress, table=table)
    sim = ss.draw(lengths, sim_sessions_per_material, seed, progress)
    return np.concatenate([q.queries, sim.queries]), np.concatenate([q.truth, sim.truth])


def train(
    table: ExemplarTable,
    sessions_per_material: int = 150,
    hidden: tuple[int, ...] = (256, 256),
    seed: int = TRAIN_SEED,
    max_epochs: int = 200,
    progress: Progress | None = None,
    sim_sessions_per_material: int = 0,
) -> Trained:
    """Fits an MLP (scikit-learn, Adam, early stopping on a tenth of the draws) and exports it."""
    require("sklearn", extra="learn", feature="tofmat train")
    from sklearn.neural_network import MLPClassifier

    t0 = time.perf_counter()
    if progress:
        progress(0, 4, "drawing training sessions")
    queries, truth = training_set(table, sessions_per_material, seed, sim_sessions_per_material, progress)
    exemplars = table.features.astype(np.float32)
    x = features(queries, exemplars).astype(np.float64)
    mean = x.mean(axis=0)
    scale = x.std(axis=0)
    scale[scale < 1e-6] = 1.0  # a feature that never varies (a bin no curve reaches)
    if progress:
        progress(1, 4, f"training on {len(truth)} sweeps")
    mlp: Any = MLPClassifier(
        hidden_layer_sizes=hidden,
        early_stopping=True,
        max_iter=max_epochs,
        batch_size=256,
        alpha=1e-3,
        random_state=seed,
    )
    with warnings.catch_warnings():  # (stopping at max_epochs is reported by Trained.epochs)
        warnings.simplefilter("ignore", category=UserWarning)
        mlp.fit((x - mean) / scale, truth)
    net = Network.from_sklearn(mlp, exemplars, mean, scale)
    if progress:
        progress(2, 4, "fitting the confidence's temperatures")
    contract = replace(ModelContract.of_table(table), temperatures=temperatures(net, table))
    blob = to_onnx(net, contract, doc=f"tofmat MLP {hidden}, {len(truth)} training sweeps, seed {seed}")
    if progress:
        progress(3, 4, "checking the exported model")
    check = queries[:: max(1, len(queries) // 2000)]
    diff = check_export(blob, net, check, table)
    return Trained(
        net,
        contract,
        len(truth),
        int(mlp.n_iter_),
        time.perf_counter() - t0,
        float(max(mlp.validation_scores_)),
        blob,
        diff,
    )


def temperatures(
    net: Network, table: ExemplarTable, sessions_per_material: int = 10
) -> tuple[tuple[float, float], ...]:
    """The confidence's temperature at each of the evaluation's sweep lengths, fitted (Brier score)
    on the evaluation's tuning split, which the network was not trained on either, then made safe as
    the exemplar matchers' are (:func:`tofmat.evaluation.confidence.tail_safe`): raised until none of
    a length's tuning labels is wrong with a confidence of 0.9 or more at session spreads of
    :data:`tofmat.evaluation.run.TAIL_SCALES` times the calibration's."""
    from ..evaluation.confidence import fit_temperatures, tail_safe
    from ..evaluation.run import LENGTHS, SPLIT_SEEDS, TAIL_SCALES, calibrated_json
    from ..evaluation.sessions import scaled_model

    library, device = calibrated_json()
    base = calibrated_model(library, table)
    lengths = [n for n in LENGTHS if n <= table.n_bins]

    def scored(scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        cs = CurveSessions(table, scaled_model(base, scale), device, library)
        q = draw_queries(cs, lengths, sessions_per_material, SPLIT_SEEDS["tune"])
        with np.errstate(divide="ignore"):
            return -np.log(net.probabilities(q.queries)), q.truth, q.lengths

    fitted = fit_temperatures(*scored(1.0))
    safe = tail_safe(fitted, [scored(s) for s in TAIL_SCALES])
    return tuple((float(n), float(t)) for n, t in sorted(safe.items()))


def check_export(blob: bytes, net: Network, queries: np.ndarray, table: ExemplarTable) -> float:
    """The largest difference between the exported model's probabilities (onnxruntime) and the
    reference network's (NumPy, float64) on the same queries."""
    import tempfile
    from pathlib import Path

    from .model import LearnedClassifier

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "model.onnx"
        path.write_bytes(blob)
        p_onnx = LearnedClassifier(path, table).probabilities(queries)
    p_ref = net.probabilities(queries)
    return float(np.max(np.abs(p_onnx.astype(np.float64) - p_ref)))
