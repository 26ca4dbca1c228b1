# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""`tofmat evaluate`: the held-out evaluation of docs/evaluation.md. Registered in the `tofmat`
group by ``main.add_command(evaluate)``."""

from __future__ import annotations

import json
import math
from dataclasses import asdict
from pathlib import Path
from typing import Any

import click

from .._clikit import TofmatCommand, UserError, progress_bar, strict_json
from ..report.cli import resolve_table, table_option


@click.command("evaluate", cls=TofmatCommand)
@click.option(
    "--source",
    type=click.Choice(["curves", "sim", "all"]),
    default="all",
    show_default=True,
    help="curves: the real curves in new sessions; sim: simulator sweeps in new sessions; all: both.",
)
@table_option("The real curves' table")
@click.option(
    "--sessions",
    type=click.IntRange(1, 1000),
    default=10,
    show_default=True,
    help="New sessions per material of the real curves, per split (one sweep of each length in each).",
)
@click.option(
    "--sim-sessions",
    type=click.IntRange(1, 1000),
    default=6,
    show_default=True,
    help="New sessions per material of the simulator, per split (rendered: about 5 s each for 29 materials).",
)
@click.option("--sim-materials", help="Comma-separated materials for the simulator source (default: its library's).")
@click.option(
    "--materials",
    help="Comma-separated materials of the real curves' table to evaluate among themselves (candidates and "
    "targets; e.g. acryl,acryl1mm,acryl2mm,acryl3mm: thickness). Default: all of them.",
)
@click.option(
    "--confusion", is_flag=True, help="Also print each matcher's confusion tables of the test split by sweep length."
)
@click.option(
    "--sim-table",
    type=click.Path(exists=True, path_type=Path),
    help="The simulator source's table (e.g. tofmat sim table's file) instead of one recorded here.",
)
@click.option("-o", "--out", type=click.Path(dir_okay=False, path_type=Path), help="Also write the table to this file.")
@click.option(
    "--model",
    "models",
    multiple=True,
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    help="Also a learned model (tofmat train; repeat for one per source): its row 'onnx' is reported for the "
    "source whose table it was trained for (the real curves', or with --sim-table the simulator's). With "
    "--session-scales: one model, trained for the table evaluated.",
)
@click.option(
    "--session-scales",
    help="Instead: the matchers as they ship (not tuned again) on a test split with the session spreads times "
    "each of these scales, e.g. 0,0.25,0.5,1,2: the real curves' (--source curves) or simulator sweeps against "
    "--sim-table at each of --yaws (--source sim).",
)
@click.option(
    "--yaws",
    help="With --source sim --session-scales: the targets' angles, degrees, comma-separated (default 0,10,20,30; "
    "the simulated camera's table is recorded at 10).",
)
@click.option(
    "--table-yaws",
    help="With --source sim --session-scales: also Eq. (12) and the session matcher against a table of the same "
    "materials recorded by the simulated camera at each of these angles, degrees, comma-separated (e.g. "
    "0,10,20,30), each angle's exemplar a candidate of its own: the label is the best exemplar's material, its "
    "confidence the sum of that material's exemplars' probabilities. With --sweeps-per-session, the learning "
    "matcher too, on the same sessions.",
)
@click.option(
    "--sweeps-per-session",
    type=click.IntRange(1, 1000),
    help="With --session-scales: sessions of this many sweeps (materials and lengths at random), labelled in "
    "turn by Eq. (12), the session matcher and the matcher that learns its session (tofmatd's session learning); "
    "--sessions (--sim-sessions with --source sim) x the table's materials sessions per scale (and angle).",
)
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of the Markdown table.")
@click.option(
    "--plot",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Also draw the test split's reliability diagram (confidence against accuracy) into this PNG.",
)
def evaluate(
    source: str,
    table_path: Path | None,
    sessions: int,
    sim_sessions: int,
    sim_materials: str | None,
    materials: str | None,
    confusion: bool,
    sim_table: Path | None,
    out: Path | None,
    models: tuple[Path, ...],
    session_scales: str | None,
    yaws: str | None,
    table_yaws: str | None,
    sweeps_per_session: int | None,
    as_json: bool,
    plot: Path | None,
) -> None:
    """Accuracy of every matcher by sweep length on a test split of new capture sessions, after
    tuning on a separate split (docs/evaluation.md): Eq. (12), the paper's classifier, against the
    session-robust matcher, each with its host time per query."""
    from ..tools.tables import open_table
    from .run import evaluate_curves, evaluate_sim, format_markdown

    if sweeps_per_session is not None and session_scales is None:
        raise UserError("--sweeps-per-session goes with --session-scales (e.g. --session-scales 0,0.25,0.5,1,2)")
    if yaws is not None and (session_scales is None or source != "sim"):
        raise UserError("--yaws goes with --source sim --session-scales")
    if table_yaws is not None and (session_scales is None or source != "sim"):
        raise UserError("--table-yaws goes with --source sim --session-scales")
    if session_scales is not None and source == "sim":
        return _evaluate_sim_scales(
            session_scales,
            yaws,
            sim_table,
            sim_materials,
            sim_sessions,
            sweeps_per_session,
            as_json,
            out,
            plot,
            models,
            _numbers(table_yaws, "--table-yaws") if table_yaws is not None else (),
        )
    if session_scales is not None:
        return _evaluate_scales(
            source, table_path, session_scales, sessions, sweeps_per_session, as_json, out, plot, models
        )
    if materials and source == "sim":
        raise UserError("--materials chooses among the real curves' materials (the simulator's: --sim-materials)")
    if sim_table is not None and sim_materials:
        raise UserError("--sim-table gives the simulator source's materials: leave out --sim-materials")
    # The sources' tables, and the learned model where it was trained for one (its contract).
    curves = open_table(resolve_table(table_path)) if source in ("curves", "all") else None
    sim = open_table(sim_table) if sim_table is not None and source in ("sim", "all") else None
    learned: dict[str, Any] = {}
    for model in models:
        from ..learn import LearnedClassifier

        try:
            m = LearnedClassifier(model)
        except ValueError as e:  # not a tofmat model
            raise UserError(f"{model}: {e}") from e
        why, fits = [], []
        for name, t in (("curves", curves), ("sim", sim)):
            if t is None:
                continue
            try:
                m.contract.check_table(t)
                fits.append(name)
            except ValueError as e:
                why.append(f"{name}: {e}")
        if not fits:
            raise UserError(
                f"{model} was trained for none of the evaluated tables (the simulator's needs --sim-table): "
                + "; ".join(why)
            )
        for name in fits:
            if name in learned:
                raise UserError(f"two models for the {name} source's table: give one")
            learned[name] = m
    results = []
    with progress_bar("evaluate") as progress:
        if curves is not None:
            only = [m.strip() for m in materials.split(",")] if materials else None
            if only is not None and "curves" in learned:
                raise UserError("a learned model is trained for the whole table: leave out --materials or --model")
            try:
                results.append(
                    evaluate_curves(curves, sessions, progress=progress, learned=learned.get("curves"), materials=only)
                )
            except ValueError as e:  # an unknown material, or fewer than two
                raise UserError(str(e)) from e
        if source in ("sim", "all"):
            names = [m.strip() for m in sim_materials.split(",")] if sim_materials else None
            try:
                results.append(
                    evaluate_sim(names, sim_sessions, progress=progress, table=sim, learned=learned.get("sim"))
                )
            except ValueError as e:  # an unknown material name
                raise UserError(str(e)) from e
    text = (
        json.dumps(
            strict_json([{**asdict(r), "tuning": [[asdict(p), s] for p, s in r.tuning]} for r in results]), indent=2
        )
        if as_json
        else format_markdown(results, confusions=confusion)
    )
    if plot is not None:
        from .plots import reliability_diagram

        reliability_diagram(results, plot)
    _emit(text, out)


def _evaluate_scales(
    source: str,
    table_path: Path | None,
    scales: str,
    sessions: int,
    sweeps_per_session: int | None,
    as_json: bool,
    out: Path | None,
    plot: Path | None = None,
    models: tuple[Path, ...] = (),
) -> None:
    from ..tools.tables import open_table
    from . import scales as single
    from . import sequences

    if source != "curves":
        raise UserError("--session-scales runs on the real curves (--source curves) or the simulator (--source sim)")
    values = _numbers(scales, "--session-scales")
    if plot is not None and sweeps_per_session is not None:
        raise UserError(
            "--plot with --session-scales draws the single sweeps' diagrams: leave out --sweeps-per-session"
        )
    table = open_table(resolve_table(table_path))
    learned = _scales_model(models, table, sweeps_per_session)
    with progress_bar("session scales") as progress:
        try:
            if sweeps_per_session is None:
                scale_rows = single.evaluate_scales(table, values, sessions, progress=progress, learned=learned)
                rows: list[Any] = scale_rows
                text = single.format_markdown(scale_rows)
            else:
                sequence_rows = sequences.evaluate_sequences(
                    table, values, sessions * len(table.materials), sweeps_per_session, progress=progress
                )
                rows = sequence_rows
                text = sequences.format_markdown(sequence_rows)
        except ValueError as e:
            raise UserError(str(e)) from e
    if plot is not None:
        from .plots import scale_reliability_diagram

        scale_reliability_diagram(scale_rows, plot)
    if as_json:
        text = json.dumps(strict_json([asdict(r) for r in rows]), indent=2)
    _emit(text, out)


def _scales_model(models: tuple[Path, ...], table: Any, sweeps_per_session: int | None) -> Any:
    """The learned model --session-scales reports beside the exemplar matchers (None without
    --model); a usage error for more than one, with --sweeps-per-session, or one for another table."""
    if not models:
        return None
    from ..learn import LearnedClassifier

    if len(models) > 1 or sweeps_per_session is not None:
        raise UserError("--session-scales takes one --model, for single sweeps: leave out --sweeps-per-session")
    try:
        return LearnedClassifier(models[0], table)
    except ValueError as e:  # not a tofmat model, or one for other curves
        raise UserError(f"{models[0]}: {e}") from e


def _numbers(text: str, option: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError as e:
        raise UserError(f"{option}: {e}") from e
    if not values:
        raise UserError(f"{option} needs at least one value")
    if any(not (math.isfinite(v) and v >= 0.0) for v in values):
        raise UserError(f"{option}: every value must be finite and >= 0, got {text}")
    return values


def _evaluate_sim_scales(
    scales: str,
    yaws: str | None,
    sim_table: Path | None,
    sim_materials: str | None,
    sim_sessions: int,
    sweeps_per_session: int | None,
    as_json: bool,
    out: Path | None,
    plot: Path | None,
    models: tuple[Path, ...] = (),
    table_yaws: tuple[float, ...] = (),
) -> None:
    from ..tools.tables import open_table
    from . import scales as single
    from . import sequences

    if plot is not None and sweeps_per_session is not None:
        raise UserError(
            "--plot with --session-scales draws the single sweeps' diagrams: leave out --sweeps-per-session"
        )
    values = _numbers(scales, "--session-scales")
    angles = _numbers(yaws, "--yaws") if yaws is not None else (0.0, 10.0, 20.0, 30.0)
    with progress_bar("simulator session scales") as progress:
        try:
            if sim_table is not None:
                if sim_materials:
                    raise UserError("--sim-materials records a table: leave it out with --sim-table")
                table = open_table(sim_table)
            else:
                from .sessions import SessionModel
                from .sim_sessions import SimSessions

                names = [m.strip() for m in sim_materials.split(",")] if sim_materials else None
                table = SimSessions(
                    names, SessionModel((0.0, 0.0), (0.0, 0.0, 0.0), 0.0, 0.0, 0.0), progress=progress
                ).table
            learned = _scales_model(models, table, sweeps_per_session)
            if sweeps_per_session is None:
                scale_rows = single.evaluate_sim_scales(
                    table, values, angles, sim_sessions, progress=progress, learned=learned, table_yaws=table_yaws
                )
                rows: list[Any] = scale_rows
                text = single.format_markdown(scale_rows)
            else:
                sequence_rows = sequences.evaluate_sim_sequences(
                    table,
                    values,
                    angles,
                    sim_sessions * len(table.materials),
                    sweeps_per_session,
                    progress=progress,
                    table_yaws=table_yaws,
                )
                rows = sequence_rows
                text = sequences.format_markdown(sequence_rows)
        except ValueError as e:
            raise UserError(str(e)) from e
    if as_json:
        text = json.dumps(strict_json([asdict(r) for r in rows]), indent=2)
    if plot is not None:
        from .plots import scale_reliability_diagram

        scale_reliability_diagram(scale_rows, plot)
    _emit(text, out)


def _emit(text: str, out: Path | None) -> None:
    """Prints the result, and writes it to ``out`` too when given."""
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text + "\n")
    click.echo(text)
