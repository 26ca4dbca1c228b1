# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Classify a saved partial query against an exemplar table, without a daemon.

A query is an .npy array of the table's shape (rows x depth bins, float32), NaN where nothing was
observed; tofmat.Classifier matches it (the session-robust matcher, or Eq. (12) with --method eq12)
and ranks every material with its probability. --make-demo-query
first writes such a query, cut from the table's own curve of --material over a few bins:

    python examples/classify_saved_query.py ../shared/data/tanaka2017_kinect2_db \\
        --make-demo-query cork.npy --material cork
    python examples/classify_saved_query.py tanaka2017.tmx cork.npy --top 3
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import numpy.typing as npt

import tofmat


def open_table(path: Path) -> tofmat.ExemplarTable:
    """A folder of <material>.npy curves (the database's layout) or a .tmx table file."""
    return tofmat.ExemplarTable.from_npy_dir(path) if path.is_dir() else tofmat.ExemplarTable.load(path)


def demo_query(table: tofmat.ExemplarTable, material: str, n_bins: int) -> tuple[npt.NDArray[np.float32], range]:
    """The table's curves of `material` over `n_bins` bins in the middle of its observed ones, NaN elsewhere."""
    if material not in table.materials:
        raise ValueError(f"{material!r} is not in the table; one of {', '.join(table.materials)}")
    curve = table.features[table.materials.index(material)]
    observed = np.flatnonzero(np.isfinite(curve).all(axis=0))
    if observed.size == 0:
        raise ValueError(f"the table has no observed bin for {material}")
    start = int(observed[max(0, observed.size // 2 - n_bins // 2)])
    bins = range(start, min(start + n_bins, table.n_bins))
    query = np.full((table.n_rows, table.n_bins), np.nan, np.float32)
    query[:, bins.start : bins.stop] = curve[:, bins.start : bins.stop]
    return query, bins


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("table", type=Path, help="a .tmx table or a folder of <material>.npy curves")
    parser.add_argument("query", type=Path, nargs="?", help="the query .npy (rows x bins, NaN = missing)")
    parser.add_argument(
        "--make-demo-query", type=Path, metavar="OUT.npy", help="write a demo query here and classify it"
    )
    parser.add_argument("--material", help="the demo query's material (default: the table's first)")
    parser.add_argument("--bins", type=int, default=10, help="depth bins in the demo query (default %(default)s)")
    parser.add_argument("--top", type=int, default=5, help="ranking entries shown (default %(default)s)")
    parser.add_argument("--method", choices=["session", "eq12"], default="session",
                        help="the matcher (default %(default)s; eq12: the paper's distance, mm^2)")  # fmt: skip
    args = parser.parse_args(argv)
    if (args.query is None) == (args.make_demo_query is None):
        parser.error("give a query .npy or --make-demo-query OUT.npy")

    try:
        table = open_table(args.table)
        print(f"table {args.table}: {len(table.materials)} materials, {table.n_rows} rows x {table.n_bins} bins")
        if args.make_demo_query is not None:
            material = args.material or table.materials[0]
            query, bins = demo_query(table, material, args.bins)
            np.save(args.make_demo_query, query)
            edges = table.bin_edges_mm
            print(f"wrote {args.make_demo_query}: {material} in bins {bins.start}..{bins.stop - 1} "
                  f"({edges[bins.start]:.0f}..{edges[bins.stop]:.0f} mm), NaN elsewhere")  # fmt: skip
            args.query = args.make_demo_query
        try:
            query = np.load(args.query, allow_pickle=False)
        except (ValueError, EOFError) as e:  # numpy's own text speaks of pickles for any other file
            raise ValueError(f"{args.query} is not an .npy array of numbers") from e
        observed = int(np.isfinite(query).sum()) if query.dtype.kind == "f" else query.size
        print(f"query {args.query}: {' x '.join(map(str, query.shape))} {query.dtype}, {observed} elements observed")
        result = tofmat.Classifier(table, backend="float", method=args.method).classify(query)
    except (OSError, ValueError) as e:  # a missing or unreadable file, a query of the wrong shape or dtype
        print(f"classify_saved_query.py: {e}", file=sys.stderr)
        return 1

    unit = " mm^2" if args.method == "eq12" else ""  # the session matcher's score has none
    print(
        f"{result.material}: {'distance' if unit else 'score'} {result.distance:.4f}{unit} over {result.valid} "
        f"elements, confidence {result.confidence:.2f}"
    )
    for rank, m in enumerate(result.ranking[: args.top], start=1):
        print(f"  {rank}. {m.material:<14s} {m.distance:10.4f}{unit}  p {m.probability:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
