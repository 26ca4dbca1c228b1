# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""`tofmat sim ...`: calibrate the simulator, reproduce the paper's evaluation, measure speed."""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import click
import numpy as np
from click.core import ParameterSource

from .._clikit import FiniteFloat, NumberList, TofmatGroup, progress_bar
from .._extras import require, require_pyplot
from . import (
    DEFAULT_DEVICE,
    DEFAULT_LIBRARY,
    Renderer,
    Scene,
    Target,
    library_path,
    load_device,
    load_library,
)
from .own_table import CALIBRATION_SESSIONS, current_table

if TYPE_CHECKING:
    from .. import ExemplarTable


@click.group("sim", cls=TofmatGroup)
def sim_cli() -> None:
    """The physically based Kinect v2 simulator."""


def _renderer(device: str, library: str, threads: int = 0) -> Renderer:
    """The simulator for a device profile and a material library, each a name or a path."""
    return Renderer(load_device(device), load_library(library), threads)


def _spread_option(option: str, hint: str, form: str, from_library: Callable[[], Sequence[float]]) -> tuple[float, ...]:
    """A spread option (--session-offsets, --session-drift): 'none' (zeros), 'library' (the spread
    the calibrated library's fits carry) or comma-separated standard deviations in the form ``form``."""
    count = len(form.split(","))
    word = {2: "two", 3: "three"}[count]
    if option == "none":
        return (0.0,) * count
    if option == "library":
        return tuple(from_library())
    try:
        s = tuple(float(v) for v in option.split(","))
    except ValueError as e:
        raise click.BadParameter(f"expected none, library or {form}", param_hint=hint) from e
    if len(s) != count:
        raise click.BadParameter(f"expected none, library or {form}: {word} finite standard deviations >= 0",
                                 param_hint=hint)  # fmt: skip
    if not all(np.isfinite(v) and v >= 0.0 for v in s):
        raise click.BadParameter(f"{word} finite standard deviations: each must be finite and >= 0", param_hint=hint)
    return s


@sim_cli.command("evaluate")
@click.option("--device", default=DEFAULT_DEVICE, show_default=True, help="Device profile name or path.")
@click.option("--library", default=DEFAULT_LIBRARY, show_default=True, help="Material library name or path.")
@click.option(
    "--out",
    "out_dir",
    default=Path("build/sim-eval"),
    type=click.Path(file_okay=False, path_type=Path),
    show_default=True,
    help="Folder for figures and results.json.",
)
@click.option("--materials", help="Comma-separated subset (default: the whole library).")
@click.option(
    "--step", default=1.0, show_default=True, type=FiniteFloat(0.05, 650), help="Stage step, mm (600..1250 mm)."
)
@click.option("--seed", default=0, show_default=True, type=click.IntRange(0, 2**31))
@click.option("--session-offsets", default="none", show_default=True,
              help="Per-capture row offsets: 'none', 'library' (the spread the calibrated library's fits carry) "
              "or 'S0,S1' (standard deviations in mm of rows 0 and 1).")  # fmt: skip
@click.option("--session-drift", default="none", show_default=True,
              help="Per-capture session states of the waveform (docs/simulator-model.md 2.2): 'none', 'library' "
              "(the spread of the states the calibrated library's fits carry) or 'S80,S16,S120' (standard deviations).")  # fmt: skip
@click.option(
    "--compare-fixed",
    is_flag=True,
    help="Also classify every query with the fixed-point backend and report where it differs.",
)
def evaluate_cmd(device: str, library: str, out_dir: Path, materials: str | None, step: float, seed: int,
                 session_offsets: str, session_drift: str, compare_fixed: bool) -> None:  # fmt: skip
    """Leave-one-orientation-out nearest neighbour in the paper's protocol (Sec. 5)."""
    require_pyplot(extra="sim", feature="tofmat sim evaluate")  # its figures: fail before the long run
    from . import evaluate as ev
    from . import plots

    r = _renderer(device, library)
    names = [m.strip() for m in materials.split(",")] if materials else list(r.library.names)
    stage = np.arange(600.0, 1250.0 + 1e-9, step)

    def fits() -> dict[str, Any]:  # the library file, read only for 'library'
        return cast(dict[str, Any], json.loads(library_path(library).read_text()))

    s0, s1 = _spread_option(session_offsets, "--session-offsets", "S0,S1", lambda: ev.session_offset_spread(fits()))
    spread = (s0, s1)
    t80, t16, t120 = _spread_option(session_drift, "--session-drift", "S80,S16,S120",
                                    lambda: ev.session_state_spread(fits()))  # fmt: skip
    drift_sd = (t80, t16, t120)
    t0 = time.perf_counter()
    with progress_bar("capturing materials") as progress:
        result, _ = ev.evaluate(r, names, stage_mm=stage, seed=seed, progress=progress,
                                session_offsets_mm=spread, compare_fixed=compare_fixed, session_drift_sd=drift_sd,
                                session_renderer=lambda t: Renderer(r.device.in_session(t), r.library, 0))  # fmt: skip
    click.echo(
        f"{len(names)} materials x {len(ev.ORIENTATIONS_DEG)} orientations, stage {stage[0]:g}..{stage[-1]:g} mm "
        f"step {step:g} mm, ROI 20x20 px, session offsets sd {spread[0]:.2f}, {spread[1]:.2f} mm, "
        f"session drift sd {drift_sd[0]:.2f}, {drift_sd[1]:.2f}, {drift_sd[2]:.2f}, "
        f"capture {result.capture_seconds:.0f} s"
    )
    click.echo("| feature | accuracy (sim) | paper | classify time |")
    click.echo("|---|---:|---:|---:|")
    for name, acc in result.accuracy.items():
        paper = ev.PAPER_ACCURACY.get(name)
        click.echo(
            f"| {name} | {acc:.1f} % | {f'{paper:.1f} %' if paper else '-'} | {result.classify_seconds[name]:.2f} s |"
        )
    out_dir.mkdir(parents=True, exist_ok=True)
    for name in ("both", "depth", "frequency"):
        plots.confusion_matrix(
            result.confusion[name],
            names,
            f"simulated database, {name} (accuracy {result.accuracy[name]:.1f} %)",
            out_dir / f"confusion_{name}.png",
        )
    for name, differ in result.fixed_disagreements.items():
        n = len(result.materials) * len(ev.ORIENTATIONS_DEG)
        worst = max((abs(d[4]) for d in differ), default=0.0)
        click.echo(
            f"fixed vs float, {name}: {len(differ)} of {n} queries labelled differently"
            + (f" (largest float margin between the two labels {worst:.4f} mm^2)" if differ else "")
        )
    conf = {k: ev.top_confusions(result, k) for k in result.confusion}
    click.echo("most frequent confusions (both): " + ", ".join(f"{t}->{p} {n}" for t, p, n in conf["both"]))

    probes = [p for p in ("acryl", "polystyrene", "whiteglass") if p in names] or names[:3]
    angles = [0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0]
    folds = [0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0]
    coarse = np.arange(600.0, 1250.0 + 1e-9, max(step, 2.0))
    orient = [ev.stability(r, names, p, angles, False, coarse, seed + 17) for p in probes]
    fold = [ev.stability(r, names, p, folds, True, coarse, seed + 29) for p in probes]
    plots.stability(
        orient,
        "orientation [deg]",
        "Feature stability vs orientation (cf. Fig. 6)",
        out_dir / "stability_orientation.png",
    )
    plots.stability(
        fold, "fold angle [deg]", "Feature stability vs fold angle (cf. Fig. 7)", out_dir / "stability_fold.png"
    )
    summary = {
        "materials": names,
        "orientations_deg": list(ev.ORIENTATIONS_DEG),
        "stage_mm": [float(stage[0]), float(stage[-1]), step],
        "session_offsets_sd_mm": list(spread),
        "session_drift_sd": list(drift_sd),
        "accuracy": result.accuracy,
        "paper_accuracy": ev.PAPER_ACCURACY,
        "confusions": conf,
        "stability_orientation": orient,
        "stability_fold": fold,
        "fixed_disagreements": result.fixed_disagreements,
        "seconds": {
            "capture": result.capture_seconds,
            "classify": result.classify_seconds,
            "total": time.perf_counter() - t0,
        },
    }
    (out_dir / "results.json").write_text(json.dumps(summary, indent=2))
    click.echo(f"wrote {out_dir}/results.json and figures")


@sim_cli.command("calibrate")
@click.option(
    "--db",
    "db_dir",
    required=True,
    type=click.Path(exists=True, file_okay=False, path_type=Path),
    help="Folder of the real database (.npy per material).",
)
@click.option("--out", "out_dir", default=Path("build/calib"), type=click.Path(file_okay=False, path_type=Path),
              show_default=True, help="Writes data/devices/kinect2_tanaka2017.json, data/materials/tanaka2017.json, "
              "the fit log and the real-vs-simulated plot under this folder.")  # fmt: skip
@click.option(
    "--restarts",
    default=3,
    show_default=True,
    type=click.IntRange(1, 100),
    help="Restarts of the harmonic phases (multimodal fit).",
)
@click.option(
    "--rounds",
    default=2,
    show_default=True,
    type=click.IntRange(1, 20),
    help="Rounds of per-material and joint refinement.",
)
@click.option("--seed", default=0, show_default=True, type=click.IntRange(0, 2**31))
@click.option("--session-drift/--no-session-drift", default=True, show_default=True,
              help="Fit a drift direction of the waveform and every capture's session state "
              "(docs/simulator-model.md 2.2); without it only the per-capture offsets.")  # fmt: skip
def calibrate_cmd(db_dir: Path, out_dir: Path, restarts: int, rounds: int, seed: int, session_drift: bool) -> None:
    """Fit the device profile and material library to the real database's curves (~43 min, one core).

    The other settings are tofmat.sim.calibrate.CalibrationConfig's defaults; the fit's log goes to
    the log file under --out (and with -v to stderr)."""
    import tofmat

    from . import calibrate as cal

    require("scipy.optimize", extra="sim", feature="tofmat sim calibrate")
    require_pyplot(extra="sim", feature="tofmat sim calibrate")  # the fit's figure, written after ~43 min
    config = cal.CalibrationConfig(restarts=restarts, rounds=rounds, seed=seed, session_drift=session_drift)
    table = tofmat.ExemplarTable.from_npy_dir(str(db_dir))
    with progress_bar("calibrating") as progress:
        result = cal.calibrate(table, config=config, progress=progress)
    for kind, path in cal.write_outputs(result, out_dir, table).items():
        click.echo(f"wrote {kind}: {path}")
    click.echo(
        f"median rms {result.median_rms_mm:.3f} mm over {len(result.rms_mm)} materials "
        f"(max {max(result.rms_mm.values()):.3f} mm), {result.runtime_s:.0f} s"
    )


@sim_cli.command("bench")
@click.option("--device", default=DEFAULT_DEVICE, show_default=True)
@click.option("--library", default=DEFAULT_LIBRARY, show_default=True)
@click.option("--frames", default=30, show_default=True, type=click.IntRange(1, 100000))
@click.option(
    "--threads",
    default=0,
    show_default=True,
    type=click.IntRange(0, 1024),
    help="Render threads (0: one per hardware thread).",
)
def bench_cmd(device: str, library: str, frames: int, threads: int) -> None:
    """Render speed (full 512x424 frames with noise) and float decode speed (full frame and 20x20 ROI)."""
    from .. import _tofmat

    r = _renderer(device, library, threads)
    names = r.library.names
    scene = Scene([Target(names[0], 900.0, 20.0, 0.0, 0.0, (96, 72, 416, 352))], names[-1], 2500.0)
    p0 = _tofmat.DecodeTables(r.p0_tables().reshape(3, -1))
    # The noise-free decode of the scene: the noisy frames' error is measured against it (the
    # material's own distortion is not an error).
    clean = _tofmat.decode_frame(r.render(scene, 0, False).raw, p0)
    times = []
    err = []
    decode_t: list[float] = []
    roi_t: list[float] = []
    roi = (246, 202, 266, 222)
    for k in range(frames):
        t0 = time.perf_counter()
        f = r.render(scene, k + 1)
        times.append(time.perf_counter() - t0)
        raw = f.raw  # (a copy out of the frame: not part of the decode's time)
        t1 = time.perf_counter()
        d = _tofmat.decode_frame(raw, p0)
        decode_t.append(time.perf_counter() - t1)
        t2 = time.perf_counter()
        _tofmat.decode_region(raw, p0, roi)
        roi_t.append(time.perf_counter() - t2)
        ok = np.isfinite(d.combined_mm) & np.isfinite(clean.combined_mm) & (f.target.reshape(-1) == 0)
        err.append(np.median(np.abs(d.combined_mm[ok] - clean.combined_mm[ok])))
    t = np.array(times)
    n_threads = threads or os.cpu_count() or 1
    click.echo(
        f"render, {n_threads} thread(s), full frame with noise: median {1e3 * np.median(t):.1f} ms = "
        f"{1 / np.median(t):.0f} frames/s (best {1e3 * t.min():.1f} ms); noise: median |combined depth - "
        f"noise-free| on the target {np.median(err):.2f} mm"
    )
    click.echo(
        f"float decode, one core (9 samples -> phase, amplitude, per-frequency depth, combined depth, Eq. (10) "
        f"features, flags): full frame median {1e3 * np.median(decode_t):.1f} ms (best {1e3 * min(decode_t):.1f}); "
        f"20x20 ROI median {1e6 * np.median(roi_t):.0f} us (best {1e6 * min(roi_t):.0f}), Python call included"
    )


@sim_cli.command("table")
@click.option("--device", default=DEFAULT_DEVICE, show_default=True, help="Device profile name or path.")
@click.option("--library", default=DEFAULT_LIBRARY, show_default=True, help="Material library name or path.")
@click.option("--materials", help="Comma-separated subset (default: the whole library).")
@click.option(
    "--bins",
    "n_bins",
    default=200,
    show_default=True,
    type=click.IntRange(2, 10000),
    help="Depth bins over the range (the real database's: 200 over 600..1200 mm).",
)
@click.option(
    "--range",
    "depth_range",
    default="600,1200",
    show_default=True,
    type=NumberList(float, 300, 2400),
    help="START,END: the first and last bins' depths, mm of combined depth (the range along each ray). "
    "A scene's pixels get labels only within it: cover the ranges at the frame's corners too.",
)
@click.option("--yaw", default=10.0, show_default=True, type=FiniteFloat(-80, 80), help="Target orientation, degrees.")
@click.option(
    "--yaws",
    type=NumberList(float, 0, 60),
    help="Y1,Y2,...: record every material at each of these orientations (degrees, 0..60; instead of --yaw): "
    "the table's entries are MATERIAL@Y, exemplars of one material (labels and rankings name the material; "
    "docs/table-format.md). The calibration, when there is one, is the table's at the first angle.",
)
@click.option(
    "--keep-current",
    is_flag=True,
    help="Leave OUTPUT as it is if it already holds a table with a depth distortion (a table of an older "
    "tofmat, without one, is recorded again; a current one without a calibration is calibrated).",
)
@click.option(
    "--calibration-sessions",
    type=click.IntRange(0, 1000),
    help="Calibrate the recorded table for itself (tofmat table calibrate --source sim) on this many rendered "
    "sessions a material and split; 0: leave it uncalibrated (tofmatd then uses the built-in calibration, "
    f"tuned on the real curves). Default: {CALIBRATION_SESSIONS} with the default device and library, 0 with "
    "others (the calibration renders its sessions with the default simulator).",
)
@click.option(
    "-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path), help="Table file (.tmx)."
)
def table_cmd(device: str, library: str, materials: str | None, n_bins: int, depth_range: list[float], yaw: float,
              yaws: list[float] | None, keep_current: bool, calibration_sessions: int | None,
              output: Path) -> None:  # fmt: skip
    """Record an exemplar table with the simulated camera (what tofmatd on --source sim matches against),
    and calibrate it for itself: the sessions the calibration renders take about 40 s a material at the
    default 6 (about 20 minutes of one core for the whole library)."""
    from .table import database_bins, simulated_table

    if len(depth_range) != 2 or not depth_range[0] < depth_range[1]:
        raise click.BadParameter("give START,END with START < END", param_hint="--range")
    if yaws is not None:
        given = click.get_current_context().get_parameter_source("yaw")
        if given is not ParameterSource.DEFAULT:
            raise click.BadParameter("give --yaw or --yaws, not both", param_hint="--yaws")
        if len(set(yaws)) != len(yaws):
            raise click.BadParameter(f"the angles must differ, got {', '.join(f'{y:g}' for y in yaws)}",
                                     param_hint="--yaws")  # fmt: skip
    default_sim = device == DEFAULT_DEVICE and library == DEFAULT_LIBRARY
    if calibration_sessions is None:
        calibration_sessions = CALIBRATION_SESSIONS if default_sim else 0
    elif calibration_sessions > 0 and not default_sim:
        raise click.BadParameter(
            "the calibration renders its sessions with the default device and library; give 0 with others",
            param_hint="--calibration-sessions",
        )
    r = _renderer(device, library)
    names = [m.strip() for m in materials.split(",")] if materials else list(r.library.names)
    from ..evaluation.angle_tables import MAX_ENTRIES

    if yaws is not None and len(names) * len(yaws) > MAX_ENTRIES:
        raise click.BadParameter(
            f"{len(names)} materials at {len(yaws)} angles are {len(names) * len(yaws)} exemplars: "
            f"a table holds at most {MAX_ENTRIES}",
            param_hint="--yaws",
        )
    entries = [f"{m}@{y:g}" for y in yaws for m in names] if yaws is not None else None
    if keep_current and output.is_file():
        current, why = current_table(output)
        if current is not None and entries is not None and current.materials != entries:
            current, why = (
                None,
                f"its entries are not {len(names)} materials at {', '.join(f'{y:g}' for y in yaws or [])} degrees",
            )
        if current is None:
            click.echo(f"{output}: {why}; recording it again", err=True)
        elif current.calibration is None and calibration_sessions > 0:
            _calibrate_sim_table(current, calibration_sessions, output, "current, not calibrated")
            return
        else:
            click.echo(f"{output}: current (it has a depth distortion); kept")
            return
    if calibration_sessions > 0 and len(set(names)) < 2:
        raise click.BadParameter(
            "a table of one material has nothing to calibrate a choice on: give --calibration-sessions 0",
            param_hint="--materials",
        )
    t0 = time.perf_counter()
    bins = database_bins(n_bins, depth_range[0], depth_range[1])
    with progress_bar("recording materials") as progress:
        table = simulated_table(r, names, bins, yaw_deg=yaws[0] if yaws else yaw, progress=progress)
    output.parent.mkdir(parents=True, exist_ok=True)
    recorded = (
        f"{len(names)} materials x 2 rows x {n_bins} bins of {bins.width_mm:.3f} mm from "
        f"{bins.start_mm:g} mm, recorded in {time.perf_counter() - t0:.1f} s"
    )
    if yaws is not None:
        _record_angles(r, names, yaws, table, calibration_sessions, output, recorded)
        return
    if calibration_sessions == 0:
        table.save(str(output))
        click.echo(f"{output}: {recorded}; not calibrated")
        return
    _calibrate_sim_table(table, calibration_sessions, output, recorded)


def _record_angles(r: Renderer, names: list[str], yaws: list[float], first: ExemplarTable, sessions: int,
                   output: Path, what: str) -> None:  # fmt: skip
    """The table of ``names`` at each of ``yaws`` (evaluation.angle_tables.record_angle_table) with the
    calibration of ``first`` (the table at the first angle) when ``sessions`` > 0: a material's
    calibration (its noise, the confidence's temperatures) holds for it at any angle."""
    from ..evaluation.angle_tables import record_angle_table
    from .own_table import calibrated

    t0 = time.perf_counter()
    if sessions > 0:
        try:
            with progress_bar("calibrating") as progress:
                first = calibrated(first, sessions, progress)
        except (ValueError, RuntimeError) as e:
            raise click.ClickException(f"calibrating {output}: {e}") from e
    with progress_bar("recording angles") as progress:
        table, _ = record_angle_table(names, yaws, first, progress, renderer=r, distortion=True)
    table.save(str(output))
    how = f"calibrated on {sessions} sessions a material and split" if sessions > 0 else "not calibrated"
    click.echo(f"{output}: {len(names)} materials at {', '.join(f'{y:g}' for y in yaws)} degrees, "
               f"{len(table.materials)} exemplars ({what} at {yaws[0]:g}); {how} in "
               f"{time.perf_counter() - t0:.1f} s")  # fmt: skip


def _calibrate_sim_table(table: ExemplarTable, sessions: int, output: Path, what: str) -> None:
    """Calibrate a table the simulated camera recorded (own_table.calibrated) and write it to
    ``output`` (ExemplarTable.save replaces it atomically): nothing is written if the calibration fails."""
    from .own_table import calibrated

    t0 = time.perf_counter()
    try:
        with progress_bar("calibrating") as progress:
            done = calibrated(table, sessions, progress)
    except (ValueError, RuntimeError) as e:
        raise click.ClickException(f"calibrating {output}: {e}") from e
    done.save(str(output))
    click.echo(f"{output}: {what}; calibrated on {sessions} sessions a material and split in "
               f"{time.perf_counter() - t0:.1f} s")  # fmt: skip
