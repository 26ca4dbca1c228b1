# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Running a learned model (an ONNX file with the tofmat model contract) through onnxruntime.

The contract (docs/learned-models.md), the same in tofmatd (firmware/learn/model_contract.hpp):
input ``query``, float32 [batch, R x B], the depth-binned queries with NaN where a bin is missing;
output ``probabilities``, float32 [batch, M]; metadata ``tofmat.contract`` ("1.0"),
``tofmat.materials`` (names, one per line, in the table's order), ``tofmat.rows`` and
``tofmat.bins`` ("start_mm width_mm count").
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from .. import Calibration
from .. import ExemplarTable as Table
from .._extras import require

CONTRACT = "1.0"
INPUT = "query"
OUTPUT = "probabilities"
MAX_MODEL_BYTES = 64 << 20  # tofmatd refuses larger files (kMaxModelBytes)
# A query element beyond this (mm) is refused, as tofmatd does (kMaxQueryMm): past about 1e19 the
# features' squares overflow float32 and the probabilities become NaN.
MAX_QUERY_MM = 1e6
SMALLEST_SHARE = 2.0**-149  # a probability of 0 counts as the smallest float32, as in tofmatd

F32 = npt.NDArray[np.float32]
F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class ModelContract:
    """What a model says about the table it was trained for."""

    materials: tuple[str, ...]
    rows: int
    bins: tuple[float, float, int]  # start_mm, width_mm, count
    version: str = CONTRACT
    # (sweep length in bins, temperature) knots of the confidence (tofmat.Calibration); empty:
    # the model's own probabilities
    temperatures: tuple[tuple[float, float], ...] = ()
    # the CRC-32 of the curves trained on (curves_crc32()); None: not checked
    curves_crc32: int | None = None

    def metadata(self) -> dict[str, str]:
        start, width, count = self.bins
        out = {
            "tofmat.contract": self.version,
            "tofmat.materials": "\n".join(self.materials),
            "tofmat.rows": str(self.rows),
            "tofmat.bins": f"{start!r} {width!r} {count}",
        }
        if self.temperatures:
            out["tofmat.temperatures"] = " ".join(f"{n!r}:{t!r}" for n, t in self.temperatures)
        if self.curves_crc32 is not None:
            out["tofmat.curves_crc32"] = f"{self.curves_crc32:08x}"
        return out

    @classmethod
    def of_table(cls, table: Table) -> ModelContract:
        b = table.bins
        return cls(
            tuple(table.materials),
            table.n_rows,
            (float(b.start_mm), float(b.width_mm), int(b.count)),
            curves_crc32=curves_crc32(table),
        )

    @classmethod
    def from_metadata(cls, meta: Mapping[str, str]) -> ModelContract:
        """Raises ValueError naming a missing or malformed key, or a contract major version other
        than this one's."""
        try:
            version = meta["tofmat.contract"]
            names = meta["tofmat.materials"]
            rows = int(meta["tofmat.rows"])
            start, width, count = meta["tofmat.bins"].split()
            bins = (float(start), float(width), int(count))
            knots = [k.split(":") for k in meta.get("tofmat.temperatures", "").split()]
            temperatures = tuple((float(n), float(t)) for n, t in knots)
            if temperatures:
                Calibration(list(temperatures))  # validates them
            crc_text = meta.get("tofmat.curves_crc32")
            crc = None
            if crc_text is not None:
                if len(crc_text) != 8 or crc_text.strip("0123456789abcdef"):
                    raise ValueError(f"tofmat.curves_crc32 {crc_text!r} is not 8 lowercase hex digits")
                crc = int(crc_text, 16)
        except KeyError as e:
            raise ValueError(f"not a tofmat model: its metadata has no {e.args[0]!r} (docs/learned-models.md)") from e
        except ValueError as e:
            raise ValueError(f"a tofmat model with malformed metadata: {e}") from e
        if version.partition(".")[0] != CONTRACT.partition(".")[0]:
            raise ValueError(f"model contract {version}: this SDK runs {CONTRACT.partition('.')[0]}.x models")
        return cls(tuple(names.split("\n")), rows, bins, version, temperatures, crc)

    def check_table(self, table: Table) -> None:
        """Raises ValueError saying how the table differs from the one the model was trained for."""
        other = ModelContract.of_table(table)
        if (self.rows, self.bins[2]) != (other.rows, other.bins[2]):
            raise ValueError(
                f"the model takes {self.rows} x {self.bins[2]} queries, the table's are {other.rows} x {other.bins[2]}"
            )
        if not all(
            math.isclose(a, b, rel_tol=1e-6, abs_tol=1e-6) for a, b in zip(self.bins[:2], other.bins[:2], strict=True)
        ):
            raise ValueError("the model's depth bins are not the table's")
        if self.materials != other.materials:
            raise ValueError(
                f"the model was trained for the materials {list(self.materials)}, the table has {list(other.materials)}"
            )
        if self.curves_crc32 is not None and self.curves_crc32 != other.curves_crc32:
            raise ValueError(
                "the table's curves are not the ones the model was trained on (same materials and bins, other "
                "values: train the model on this table)"
            )


def curves_crc32(table: Table) -> int:
    """zlib's CRC-32 of the table's curves as little-endian float32, NaN as 0x7fc00000 (tofmatd's
    curves_crc32())."""
    bits = np.ascontiguousarray(table.features, dtype="<f4").view("<u4").copy()
    bits[np.isnan(table.features)] = 0x7FC00000
    return zlib.crc32(bits.tobytes())


class LearnedClassifier:
    """A learned model through onnxruntime (CPU, one thread), for one table."""

    def __init__(self, path: str | Path, table: Table | None = None) -> None:
        """Raises ValueError when the file is not a tofmat model, is too large, or was trained for
        another table than ``table``."""
        ort: Any = require("onnxruntime", extra="learn", feature="a learned classifier")
        p = Path(path)
        size = p.stat().st_size
        if size > MAX_MODEL_BYTES:
            raise ValueError(f"{p}: {size} bytes, over the {MAX_MODEL_BYTES} a model may have")
        options = ort.SessionOptions()
        options.intra_op_num_threads = 1
        options.inter_op_num_threads = 1
        try:
            self.session = ort.InferenceSession(p.read_bytes(), options, providers=["CPUExecutionProvider"])
        except Exception as e:  # onnxruntime raises its own exception types
            raise ValueError(f"{p}: not an ONNX model onnxruntime can run: {e}") from e
        meta = self.session.get_modelmeta().custom_metadata_map
        self.contract = ModelContract.from_metadata(meta)
        inputs = self.session.get_inputs()
        if [i.name for i in inputs] != [INPUT] or OUTPUT not in [o.name for o in self.session.get_outputs()]:
            raise ValueError(f"{p}: a tofmat model has one input {INPUT!r} and an output {OUTPUT!r}")
        if table is not None:
            self.contract.check_table(table)
        self.path = p
        temperatures = list(self.contract.temperatures) or [(1.0, 1.0)]
        self.calibration = Calibration(temperatures)  # the confidence's (tofmatd's RegionMatcher's)

    @property
    def materials(self) -> tuple[str, ...]:
        return self.contract.materials

    def probabilities(self, queries: npt.ArrayLike) -> F32:
        """(N, M) probabilities of N queries, each R x B (NaN = missing)."""
        q = np.asarray(queries, dtype=np.float32)
        elements = self.contract.rows * self.contract.bins[2]
        if q.size % elements or q.size == 0:
            raise ValueError(
                f"queries of {elements} elements ({self.contract.rows} x {self.contract.bins[2]}) expected"
            )
        q = q.reshape(q.size // elements, elements)
        if (np.abs(q[~np.isnan(q)]) > MAX_QUERY_MM).any():
            raise ValueError(f"a query element is beyond +-{MAX_QUERY_MM:g} mm (or infinite)")
        out = self.session.run([OUTPUT], {INPUT: q})[0]
        return np.asarray(out, dtype=np.float32)

    def scores(self, queries: npt.ArrayLike) -> F64:
        """-ln p: lower is better, as every matcher's score (tofmat evaluate)."""
        p = self.probabilities(queries).astype(np.float64)
        with np.errstate(divide="ignore"):
            return np.asarray(-np.log(p), dtype=np.float64)

    def classify(self, query: npt.ArrayLike, candidates: Sequence[str] | None = None) -> list[tuple[str, float]]:
        """One query's ranking: (material, confidence) best first, as tofmatd computes it: the
        distance -ln p of the model's probabilities renormalised over ``candidates`` (default: every
        material; a probability of 0 counts as 2^-149), and the confidence softmax(-distance / T)
        with the temperature the model's metadata gives for the sweep's length (observed elements
        over rows)."""
        from ..evaluation.confidence import probabilities

        q = np.asarray(query, dtype=np.float32)
        p = self.probabilities(q[None])[0].astype(np.float64)
        names = list(self.materials)
        for c in candidates or []:
            if c not in names:
                raise ValueError(f"{c!r} is not a material of the model")
        keep = list(range(len(names))) if candidates is None else [names.index(c) for c in candidates]
        total = float(p[keep].sum())
        share = p[keep] / total if total > 0 else np.full(len(keep), 1.0 / len(keep))
        distance = -np.log(np.maximum(share, SMALLEST_SHARE))
        t = self.calibration.temperature(float(np.isfinite(q).sum()) / self.contract.rows)
        conf = probabilities(distance[None], t)[0]
        order = sorted(range(len(keep)), key=lambda k: (distance[k], keep[k]))
        return [(names[keep[k]], float(conf[k])) for k in order]
