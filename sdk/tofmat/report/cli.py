# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""`tofmat report`: run the benchmarks and write the error-against-run-time report (docs/report.md).

The command is registered in the `tofmat` group by ``main.add_command(report)``.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import click

from .._clikit import FiniteFloat, TofmatCommand, UserError, progress_bar

_F = TypeVar("_F", bound=Callable[..., Any])

DEFAULT_TABLE = Path("build/tanaka2017.tmx")
DEFAULT_DB = Path("../shared/data/tanaka2017_kinect2_db")


def default_table() -> Path:
    """build/tanaka2017.tmx when it exists (``make`` imports it), else the real database's folder."""
    return DEFAULT_TABLE if DEFAULT_TABLE.is_file() else DEFAULT_DB


def table_option(what: str) -> Callable[[_F], _F]:
    """``--table`` (into ``table_path``, None: :func:`default_table`), its help starting with ``what``."""
    return click.option(
        "--table",
        "table_path",
        type=click.Path(exists=True, path_type=Path),
        default=None,
        help=f"{what} (.tmx, or a folder of .npy curves). [default: {DEFAULT_TABLE} if it exists, else {DEFAULT_DB}]",
    )


def resolve_table(table_path: Path | None) -> Path:
    """The table given, else :func:`default_table`; a UserError when neither exists."""
    table = table_path if table_path is not None else default_table()
    if not table.exists():
        raise UserError(f"no table: neither {DEFAULT_TABLE} nor {DEFAULT_DB} exists (give --table)")
    return table


@click.command("report", cls=TofmatCommand)
@table_option("The table")
@click.option(
    "-o",
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("build/report"),
    show_default=True,
    help="Folder for report.md, its figures/ and the benchmarks' raw/ output.",
)
@click.option("--quick", is_flag=True, help="Tiny runs of everything (seconds; the timings are not worth reading).")
@click.option(
    "--runs",
    type=click.IntRange(1, 100),
    default=None,
    help="Runs of each benchmark; the report gives their medians. [default: 5, 1 with --quick]",
)
@click.option(
    "--per-material",
    type=click.IntRange(1, 10000),
    default=None,
    help="Noisy windows per material and length for the classifier. [default: 40, 3 with --quick]",
)
@click.option(
    "--noise", default=0.3, show_default=True, type=FiniteFloat(0, 100), help="Noise sigma of the windows, mm."
)
@click.option(
    "--build-dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("build/release"),
    show_default=True,
    help="The C++ build whose tests/bench and tests/cpp executables run.",
)
@click.option(
    "--counts-dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("build/bench"),
    show_default=True,
    help="Where `make report-counts` kept the aarch64 instruction counts.",
)
def report(
    table_path: Path | None,
    out_dir: Path,
    quick: bool,
    runs: int | None,
    per_material: int | None,
    noise: float,
    build_dir: Path,
    counts_dir: Path,
) -> None:
    """Error against run time of every path (float, fixed scalar, fixed vector) and the fixed-point
    path's stability, measured on this host: one Markdown report with PNG figures.

    Runs the Python classifier over window lengths, tofmat_bench_fixed and tofmat_bench_profiles of
    the C++ build, and the fixed-point classifier's stiff cases; prints the report's path.
    """
    from . import write_report

    table = resolve_table(table_path)
    with progress_bar("report") as progress:
        md = write_report(
            out_dir,
            table,
            quick=quick,
            progress=progress,
            runs=runs,
            per_material=per_material,
            noise_mm=noise,
            build_dir=build_dir,
            counts_dir=counts_dir,
        )
    click.echo(str(md))


__all__ = ["default_table", "report"]
