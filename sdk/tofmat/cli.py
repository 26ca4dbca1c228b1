"""The `tofmat` command line."""

from __future__ import annotations

import json
import logging
import sys
from pathlib import Path
from typing import Any, Callable, TypeVar

import click
import numpy as np

from . import Classifier, ClassificationResult, ExemplarTable, __version__
from .tools.tables import open_table

F = TypeVar("F", bound=Callable[..., Any])
log = logging.getLogger("tofmat")


def user_errors(fn: F) -> F:
    """Bad input (ValueError, including FormatError) and refused files (OSError) end in one clear line."""

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except (ValueError, OSError) as e:
            raise click.ClickException(str(e)) from e

    wrapper.__name__ = fn.__name__
    wrapper.__doc__ = fn.__doc__
    return wrapper  # type: ignore[return-value]


def csv_list(value: str | None) -> list[str] | None:
    return [v.strip() for v in value.split(",") if v.strip()] if value else None


@click.group()
@click.version_option(__version__, prog_name="tofmat")
@click.option("-v", "--verbose", is_flag=True, help="Log progress to stderr.")
def main(verbose: bool) -> None:
    """Material classification from Time-of-Flight depth distortion."""
    logging.basicConfig(level=logging.INFO if verbose else logging.WARNING, format="%(levelname)s %(message)s")


@main.group()
def table() -> None:
    """Build and inspect exemplar tables."""


@table.command("import")
@click.argument("directory", type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path), help="Table file to write (.tmx).")
@click.option("--bin-start", default=600.0, show_default=True, help="Left edge of the first bin, mm.")
@click.option("--bin-stop", default=1200.0, show_default=True, help="Left edge of the last bin, mm (numpy.linspace convention).")
@user_errors
def table_import(directory: Path, output: Path, bin_start: float, bin_stop: float) -> None:
    """Import a folder of <material>.npy curves into a compact table file."""
    t = ExemplarTable.from_npy_dir(directory, bin_start_mm=bin_start, bin_stop_mm=bin_stop)
    t.save(output)
    saved = ExemplarTable.load(output)
    click.echo(
        f"wrote {output}: {len(saved)} materials x {saved.n_rows} rows x {saved.n_bins} bins, "
        f"step {saved.quant_step_mm:g} mm, {output.stat().st_size} bytes"
    )


def table_summary(path: Path, t: ExemplarTable) -> dict[str, Any]:
    return {
        "path": str(path),
        "bytes": path.stat().st_size if path.is_file() else None,
        "materials": t.materials,
        "valid_elements": dict(zip(t.materials, t.valid_counts)),
        "rows": [{"freq_mhz": f, "ref_freq_mhz": r} for f, r in t.rows],
        "bins": {"start_mm": t.bins.start_mm, "width_mm": t.bins.width_mm, "count": t.bins.count},
        "quant_step_mm": t.quant_step_mm,
    }


@table.command("info")
@click.argument("path", type=click.Path(exists=True, path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@user_errors
def table_info(path: Path, as_json: bool) -> None:
    """Describe a table file (or a folder of .npy curves)."""
    t = open_table(path)
    s = table_summary(path, t)
    if as_json:
        click.echo(json.dumps(s, indent=2))
        return
    b = t.bins
    click.echo(f"{path}: {len(t)} materials x {t.n_rows} rows x {t.n_bins} bins" + (f", {s['bytes']} bytes" if s["bytes"] else ""))
    click.echo(f"bins: {b.count} from {b.start_mm:g} mm, width {b.width_mm:.6g} mm (to {b.start_mm + b.count * b.width_mm:g} mm)")
    click.echo("rows: " + ", ".join(f"d({f} MHz) - d({r} MHz)" for f, r in t.rows))
    click.echo(f"quantisation step: {t.quant_step_mm:g} mm" if t.quant_step_mm else "not quantised (float values)")
    per_mat = t.n_rows * t.n_bins
    for name, n in zip(t.materials, t.valid_counts):
        click.echo(f"  {name:<14s} {n:5d}/{per_mat} valid")


def result_dict(r: ClassificationResult, top: int) -> dict[str, Any]:
    return {
        "material": r.material,
        "index": r.index,
        "distance": r.distance,
        "valid": r.valid,
        "ranking": [{"material": m.material, "index": m.index, "distance": m.distance, "valid": m.valid} for m in r.ranking[:top]],
    }


@main.command()
@click.option("--table", "table_path", required=True, type=click.Path(exists=True, path_type=Path), help="Table file (.tmx) or folder of .npy curves.")
@click.argument("query", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--materials", help="Comma-separated candidate materials (default: all).")
@click.option("--top", default=5, show_default=True, help="Ranking entries to print.")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@user_errors
def classify(table_path: Path, query: Path, materials: str | None, top: int, as_json: bool) -> None:
    """Classify QUERY.npy: (rows, bins) or a batch (n, rows, bins), NaN = missing."""
    t = open_table(table_path)
    try:
        q = np.load(query, allow_pickle=False)
    except (ValueError, EOFError) as e:
        raise ValueError(f"{query}: not a readable .npy array: {e}") from e
    clf = Classifier(t, backend="float", materials=csv_list(materials))
    single = q.ndim == 2
    results = [clf.classify(q)] if single else clf.classify_batch(q)
    if as_json:
        out = [result_dict(r, top) for r in results]
        click.echo(json.dumps(out[0] if single else out, indent=2))
        return
    for i, r in enumerate(results):
        prefix = "" if single else f"[{i}] "
        click.echo(f"{prefix}{r.material}  distance {r.distance:.4f} mm^2  valid {r.valid}")
        for m in r.ranking[1:top]:
            click.echo(f"{' ' * len(prefix)}  then {m.material:<14s} {m.distance:.4f}")


@main.group()
def plot() -> None:
    """Figures."""


@plot.command("table")
@click.argument("path", type=click.Path(exists=True, path_type=Path))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path))
@user_errors
def plot_table_cmd(path: Path, output: Path) -> None:
    """Plot every material's distortion curves (like the paper's Fig. 4)."""
    from .tools.plot import plot_table

    plot_table(open_table(path), output, title=f"{path.name}: relative depth distortion")
    click.echo(f"wrote {output}")


@main.command()
@click.option("--table", "table_path", required=True, type=click.Path(exists=True, path_type=Path), help="Table file or .npy folder.")
@click.option("--windows", default="1,3,10,30,100", show_default=True, help="Window lengths in bins.")
@click.option("--noise", default=0.3, show_default=True, help="Gaussian noise sigma, mm.")
@click.option("--per-material", default=40, show_default=True, help="Windows per material and length.")
@click.option("--seed", default=0, show_default=True)
@click.option("--backends", default="float,fixed", show_default=True, help="Classifier backends to compare.")
@click.option("--json", "as_json", is_flag=True)
@user_errors
def bench(table_path: Path, windows: str, noise: float, per_material: int, seed: int, backends: str,
          as_json: bool) -> None:  # fmt: skip
    """Accuracy and time per query on noisy windows of the table's own curves, per backend."""
    from .tools.bench import bench_windows, format_markdown

    lengths = [int(w) for w in csv_list(windows) or []]
    table = open_table(table_path)
    rows = [r for b in csv_list(backends) or [] for r in bench_windows(table, lengths, noise, per_material, seed, b)]
    click.echo(json.dumps([r.as_dict() for r in rows], indent=2) if as_json else format_markdown(rows, noise))


@main.command()
@click.option("--table", "table_path", required=True, type=click.Path(exists=True, path_type=Path), help="Table file or .npy folder.")
@click.option("--sweeps", default=8, show_default=True)
@click.option("--sweep-bins", default=60, show_default=True, help="Depth bins one sweep passes through.")
@click.option("--frames-per-bin", default=2, show_default=True)
@click.option("--noise", default=0.3, show_default=True, help="Per-frame noise sigma, mm.")
@click.option("--seed", default=1, show_default=True)
@user_errors
def demo(table_path: Path, sweeps: int, sweep_bins: int, frames_per_bin: int, noise: float, seed: int) -> None:
    """Simulated hand-held sweeps classified live as they grow (partial matching)."""
    from .tools.demo import run_demo

    run_demo(open_table(table_path), sweeps, sweep_bins, frames_per_bin, noise, seed, echo=click.echo)


@main.command()
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
def devices(as_json: bool) -> None:
    """List Kinect v2 cameras on the USB bus; exit 1 with the reason when there is none usable."""
    from . import UsbError, _tofmat

    try:
        found = _tofmat.kinect.list_devices()
    except UsbError as e:
        raise click.ClickException(str(e)) from e
    if as_json:
        click.echo(json.dumps(found, indent=2))
    for d in found if not as_json else []:
        state = "ok" if d["accessible"] else f"not usable: {d['problem']}"
        click.echo(f"Kinect v2 045e:{d['product_id']:04x} at USB {d['port']} serial {d['serial'] or '?'} ({state})")
    if not found:
        raise click.ClickException("no Kinect v2 found (USB 045e:02d8 or 045e:02c4); is it plugged into a USB 3 port "
                                   "and powered?")
    if not any(d["accessible"] for d in found):
        raise click.ClickException(f"no usable Kinect v2: {found[0]['problem']}")


def _register_sim() -> None:
    from .sim.cli import sim_cli

    main.add_command(sim_cli)


_register_sim()

if __name__ == "__main__":
    sys.exit(main())
