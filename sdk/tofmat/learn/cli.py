# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""`tofmat train`: a learned classifier for a table (docs/learned-models.md). Registered in the
`tofmat` group by ``main.add_command(train)``."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import click

from .._clikit import TofmatCommand, UserError, progress_bar
from ..report.cli import resolve_table, table_option


def _hidden(text: str) -> tuple[int, ...]:
    try:
        sizes = tuple(int(s) for s in text.split(","))
    except ValueError:
        raise click.BadParameter(f"{text!r}: comma-separated layer sizes, e.g. 256 or 256,128") from None
    if not sizes or len(sizes) > 4 or not all(1 <= s <= 4096 for s in sizes):
        raise click.BadParameter(f"{text!r}: 1 to 4 layers of 1 to 4096 units")
    return sizes


@click.command("train", cls=TofmatCommand)
@table_option("The table to train for (the model runs only with it)")
@click.option(
    "-o", "--out", type=click.Path(dir_okay=False, path_type=Path), required=True, help="The ONNX model to write."
)
@click.option("--force", is_flag=True, help="Replace --out if it exists.")
@click.option(
    "--sessions",
    type=click.IntRange(1, 2000),
    default=150,
    show_default=True,
    help="New sessions per material to train on (tuning side), each with one sweep of 15 lengths from 1 to 100 bins.",
)
@click.option(
    "--sim-sessions",
    type=click.IntRange(0, 200),
    default=0,
    show_default=True,
    help="Also simulator sweeps rendered in this many new sessions per material (target angles the curves' "
    "session model lacks; about 20 s a session for 29 materials).",
)
@click.option("--hidden", default="256,256", show_default=True, help="Hidden layer sizes, comma-separated.")
@click.option("--epochs", type=click.IntRange(1, 10000), default=200, show_default=True, help="At most this many.")
@click.option(
    "--seed",
    type=click.IntRange(0, 2**32 - 1),
    default=None,
    help="Seed of the training draws and the network (default: 3003).",
)
def train(
    table_path: Path | None,
    out: Path,
    force: bool,
    sessions: int,
    sim_sessions: int,
    hidden: str,
    epochs: int,
    seed: int | None,
) -> None:
    """Train an MLP on new capture sessions of the table's curves (the session model of
    docs/evaluation.md, tuning side only), export it to ONNX with the tofmat model contract, and
    check the export against the network. Run it with `tofmatd --classifier onnx:FILE`, or
    `tofmat evaluate --model FILE` to compare it with the exemplar matchers."""
    from ..tools.tables import open_table
    from .train import TRAIN_SEED
    from .train import train as fit

    sizes = _hidden(hidden)
    if out.exists() and not force:
        raise UserError(f"{out} exists (--force replaces it)")
    if not out.parent.is_dir():
        raise UserError(f"{out.parent} is not a folder")
    table = open_table(resolve_table(table_path))
    with progress_bar("train") as progress:
        try:
            t = fit(table, sessions, sizes, TRAIN_SEED if seed is None else seed, epochs, progress, sim_sessions)
        except ValueError as e:  # a material the simulator does not have
            raise UserError(str(e)) from e
    if t.check_max_abs > 1e-4:
        raise UserError(
            f"the exported model differs from the network by {t.check_max_abs:.3g} (over 1e-4): not written"
        )
    # Atomically: a reader (tofmatd restarting) sees the old model or the new one.
    fd, tmp = tempfile.mkstemp(dir=out.parent, prefix=f".{out.name}.")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(t.onnx)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, out)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    click.echo(
        f"{out}: MLP {list(sizes)} for {len(t.contract.materials)} materials, {len(t.onnx)} bytes; "
        f"{t.samples} training sweeps, {t.epochs} epochs, {t.seconds:.0f} s; "
        f"validation accuracy {100 * t.validation_accuracy:.1f} %; "
        f"export matches the network to {t.check_max_abs:.1e}"
    )
