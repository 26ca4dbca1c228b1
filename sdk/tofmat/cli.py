# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The `tofmat` command line."""

from __future__ import annotations

import json
import sys
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar, cast

import click
import numpy as np

from . import ClassificationResult, Classifier, ExemplarTable, __version__, curve_roughness
from ._clikit import (
    CliState,
    Failure,
    FiniteFloat,
    NumberList,
    TofmatGroup,
    classify_exception,
    progress_bar,
    setup_logging,
)
from ._extras import require_pyplot
from .client import Backend
from .tools.tables import open_table

if TYPE_CHECKING:
    from .sim import MaterialLibrary

F = TypeVar("F", bound=Callable[..., Any])


def csv_list(value: str | None) -> list[str] | None:
    return [v.strip() for v in value.split(",") if v.strip()] if value else None


@click.group(cls=TofmatGroup)
@click.version_option(__version__, prog_name="tofmat")
@click.option("-v", "--verbose", is_flag=True, help="Show debug logs, and the traceback of an error.")
@click.option("-q", "--quiet", is_flag=True, help="No progress bars or progress notes.")
@click.pass_context
def main(ctx: click.Context, verbose: bool, quiet: bool) -> None:
    """Material classification from Time-of-Flight depth distortion."""
    ctx.obj = CliState(verbose=verbose, quiet=quiet)
    setup_logging(verbose)


# The table a command reads: a .tmx file or a folder of .npy curves (the real database's layout).
_table_option = click.option(
    "--table",
    "table_path",
    required=True,
    type=click.Path(exists=True, path_type=Path),
    help="Table file (.tmx) or folder of .npy curves.",
)
# The table of a command that starts tofmatd on the simulated camera.
_sim_table_option = click.option(
    "--table",
    "table_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Table for the daemon (default: the simulated camera's own, recorded and calibrated once into build/, "
    "about 10 minutes).",
)


@main.group()
def table() -> None:
    """Build and inspect exemplar tables."""


@table.command("import")
@click.argument("directory", type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option(
    "-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path), help="Table file to write (.tmx)."
)
@click.option(
    "--bin-start", default=600.0, show_default=True, type=FiniteFloat(0, 20000), help="Left edge of the first bin, mm."
)
@click.option(
    "--bin-stop",
    default=1200.0,
    show_default=True,
    type=FiniteFloat(0, 20000),
    help="Left edge of the last bin, mm (numpy.linspace convention).",
)
@click.option(
    "--no-noise",
    is_flag=True,
    help="Leave out each material's measured bin noise: a version 1.0 file, for readers older than 1.1.",
)
def table_import(directory: Path, output: Path, bin_start: float, bin_stop: float, no_noise: bool) -> None:
    """Import a folder of <material>.npy curves into a compact table file.

    Each material's bin noise per row is measured from its curve (tofmat.curve_roughness) and
    stored with it (format 1.1), for the session matcher.
    """
    t = ExemplarTable.from_npy_dir(directory, bin_start_mm=bin_start, bin_stop_mm=bin_stop)
    if not no_noise:
        t = t.with_noise(curve_roughness(t))
    t.save(output)
    saved = ExemplarTable.load(output)
    click.echo(
        f"wrote {output}: {len(saved)} materials x {saved.n_rows} rows x {saved.n_bins} bins, "
        f"step {saved.quant_step_mm:g} mm, {'with' if saved.noise_mm is not None else 'without'} noise, "
        f"{output.stat().st_size} bytes"
    )


def _distortion_summary(t: ExemplarTable) -> dict[str, Any] | None:
    g, d = t.distortion_grid, t.distortion_mm
    if g is None or d is None:
        return None
    return {
        "grid": {"start_mm": g.start_mm, "width_mm": g.width_mm, "count": g.count},
        "known_samples": {m: int(np.isfinite(row).sum()) for m, row in zip(t.materials, d, strict=True)},
    }


def table_summary(path: Path, t: ExemplarTable) -> dict[str, Any]:
    return {
        "path": str(path),
        "bytes": path.stat().st_size if path.is_file() else None,
        "materials": t.materials,
        "valid_elements": dict(zip(t.materials, t.valid_counts, strict=True)),
        "rows": [{"freq_mhz": f, "ref_freq_mhz": r} for f, r in t.rows],
        "bins": {"start_mm": t.bins.start_mm, "width_mm": t.bins.width_mm, "count": t.bins.count},
        "quant_step_mm": t.quant_step_mm,
        "noise_mm": None
        if t.noise_mm is None
        else {
            m: [None if np.isnan(v) else float(v) for v in row] for m, row in zip(t.materials, t.noise_mm, strict=True)
        },
        "distortion": _distortion_summary(t),
        "calibration": t.calibration,
    }


@table.command("info")
@click.argument("path", type=click.Path(exists=True, path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
def table_info(path: Path, as_json: bool) -> None:
    """Describe a table file (or a folder of .npy curves)."""
    t = open_table(path)
    s = table_summary(path, t)
    if as_json:
        click.echo(json.dumps(s, indent=2))
        return
    b = t.bins
    click.echo(
        f"{path}: {len(t)} materials x {t.n_rows} rows x {t.n_bins} bins"
        + (f", {s['bytes']} bytes" if s["bytes"] else "")
    )
    click.echo(
        f"bins: {b.count} from {b.start_mm:g} mm, width {b.width_mm:.6g} mm (to {b.start_mm + b.count * b.width_mm:g} mm)"
    )
    click.echo("rows: " + ", ".join(f"d({f} MHz) - d({r} MHz)" for f, r in t.rows))
    click.echo(f"quantisation step: {t.quant_step_mm:g} mm" if t.quant_step_mm else "not quantised (float values)")
    per_mat = t.n_rows * t.n_bins
    noise = t.noise_mm
    click.echo("bin noise: " + ("measured, mm per row" if noise is not None else "not stored (a version 1.0 table)"))
    g, dist = t.distortion_grid, t.distortion_mm
    click.echo("depth distortion: " + ("none (no corrected depth)" if g is None else
               f"{g.count} samples every {g.width_mm:g} mm of measured depth from {g.start_mm + g.width_mm / 2:g} mm"))  # fmt: skip
    c = t.calibration
    click.echo("calibration: " + ("built-in (tuned on the real database's curves)" if c is None else
               "its own (tofmat table calibrate, tofmat sim table): session row offsets "
               + ", ".join(f"{v:.2f}" for v in c["offset_sd_mm"]) + " mm; " + ", ".join(sorted(c["methods"]))))  # fmt: skip
    for i, (name, n) in enumerate(zip(t.materials, t.valid_counts, strict=True)):
        sd = "" if noise is None else "  noise " + " ".join("-" if np.isnan(v) else f"{v:.3f}" for v in noise[i])
        if dist is not None:
            known = np.isfinite(dist[i])
            sd += ("  distortion " + (f"{dist[i][known].min():+.1f}..{dist[i][known].max():+.1f} mm over "
                                      f"{int(known.sum())} samples" if known.any() else "none"))  # fmt: skip
        click.echo(f"  {name:<14s} {n:5d}/{per_mat} valid{sd}")


def result_dict(r: ClassificationResult, top: int) -> dict[str, Any]:
    out: dict[str, Any] = {
        "material": r.material,
        "index": r.index,
        "distance": r.distance,
        "valid": r.valid,
        "confidence": r.confidence,
        "unknown": r.unknown,
        "nearest": r.nearest,
        "ranking": [
            {
                "material": m.material,
                "index": m.index,
                "distance": m.distance,
                "valid": m.valid,
                "probability": m.probability,
            }
            for m in r.ranking[:top]
        ],
    }
    if r.fit == r.fit:  # (NaN with eq12: left out, JSON has no NaN)
        out["fit"] = r.fit
    return out


@main.command()
@_table_option
@click.argument("query", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--materials", help="Comma-separated candidate materials (default: all).")
@click.option("--top", default=5, show_default=True, type=click.IntRange(1, 255), help="Ranking entries to print.")
@click.option("--method", type=click.Choice(["session", "eq12"]), default="session", show_default=True,
              help="The session-robust matcher, or the paper's Eq. (12) (distance in mm^2).")  # fmt: skip
@click.option("--open-set", is_flag=True, help="Label a query no material explains 'unknown' (--method session).")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
def classify(
    table_path: Path, query: Path, materials: str | None, top: int, method: str, open_set: bool, as_json: bool
) -> None:
    """Classify QUERY.npy: (rows, bins) or a batch (n, rows, bins), NaN = missing."""
    t = open_table(table_path)
    try:
        q = np.load(query, allow_pickle=False)
    except (ValueError, EOFError) as e:
        raise ValueError(f"{query}: not a readable .npy array: {e}") from e
    if open_set and method != "session":
        raise click.BadParameter("needs --method session (Eq. (12) has no noise model)", param_hint="--open-set")
    clf = Classifier(t, backend="float", materials=csv_list(materials), method=cast(Any, method), open_set=open_set)
    single = q.ndim == 2
    results = [clf.classify(q)] if single else clf.classify_batch(q)
    if as_json:
        out = [result_dict(r, top) for r in results]
        click.echo(json.dumps(out[0] if single else out, indent=2))
        return
    for i, r in enumerate(results):
        prefix = "" if single else f"[{i}] "
        score = f"distance {r.distance:.4f} mm^2" if method == "eq12" else f"score {r.distance:.4f}"
        click.echo(f"{prefix}{r.material}  {score}  valid {r.valid}  confidence {r.confidence:.3f}")
        for m in r.ranking[1:top]:
            click.echo(f"{' ' * len(prefix)}  then {m.material:<14s} {m.distance:.4f}  p {m.probability:.3f}")


@main.group()
def plot() -> None:
    """Figures."""


@plot.command("table")
@click.argument("path", type=click.Path(exists=True, path_type=Path))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path))
def plot_table_cmd(path: Path, output: Path) -> None:
    """Plot every material's distortion curves (like the paper's Fig. 4)."""
    require_pyplot(extra="plot", feature="tofmat plot table")
    from .tools.plot import plot_table

    plot_table(open_table(path), output, title=f"{path.name}: relative depth distortion")
    click.echo(f"wrote {output}")


@main.command()
@_table_option
@click.option(
    "--windows",
    default="1,3,10,30,100",
    show_default=True,
    type=NumberList(int, 1, 10000),
    help="Window lengths in bins.",
)
@click.option("--noise", default=0.3, show_default=True, type=FiniteFloat(0, 1000), help="Gaussian noise sigma, mm.")
@click.option(
    "--per-material",
    default=40,
    show_default=True,
    type=click.IntRange(1, 100000),
    help="Windows per material and length.",
)
@click.option("--seed", default=0, show_default=True, type=click.IntRange(0, 2**63 - 1))
@click.option("--backends", default="float,fixed", show_default=True, help="Classifier backends to compare.")
@click.option("--json", "as_json", is_flag=True)
def bench(table_path: Path, windows: list[int], noise: float, per_material: int, seed: int, backends: str,
          as_json: bool) -> None:  # fmt: skip
    """Accuracy and time per query on noisy windows of the table's own curves, per backend."""
    from .tools.bench import bench_windows, format_markdown

    table = open_table(table_path)
    names = csv_list(backends) or []
    rows = []
    with progress_bar("backends") as progress:
        for k, b in enumerate(names):
            progress(k, len(names), b)
            rows += bench_windows(table, windows, noise, per_material, seed, cast(Backend, b))  # the core checks it
        progress(len(names), len(names), "done")
    click.echo(json.dumps([r.as_dict() for r in rows], indent=2) if as_json else format_markdown(rows, noise))


@main.command("sweeps")
@_table_option
@click.option("--sweeps", default=8, show_default=True, type=click.IntRange(1, 10000))
@click.option(
    "--sweep-bins",
    default=60,
    show_default=True,
    type=click.IntRange(1, 10000),
    help="Depth bins one sweep passes through.",
)
@click.option("--frames-per-bin", default=2, show_default=True, type=click.IntRange(1, 1000))
@click.option("--noise", default=0.3, show_default=True, type=FiniteFloat(0, 1000), help="Per-frame noise sigma, mm.")
@click.option("--seed", default=1, show_default=True, type=click.IntRange(0, 2**63 - 1))
def sweeps_cmd(table_path: Path, sweeps: int, sweep_bins: int, frames_per_bin: int, noise: float, seed: int) -> None:
    """Partial matching on noisy windows of the table's own curves (no camera, no daemon)."""
    from .tools.demo import run_demo

    run_demo(open_table(table_path), sweeps, sweep_bins, frames_per_bin, noise, seed, echo=click.echo)


@main.command()
@_sim_table_option
@click.option("--materials", default="cork,pvc,wood,paper,acryl", show_default=True, help="Targets swept, in order.")
@click.option(
    "--frames", default=60, show_default=True, type=click.IntRange(2, 10000), help="Frames per sweep (600 to 1200 mm)."
)
@click.option(
    "--gap", default=10, show_default=True, type=click.IntRange(0, 10000), help="Frames with no target between sweeps."
)
@click.option("--classifier", default="session", show_default=True, type=click.Choice(["session", "eq12"]),
              help="tofmatd's --classifier: the session-robust matcher or the paper's Eq. (12).")  # fmt: skip
def demo(table_path: Path | None, materials: str, frames: int, gap: int, classifier: str) -> None:
    """tofmatd on the simulated camera, live labels through the Python client, accuracy and latency."""
    from .tools.live_demo import run_live_demo

    table = table_path or _sim_table()
    run_live_demo(table, csv_list(materials) or [], frames, gap, echo=click.echo, classifier=classifier)


@main.command("line-demo")
@_sim_table_option
@click.option("--materials", default="acryl,copper,fabric,silicone,cork", show_default=True,
              help="The items' materials; each gets an outlet, in this order along the belt.")  # fmt: skip
@click.option("--seconds", default=60.0, show_default=True, type=FiniteFloat(5, 3600),
              help="How long to run after the first item.")  # fmt: skip
@click.option("--speed", default=500.0, show_default=True, type=FiniteFloat(50, 2000), help="Belt speed, mm/s.")
@click.option("--rate", default=60.0, show_default=True, type=FiniteFloat(1, 600), help="Items offered a minute.")
@click.option("--burst", default=4, show_default=True, type=click.IntRange(1, 30), help="Frames per item.")
@click.option("--seed", default=1, show_default=True, type=click.IntRange(0, 2**30))
@click.option("--gates/--no-gates", default=True, show_default=True,
              help="Run tofmat sort beside it: a flap per outlet on a simulated PCA9685.")  # fmt: skip
@click.option("-q", "--quiet", is_flag=True, help="Only the summary, not every item.")
def line_demo(table_path: Path | None, materials: str, seconds: float, speed: float, rate: float, burst: int,
              seed: int, gates: bool, quiet: bool) -> None:  # fmt: skip
    """tofmatd sorting a simulated belt: barrier, camera, outlets; items/min, right outlet, margins."""
    from .tools.line_demo import LineSetup, run_line, summary

    table = table_path or _sim_table()
    setup = LineSetup(tuple(csv_list(materials) or []), speed_mm_s=speed, rate_per_min=rate, burst=burst, seed=seed)
    click.echo(f"starting tofmatd --source {setup.source()} --gpio sim (a simulated line, {seconds:g} s)")
    result = run_line(table, setup, seconds, echo=None if quiet else click.echo, gates=gates)
    click.echo("")
    for line in summary(setup, result):
        click.echo(line)


@main.command("bench-line")
@_sim_table_option
@click.option(
    "--speeds", default="200,500,1000", show_default=True, type=NumberList(float, 50, 2000), help="Belt speeds, mm/s."
)
@click.option("--loads", default="0.6,0.8,0.9,1.0,1.2", show_default=True, type=NumberList(float, 0.01, 10),
              help="Offered rates as fractions of what the belt carries packed tight.")  # fmt: skip
@click.option("--bursts", default="4", show_default=True, type=NumberList(int, 1, 30), help="Frames per item.")
@click.option("--seeds", default=3, show_default=True, type=click.IntRange(1, 50))
@click.option("--seconds", default=20.0, show_default=True, type=FiniteFloat(5, 3600), help="Per run.")
@click.option("--item", default=160.0, show_default=True, type=FiniteFloat(10, 1000), help="Item length, mm.")
def bench_line_cmd(table_path: Path | None, speeds: list[float], loads: list[float], bursts: list[int], seeds: int, seconds: float,
                   item: float) -> None:  # fmt: skip
    """The simulated sorting line over speeds and rates: the highest rate with 99 % to the right outlet."""
    from .tools.line_bench import format_markdown, run_grid
    from .tools.line_demo import LineSetup

    table = table_path or _sim_table()
    base = LineSetup(("acryl", "copper", "fabric", "silicone", "cork"), item_mm=item)
    with progress_bar("simulated line runs") as progress:
        cells = run_grid(table, base, speeds, loads, seeds, seconds, bursts, progress)
    click.echo("")
    for line in format_markdown(cells, seeds, seconds):
        click.echo(line)


@main.command("bench-daemon")
@_sim_table_option
@click.option("--profiles", default="handheld,segmentation,sorting", show_default=True)
@click.option(
    "--clients",
    default="1,8",
    show_default=True,
    type=NumberList(int, 1, 64),
    help="Numbers of subscribed clients to try.",
)
@click.option(
    "--seconds", default=20.0, show_default=True, type=FiniteFloat(1, 3600), help="Per profile and client count."
)
def bench_daemon_cmd(table_path: Path | None, profiles: str, clients: list[int], seconds: float) -> None:
    """Latency, frame rate and accuracy of each tofmatd profile on the simulated camera (30 frames/s)."""
    from .tools.daemon_bench import bench_daemon, format_markdown

    table = table_path or _sim_table()
    with progress_bar("profiles") as progress:
        runs = bench_daemon(table, csv_list(profiles) or [], clients, seconds, progress)
    click.echo(format_markdown(runs))


@main.command("bench-depth")
@_sim_table_option
@click.option("--scenes", help="sim:SCENE specs (without 'sim:') separated by ';' (default: the regions scene with "
              "3 and with 6 materials at 600..1200 mm).")  # fmt: skip
@click.option("--frames", default=5, show_default=True, type=click.IntRange(1, 1000), help="Frames per scene.")
@click.option("--no-region-vote", is_flag=True, help="Run tofmatd with --no-region-vote.")
@click.option("--accumulate", default=1, show_default=True, type=click.IntRange(1, 256),
              help="Run tofmatd with --accumulate N (each pixel's features averaged over N frames).")  # fmt: skip
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
def bench_depth_cmd(table_path: Path | None, scenes: str | None, frames: int, no_region_vote: bool, accumulate: int,
                    as_json: bool) -> None:  # fmt: skip
    """tofmatd's segmentation on simulated scenes against their truth: the label map's accuracy (away
    from the targets' edges and near them), and the material-corrected depth's error per material."""
    from dataclasses import asdict

    from .tools.depth_bench import DEFAULT_SCENES, bench_depth, format_labels_markdown, format_markdown

    table = table_path or _sim_table()
    specs = [s.strip() for s in scenes.split(";") if s.strip()] if scenes else list(DEFAULT_SCENES)
    try:
        with progress_bar("scenes") as progress:
            extra = [*(["--no-region-vote"] if no_region_vote else []), "--accumulate", str(accumulate)]
            labels, results = bench_depth(table, specs, frames, progress, extra)
    except (RuntimeError, ValueError) as e:
        raise click.ClickException(str(e)) from e
    if as_json:
        click.echo(json.dumps({"labels": [asdict(s) for s in labels], "depth": [asdict(r) for r in results]}, indent=2))
    else:
        click.echo(format_labels_markdown(labels) + "\n\n" + format_markdown(results))


@main.command("bench-targets")
@_sim_table_option
@click.option("--depths", default="650,800,950,1100", show_default=True, type=NumberList(float, 100, 5000),
              help="Still targets' depths, mm.")  # fmt: skip
@click.option("--yaws", default="0,10,20,30", show_default=True, type=NumberList(float, -85, 85),
              help="The targets' angles, degrees.")  # fmt: skip
@click.option("--materials", help="Materials of the table to show, comma-separated (default: all).")
@click.option("--no-sweeps", is_flag=True, help="Still targets only.")
@click.option("--session-learning/--no-session-learning", default=True, show_default=True,
              help="The labelling daemon learns each scene's session (tofmatd's default), or labels each sweep on "
                   "its own (tofmatd --no-session-learning).")  # fmt: skip
@click.option("--json", "as_json", is_flag=True, help="Print every target's result as JSON.")
def bench_targets_cmd(table_path: Path | None, depths: list[float], yaws: list[float], materials: str | None,
                      no_sweeps: bool, session_learning: bool, as_json: bool) -> None:  # fmt: skip
    """Still targets and sweeps through tofmatd's hand-held path against the simulated camera's table:
    labels right, right among the candidates a target can be told from, confidently wrong, and the
    live query's Eq. (12) distance to the true material (docs/benchmarks.md)."""
    from dataclasses import asdict

    from .tools.target_bench import bench_targets, format_markdown, summary

    table = table_path or _sim_table()
    try:
        with progress_bar("scenes") as progress:
            results = bench_targets(table, depths, yaws, not no_sweeps, materials=csv_list(materials),
                                    progress=progress, labeller_args=[] if session_learning else ["--no-session-learning"])  # fmt: skip
    except (RuntimeError, ValueError) as e:
        raise click.ClickException(str(e)) from e
    if as_json:
        click.echo(json.dumps({"summary": summary(results), "targets": [asdict(r) for r in results]}, indent=2))
    else:
        click.echo(format_markdown(results))


@main.command("thickness")
@click.argument("query", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--material", default="acryl3mm", show_default=True,
              help="The slab material (of the simulator's calibrated library) the query is a slab of.")  # fmt: skip
@click.option("--new-session", is_flag=True,
              help="The query comes from another capture session than the model's (a real camera): fit "
              "each row's offset too.")  # fmt: skip
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
def thickness_cmd(query: Path, material: str, new_session: bool, as_json: bool) -> None:
    """A slab's thickness from QUERY.npy: its rows (2, 200) in the database's bins (600..1200 mm), or a
    batch (n, 2, 200); NaN, or both rows exactly 0 (the database's files), is missing."""
    from dataclasses import asdict

    from .sim import load_device
    from .sim.table import database_bins
    from .sim.thickness import ThicknessEstimator

    try:
        with warnings.catch_warnings():  # (the database's files are Python 2's: numpy says so, once a file)
            warnings.simplefilter("ignore", UserWarning)
            q = np.asarray(np.load(query, allow_pickle=False), dtype=np.float64)
    except (ValueError, EOFError, TypeError) as e:
        raise click.BadParameter(f"{query}: not a readable .npy array of numbers: {e}", param_hint="QUERY") from e
    bins = database_bins()
    if q.shape[-2:] != (2, bins.count) or q.ndim not in (2, 3):
        raise click.BadParameter(f"{query}: shape {q.shape}; expected (2, {bins.count}) or (n, 2, {bins.count})",
                                 param_hint="QUERY")  # fmt: skip
    library = _slab_library(material)
    batch = q if q.ndim == 3 else q[None]
    batch = np.where((batch == 0.0).all(axis=1, keepdims=True), np.nan, batch)  # the database's "missing"
    estimator = ThicknessEstimator(load_device(), library, material, bins)
    try:
        results = [estimator.estimate(r, offsets=new_session) for r in batch]
    except ValueError as e:
        raise click.BadParameter(f"{query}: {e}", param_hint="QUERY") from e
    if as_json:
        out = [asdict(r) for r in results]
        click.echo(json.dumps(out[0] if q.ndim == 2 else out, indent=2))
        return
    for i, r in enumerate(results):
        prefix = "" if q.ndim == 2 else f"[{i}] "
        if r.open_above and r.low_mm <= estimator.grid[0]:
            said = "no thickness (the rows fit every thickness alike)"
        elif r.open_above:
            said = f"at least {r.low_mm:.2f} mm (the rows do not tell it from thicker slabs; best {r.thickness_mm:.2f})"
        else:
            said = f"{r.thickness_mm:.2f} mm (95 %: {r.low_mm:.2f}..{r.high_mm:.2f} mm)"
        click.echo(f"{prefix}{material}: {said}, residual {r.residual_mm:.2f} mm over {r.values} values")


@main.command("bench-thickness")
@click.option("--material", default="acryl3mm", show_default=True, help="The slab material whose thickness varies.")
@click.option("--thicknesses", type=NumberList(float, 0.2, 13.0),
              help="Slab thicknesses, mm (default: 0.5,1,1.5,2,3,4,5,6,7,8,10).")  # fmt: skip
@click.option("--sweeps", default=5, show_default=True, type=click.IntRange(1, 1000), help="Sweeps per thickness.")
@click.option("--lengths", default="0,30", show_default=True, type=NumberList(int, 0, 200),
              help="Sweep lengths in bins (0: the whole 600..1200 mm sweep).")  # fmt: skip
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
def bench_thickness_cmd(material: str, thicknesses: list[float] | None, sweeps: int, lengths: list[int],
                        as_json: bool) -> None:  # fmt: skip
    """Thickness estimates of simulated slabs against their truth: error by thickness, sweep length and
    capture session."""
    from .tools.thickness_bench import DEFAULT_THICKNESSES, bench_thickness, format_json, format_markdown

    _slab_library(material)
    with progress_bar("thicknesses") as progress:
        rows = bench_thickness(material, tuple(thicknesses or DEFAULT_THICKNESSES), sweeps, tuple(lengths),
                               progress=progress)  # fmt: skip
    click.echo(format_json(rows) if as_json else format_markdown(rows))


def _slab_library(material: str) -> MaterialLibrary:
    """The simulator's calibrated library, if `material` is a slab of it (a usage error otherwise)."""
    from .sim import load_library
    from .sim.thickness import slab_materials

    library = load_library()
    if material not in library.names or library[material].kind != "slab":
        raise click.BadParameter(f"{material!r} is not a slab of the library; slabs: {', '.join(slab_materials(library))}",
                                 param_hint="--material")  # fmt: skip
    return library


def _sim_table() -> Path:
    """The simulated camera's own table, recorded and calibrated once into build/ (about 7 minutes the
    first time)."""
    from .sim.own_table import ensure_sim_table

    path = Path("build/sim_table.tmx")
    with progress_bar(f"recording and calibrating the simulated camera's table into {path} (once)") as progress:
        return ensure_sim_table(path, progress)


def _client_options(fn: F) -> F:
    fn = click.option("--token-file", type=click.Path(exists=True, dir_okay=False, path_type=Path),
                      help="File holding the daemon's TCP token.")(fn)  # fmt: skip
    fn = click.option("--address", envvar="TOFMAT_SOCKET", default="/run/tofmat/tofmatd.sock", show_default=True,
                      help="Unix socket path or host:port of tofmatd.")(fn)  # fmt: skip
    return fn


def _token(token_file: Path | None) -> str | None:
    """The daemon's TCP token: the first line of its file, without the blanks around it."""
    return token_file.read_text().splitlines()[0].strip() if token_file else None


def _i2c_bus(bus: str) -> Any:
    """A real I2C bus by number ("1": /dev/i2c-1) or device path (smbus2, `tofmat[hw]`)."""
    from .hw import open_bus

    try:
        return open_bus(int(bus) if bus.isdigit() else bus)
    except FileNotFoundError as e:  # the bus is not there: the box's hardware, not the user's input
        raise Failure(str(e)) from e


def _connect(address: str, token_file: Path | None) -> Any:
    from .client import Client, ClientError

    token = _token(token_file)
    try:
        return Client(address, token=token)
    except ClientError as e:
        raise classify_exception(e) from e


@table.command("distortion")
@click.argument("path", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              help="Table file to write (default: PATH itself, replaced atomically).")  # fmt: skip
@click.option("--device", default="kinect2_tanaka2017", show_default=True, help="Simulator device profile.")
@click.option("--library", default="tanaka2017", show_default=True,
              help="Simulator material library (the calibrated one: each material's response fitted to the "
                   "real database).")  # fmt: skip
@click.option("--yaw", default=10.0, show_default=True, type=FiniteFloat(-80, 80), help="Target orientation, degrees.")
def table_distortion(path: Path, output: Path | None, device: str, library: str, yaw: float) -> None:
    """Add each material's depth distortion (Eq. (8)) from the calibrated simulator to a table.

    The database's rows are relative, so a table imported from it cannot correct a depth; the
    simulator's library holds each material's response fitted to those rows, and a sweep of it in
    front of the simulated camera gives the absolute distortion tofmatd's corrected depth
    subtracts. How far to trust it: how well the fit matched the material's relative rows (the
    "fit rms" printed, from the library)."""
    from .sim import Renderer, load_device, load_library
    from .sim.table import DISTORTION_GRID, depth_distortion, library_fit_rms

    t = open_table(path)
    r = Renderer(load_device(device), load_library(library))
    known = [m for m in t.materials if m in r.library.names]
    with progress_bar("sweeping materials") as progress:
        found = depth_distortion(r, known, yaw_deg=yaw, progress=progress)
    out = np.full((len(t), DISTORTION_GRID.count), np.nan)
    for k, name in enumerate(known):
        out[t.index_of(name)] = found[k]
    t = t.with_distortion(DISTORTION_GRID, out)
    target = output or path
    t.save(str(target))
    fits = library_fit_rms(library)
    click.echo(f"{target}: depth distortion for {len(known)} of {len(t)} materials (library {library})")
    for i, name in enumerate(t.materials):
        row = out[i][np.isfinite(out[i])]
        if name not in known:
            click.echo(f"  {name:<14s} none: not in the simulator's library")
            continue
        fit = f"fit rms {fits[name]:.2f} mm" if name in fits else "fit rms unknown"
        span = f"{row.min():+.1f}..{row.max():+.1f} mm over {row.size} samples" if row.size else "none measured"
        click.echo(f"  {name:<14s} {span}  ({fit})")


@table.command("calibrate")
@click.argument("path", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              help="Table file to write (default: PATH itself, replaced atomically).")  # fmt: skip
@click.option("--source", type=click.Choice(["curves", "sim"]), default="curves", show_default=True,
              help="curves: a table of the real database's curves, its sessions drawn from them; sim: a table the "
              "simulated camera recorded, its sessions rendered.")  # fmt: skip
@click.option("--sessions", type=click.IntRange(1, 1000), default=10, show_default=True,
              help="New sessions per material and split (as tofmat evaluate's).")  # fmt: skip
@click.option("--json", "as_json", is_flag=True, help="Print the calibration written as JSON.")
def table_calibrate(path: Path, output: Path | None, source: str, sessions: int, as_json: bool) -> None:
    """Calibrate a table for itself and store the calibration in it (format 1.3).

    The held-out evaluation (docs/evaluation.md) on this table's materials: its tuning split tunes the
    session matcher's prior and fits each method's confidence temperatures and the open-set
    thresholds, which the table then carries; tofmatd and tofmat.Classifier use them instead of the
    built-in ones. Everything else the table holds (noise, depth distortion) is kept. Prints the
    test split's accuracy with them."""
    from .evaluation.run import format_markdown
    from .evaluation.table_calibration import calibrate_table

    t = open_table(path)
    if len(t) < 2:
        raise click.BadParameter("a table of one material has nothing to calibrate a choice on", param_hint="PATH")
    try:
        with progress_bar("calibrating") as progress:
            calibrated, result = calibrate_table(t, source, sessions, progress)
    except (ValueError, RuntimeError) as e:
        raise click.ClickException(str(e)) from e
    target = output or path
    calibrated.save(str(target))
    if as_json:
        click.echo(json.dumps(calibrated.calibration, indent=2))
        return
    c = calibrated.calibration or {}
    click.echo(f"{target}: calibrated for {len(t)} materials ({source}, {sessions} sessions a material and split)")
    click.echo("  session prior: row offsets " + ", ".join(f"{v:.2f}" for v in c["offset_sd_mm"]) + " mm, drift "
               + ", ".join(f"{v:.2f}" for v in c["drift_sd_mm"]) + " mm")  # fmt: skip
    for name, m in c["methods"].items():
        temps = ", ".join(f"{n:g}: {v:.3g}" for n, v in m["temperatures"])
        click.echo(f"  {name}: temperatures by sweep length {temps}")
    click.echo(format_markdown([result]))


@table.command("twins")
@click.argument("path", type=click.Path(exists=True, path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of the table.")
def table_twins(path: Path, as_json: bool) -> None:
    """Each material's near twin: the other curve closest to it once a per-row offset and slope
    (what a capture session can do) are taken out, closest pairs first.

    What is left, in mm rms, beside the material's own bin noise: a material within a session's
    reach of another is labelled among the two with low confidence, and held out of the table it
    passes as known (docs/evaluation.md, "Open set"). PATH: a .tmx table or a folder of .npy curves."""
    from dataclasses import asdict

    from .tools.twins import near_twins

    try:
        twins = near_twins(open_table(path))
    except ValueError as e:
        raise click.BadParameter(str(e), param_hint="PATH") from e
    if as_json:
        click.echo(json.dumps([asdict(t) for t in twins], indent=2))
        return
    click.echo(
        "| material | near twin | as stored (mm rms) | after an offset | after an offset and slope | bin noise |"
    )
    click.echo("|---|---|---:|---:|---:|---:|")
    for t in twins:
        click.echo(f"| {t.material} | {t.twin or '-'} | {t.raw_mm:.2f} | {t.after_offset_mm:.2f} | "
                   f"{t.after_drift_mm:.2f} | {t.noise_mm:.2f} |")  # fmt: skip


@table.command("add")
@click.argument("name")
@_client_options
@click.option("--table", "table_path", required=True, type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="The table (.tmx) to add the material to.")  # fmt: skip
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              help="Table file to write (default: --table itself, replaced atomically).")  # fmt: skip
@click.option("--passes", default=3, show_default=True, type=click.IntRange(1, 100),
              help="Hand-held passes to average.")  # fmt: skip
@click.option("--min-bins", default=10, show_default=True, type=click.IntRange(1, 65535),
              help="A pass covering fewer depth bins is left out.")  # fmt: skip
@click.option("--timeout", "timeout_s", default=300.0, show_default=True, type=FiniteFloat(1, 86400),
              help="Seconds to wait for all the passes.")  # fmt: skip
@click.option("--replace", is_flag=True, help="Capture a material the table already has again, in place of its curve.")
def table_add(name: str, address: str, token_file: Path | None, table_path: Path, output: Path | None, passes: int,
              min_bins: int, timeout_s: float, replace: bool) -> None:  # fmt: skip
    """Capture a new material NAME with the box and add it to a table.

    tofmatd (at --address, in its handheld profile, on whatever source it runs: the camera, the
    simulator or a replay) watches the user sweep the material through the depth range, --passes
    times; their mean is the curve and their spread its bin noise, written with the table (format
    1.1). Then send tofmatd SIGHUP (systemctl reload tofmatd) to serve the new table.
    """
    from .tools.capture import CaptureError, capture_passes, combine_passes, with_material

    table = ExemplarTable.load(table_path)
    out = output or table_path
    if name in table.materials and not replace:
        raise click.BadParameter(
            f"the table already has '{name}': give --replace to capture it again", param_hint="NAME"
        )
    try:  # the table's rules for a name, before anyone sweeps anything
        ExemplarTable([name], np.zeros((1, table.n_rows, table.n_bins)), table.bins, table.rows)
    except ValueError as e:
        raise click.BadParameter(str(e), param_hint="NAME") from e
    with _connect(address, token_file) as client:
        click.echo(f"sweep {name} through the camera's region {passes} time(s), taking it away between passes")
        try:
            got = capture_passes(client, table, passes, min_bins, timeout_s, click.echo)
            cap = combine_passes(got, table, name)
            new = with_material(table, name, cap, replace)
        except CaptureError as e:
            raise Failure(str(e)) from e
    new.save(out)
    seen = int(np.isfinite(cap.curve).all(axis=0).sum())
    noise = ", ".join("-" if np.isnan(v) else f"{v:.3f}" for v in cap.noise_mm)
    click.echo(
        f"wrote {out}: {name} ({seen} of {table.n_bins} bins, noise {noise} mm from the {cap.noise_from}), "
        f"{len(new)} materials; send tofmatd SIGHUP to serve it"
    )


@main.command("sort")
@_client_options
@click.option("--gate", "gates", multiple=True, required=True,
              help="An outlet's gate: OUTLET:channel=N[,open=DEG][,closed=DEG][,travel=MS][,hold=MS] (repeat).")  # fmt: skip
@click.option("--bus", help="I2C bus of the PCA9685 (number or /dev path).")
@click.option("--pca-address", default="0x40", show_default=True, help="The PCA9685's I2C address.")
@click.option("--simulated", is_flag=True, help="Drive a simulated PCA9685 instead of a real bus.")
@click.option("--seconds", type=FiniteFloat(0.1, None), help="Stop after this long (default: run until stopped).")
def sort_cmd(address: str, token_file: Path | None, gates: tuple[str, ...], bus: str | None, pca_address: str,
             simulated: bool, seconds: float | None) -> None:  # fmt: skip
    """The diverter agent: moves each outlet's gate (a servo on a PCA9685) for tofmatd's sort decisions."""
    from .hw import FakePCA9685Bus
    from .line import parse_gate
    from .tools.sort_agent import gate_servos, run_sort_agent

    if simulated == (bus is not None):
        raise click.UsageError("give --bus N (the PCA9685's I2C bus) or --simulated")
    try:
        parsed = [parse_gate(g) for g in gates]
        addr = int(pca_address, 0)
    except ValueError as e:
        raise click.BadParameter(str(e)) from e
    servos = gate_servos(FakePCA9685Bus(addr) if simulated else _i2c_bus(str(bus)), parsed, addr)
    with _connect(address, token_file) as client:
        r = run_sort_agent(client, servos, parsed, seconds, echo=click.echo)
    click.echo(f"{r.decisions} decisions, {len(r.moves)} gate moves, {len(r.late)} too late to open in time")


@main.command("panel")
@_client_options
@click.option("--bus", help="I2C bus of the SSD1306 (number or /dev path).")
@click.option("--oled-address", default="0x3c", show_default=True, help="The SSD1306's I2C address.")
@click.option("--simulated", is_flag=True, help="Draw on a simulated SSD1306 instead of a real bus.")
@click.option("--png", type=click.Path(dir_okay=False, path_type=Path),
              help="With --simulated: write what the panel shows at the end to this PNG.")  # fmt: skip
@click.option("--seconds", type=FiniteFloat(0.1, None), help="Stop after this long (default: run until stopped).")
def panel_cmd(address: str, token_file: Path | None, bus: str | None, oled_address: str, simulated: bool,
              png: Path | None, seconds: float | None) -> None:  # fmt: skip
    """The box's front panel: tofmatd's label, confidence and state on an SSD1306 OLED."""
    from .client import Client
    from .hw import SSD1306, FakeSSD1306Bus
    from .tools.panel_agent import run_panel

    if simulated == (bus is not None):
        raise click.UsageError("give --bus N (the SSD1306's I2C bus) or --simulated")
    if png is not None and not simulated:
        raise click.UsageError("--png saves the simulated panel's picture: it needs --simulated")
    try:
        addr = int(oled_address, 0)
    except ValueError as e:
        raise click.BadParameter(f"--oled-address: {e}") from e
    token = _token(token_file)
    fake = FakeSSD1306Bus(addr) if simulated else None
    i2c = fake or _i2c_bus(str(bus))
    display = SSD1306(i2c, addr)
    try:
        r = run_panel(lambda: Client(address, token=token, reconnect=False), display, seconds, echo=click.echo)
    except KeyboardInterrupt:
        return
    click.echo(f"panel: {r.draws} frames drawn; showing: {' | '.join(r.shown or [])}")
    if fake is not None and png is not None:
        click.echo(f"panel: picture in {fake.save_png(png)}")


@main.command()
@_client_options
@click.option("--top", default=3, show_default=True, type=click.IntRange(1, 255), help="Ranking entries shown.")
@click.option(
    "--count", default=0, type=click.IntRange(0, None), help="Stop after this many labels (0: until interrupted)."
)
@click.option("--json", "as_json", is_flag=True,
              help="One JSON object a line: the daemon first, then each label and device event as the protocol's "
              "fields (for a program to read).")  # fmt: skip
def watch(address: str, token_file: Path | None, top: int, count: int, as_json: bool) -> None:
    """Live labels from tofmatd with their ranking, in the terminal."""
    from dataclasses import asdict

    from ._clikit import strict_json
    from .client import ClientError, DeviceEvent, Label

    def emit_json(kind: str, fields: dict[str, Any]) -> None:
        click.echo(json.dumps(strict_json({"event": kind, **fields})))

    redraw = sys.stdout.isatty() and not as_json
    n = 0
    with _connect(address, token_file) as client:
        profile = client.status()["profile"]
        if as_json:
            emit_json("daemon", {"server": client.hello["server"], "address": address, "profile": profile,
                                 "minor": client.hello.get("minor", 0)})  # fmt: skip
        else:
            click.echo(f"{client.hello['server']} at {address}: profile {profile}")
        client.subscribe("labels", "device")
        try:
            for e in client.events(timeout=None):
                if isinstance(e, DeviceEvent):
                    if as_json:
                        emit_json("device", asdict(e))
                    else:
                        click.echo(f"\ndevice {e.state}: {e.message}")
                    continue
                if not isinstance(e, Label):
                    continue
                n += 1
                if as_json:
                    emit_json("label", asdict(e))
                else:
                    if e.state == "no_target":
                        line = f"frame {e.frame:6d}  (no target)"
                    elif e.state == "out_of_range":
                        line = f"frame {e.frame:6d}  (a target outside the table's depth range: see tofmat status)"
                    else:
                        ranks = "  ".join(f"{r.material} {r.distance:.2f}" for r in e.ranking[:top])
                        name = e.material or e.state  # ("unknown": no material fits)
                        line = f"frame {e.frame:6d}  bins {e.bins_covered:3d}  {name:12s}  | {ranks} mm^2"
                    if e.truth is not None and e.truth.material:
                        line += f"  [truth {e.truth.material}]"
                    if e.simulated:
                        line += "  [SIMULATED]"
                    click.echo(("\r\033[K" + line) if redraw else line, nl=not redraw)
                if count and n >= count:
                    break
        except KeyboardInterrupt:
            pass
        except ClientError as err:
            raise classify_exception(err) from err
        if redraw:
            click.echo("")


@main.command()
@_client_options
@click.option("-o", "--output", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Folder to write labels.png, depth.png, corrected.png, points.ply and snapshot.json into.")  # fmt: skip
@click.option("--timeout", "timeout_s", default=10.0, show_default=True, type=FiniteFloat(0.1, 3600),
              help="Seconds to wait for a frame.")  # fmt: skip
@click.option("--intrinsics", type=NumberList(float, -1e6, 1e6),
              help="FX,FY,CX,CY[,K1,K2,K3,P1,P2] in place of the camera's own (a daemon that sends none).")  # fmt: skip
@click.option("--overwrite", is_flag=True, help="Replace the files of an earlier snapshot in the folder.")
def snapshot(address: str, token_file: Path | None, output: Path, timeout_s: float, intrinsics: list[float] | None,
             overwrite: bool) -> None:  # fmt: skip
    """One frame of what tofmatd sees: the label map and depth as PNGs, and a PLY point cloud."""
    from .client import ClientError
    from .geometry import Intrinsics
    from .tools.snapshot import SnapshotError, capture, write_snapshot

    intr = None
    if intrinsics is not None:
        if len(intrinsics) not in (4, 9):
            raise click.BadParameter("give FX,FY,CX,CY or all nine values", param_hint="--intrinsics")
        try:
            intr = Intrinsics(*intrinsics)
        except ValueError as e:
            raise click.BadParameter(str(e), param_hint="--intrinsics") from e
    with _connect(address, token_file) as client:
        try:
            shot = capture(client, timeout_s)
        except (ClientError, SnapshotError) as e:
            raise click.ClickException(str(e)) from e
    try:
        paths = write_snapshot(shot, output, intrinsics=intr, overwrite=overwrite)
    except (SnapshotError, OSError) as e:
        raise click.ClickException(str(e)) from e
    labelled = int((shot.labels != 255).sum())
    click.echo(f"frame {shot.frame} ({shot.profile}): {labelled} of {shot.labels.size} pixels labelled; "
               f"wrote {', '.join(str(p) for p in paths)}")  # fmt: skip


@main.command()
@_client_options
def status(address: str, token_file: Path | None) -> None:
    """tofmatd's status as JSON."""
    with _connect(address, token_file) as client:
        click.echo(json.dumps(client.status(), indent=2))


@main.command()
@click.option(
    "--source", required=True, help="kinect[:SERIAL] | sim[:SCENE,...] | replay:FILE (named: never a default)"
)
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path), help="Recording file.")
@click.option(
    "--frames", default=30, show_default=True, type=click.IntRange(1, 100000), help="Frames to record (2.6 MB each)."
)
@click.option(
    "--timeout", default=60.0, show_default=True, type=FiniteFloat(0.1, 86400), help="Seconds to wait for them."
)
def record(source: str, output: Path, frames: int, timeout: float) -> None:
    """Record a source's raw frames for `tofmatd --source replay:FILE`."""
    from . import _tofmat
    from .client import sim_data_dir

    try:
        n = _tofmat.record(source, str(output), frames, str(sim_data_dir()), timeout)
    except RuntimeError as e:
        raise click.ClickException(str(e)) from e
    click.echo(f"{output}: {n} frames from {source}")


@main.command()
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
def devices(as_json: bool) -> None:
    """List Kinect v2 cameras on the USB bus; exit 1 with the reason when there is none usable."""
    from . import UsbError, devices

    try:
        found = devices()
    except UsbError as e:
        raise click.ClickException(str(e)) from e
    if as_json:
        click.echo(json.dumps([d.as_dict() for d in found], indent=2))
    for d in found if not as_json else []:
        state = "ok" if d.accessible else f"not usable: {d.problem}"
        click.echo(f"Kinect v2 045e:{d.product_id:04x} at USB {d.port} serial {d.serial or '?'} ({state})")
    if not found:
        raise click.ClickException(
            "no Kinect v2 found (USB 045e:02d8 or 045e:02c4); is it plugged into a USB 3 port and powered?"
        )
    if not any(d.accessible for d in found):
        raise click.ClickException(f"no usable Kinect v2: {found[0].problem}")


def _register_sim() -> None:
    from .evaluation.cli import evaluate
    from .learn.cli import train
    from .report.cli import report
    from .sim.cli import sim_cli

    main.add_command(sim_cli)
    main.add_command(report)
    main.add_command(evaluate)
    main.add_command(train)


_register_sim()

if __name__ == "__main__":
    sys.exit(main())
