# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""`tofmat report`: runs the benchmarks and writes one Markdown report, error against run time.

The figures come from what runs on this host, now: the Python SDK's classifier
(:func:`tofmat.tools.bench.bench_windows`), ``tofmat_bench_fixed --op all`` and
``tofmat_bench_profiles --profile all`` of the C++ build, the fixed-point path's stability cases
computed in Python (:mod:`.stability`) and the decode's error-budget test of the C++ suite. The
aarch64 instruction counts are read from files a cross run kept (``make report-counts``); when
there are none, the report says how to get them.
"""

from __future__ import annotations

import math
import os
import shlex
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypeVar

from .._extras import require_pyplot
from .._progress import Progress
from ..tools.bench import BenchRow, bench_windows, format_markdown
from ..tools.tables import open_table
from . import cppbench as cb
from .families import Family, Point, Stat
from .figures import plot_families
from .machine import Machine, cmake_cache_value, describe_machine
from .stability import CLASSIFIER_BUDGET, CPP_TESTS_ONLY, StabilityRow, classifier_stability

_T = TypeVar("_T")

WINDOWS = (1, 3, 10, 30, 100)
REPORT_NAME = "report.md"

# The report's sections, in order (tests check that each is there).
SECTIONS = (
    "Machine",
    "Summary: the Pareto fronts",
    "1. Error against run time",
    "1.1 Classifier per query, Python SDK",
    "1.2 Eq. (12) per query, C++",
    "1.3 Decode per frame",
    "1.4 Decode and its stages, per frame",
    "1.5 Scene profiles per frame",
    "1.6 aarch64 instruction counts",
    "2. Numerical stability of the fixed-point path",
    "2.1 Eq. (12) classifier at its stiff cases, computed here",
    "2.2 Decode, depth bins and box mean at their stiff cases, C++",
    "2.3 What only the C++ tests check",
    "3. How this report was made",
)

STABILITY_CASES = 7  # the cases classifier_stability() ticks through


class ReportError(RuntimeError):
    """The report could not be made (a benchmark failed, or printed what the report cannot read)."""


@dataclass
class _Steps:
    """Tells the progress callback about each step of a known total."""

    progress: Progress | None
    total: int
    done: int = 0

    def __call__(self, what: str) -> None:
        if self.progress is not None:
            self.progress(min(self.done, self.total), self.total, what)
        self.done += 1

    def finish(self) -> None:
        if self.progress is not None:
            self.progress(self.total, self.total, "done")


@dataclass
class _Results:
    machine: Machine
    table_path: Path
    out_dir: Path
    table_desc: str
    quick: bool
    runs: int
    per_material: int
    noise_mm: float
    python_rows: list[list[BenchRow]] = field(default_factory=list)  # per run: float rows then fixed rows
    fixed: list[cb.FixedBench] = field(default_factory=list)
    fixed_missing: str = ""
    fixed_db: str = ""  # the database tofmat_bench_fixed read
    profiles: list[cb.ProfilesBench] = field(default_factory=list)
    profiles_missing: str = ""
    insn: cb.InsnCounts | None = None
    insn_file: Path | None = None
    profile_counts: list[cb.MdTable] = field(default_factory=list)
    profile_counts_file: Path | None = None
    stability: list[StabilityRow] = field(default_factory=list)
    stiff: list[cb.StiffCaseRow] = field(default_factory=list)
    decode_test: cb.DecodeTestFigures | None = None
    decode_test_note: str = ""
    commands: list[str] = field(default_factory=list)
    raw_files: list[Path] = field(default_factory=list)
    figures: list[tuple[str, Path]] = field(default_factory=list)  # (caption, path relative to out_dir)
    seconds: float = 0.0
    load_end: str = ""  # load average when the benchmarks were done (a shared machine's other work)


def write_report(
    out_dir: Path,
    table: Path,
    quick: bool = False,
    progress: Progress | None = None,
    *,
    runs: int | None = None,
    per_material: int | None = None,
    noise_mm: float = 0.3,
    build_dir: Path = Path("build/release"),
    counts_dir: Path = Path("build/bench"),
) -> Path:
    """Runs the benchmarks and writes ``out_dir/report.md`` with its figures in ``out_dir/figures``
    and the benchmarks' own output in ``out_dir/raw``; returns the Markdown file.

    ``table``: a .tmx table file or a folder of the database's .npy curves. ``quick``: tiny versions
    of everything (one run, few queries, the C++ benchmarks with one repetition: seconds, for tests;
    its timings are not worth reading). ``runs``: how many times each benchmark runs (the report
    gives medians over them; default 5, 1 when quick). ``per_material``: noisy windows per material
    and length for the Python classifier (default 40 as ``make bench``, 3 when quick).
    ``build_dir``: the C++ build whose tests/bench and tests/cpp executables run (a missing one is
    reported as not measured). ``counts_dir``: where ``make report-counts`` kept the aarch64
    instruction counts (insn_counts.md, profile_counts.md).
    """
    require_pyplot(extra="plot", feature="tofmat report")
    t_start = time.monotonic()
    runs = runs if runs is not None else (1 if quick else 5)
    per_material = per_material if per_material is not None else (3 if quick else 40)
    if runs < 1 or per_material < 1:
        raise ValueError("runs and per_material must be at least 1")
    if not math.isfinite(noise_mm) or noise_mm < 0:
        raise ValueError(f"noise_mm must be a finite number >= 0, got {noise_mm}")
    out_dir = Path(out_dir)
    table = Path(table)
    exemplars = open_table(table)
    raw_dir, fig_dir = out_dir / "raw", out_dir / "figures"
    raw_dir.mkdir(parents=True, exist_ok=True)
    fig_dir.mkdir(parents=True, exist_ok=True)

    bench_dir = build_dir / "tests" / "bench"
    fixed_exe, profiles_exe = bench_dir / "tofmat_bench_fixed", bench_dir / "tofmat_bench_profiles"
    decode_test_exe = build_dir / "tests" / "cpp" / "test_fixed_decode"
    n_figures = 6
    steps = _Steps(progress, total=runs * 3 + STABILITY_CASES + 2 + n_figures + 1)

    res = _Results(
        machine=describe_machine(build_dir),
        table_path=table,
        out_dir=out_dir,
        table_desc=f"{table} ({len(exemplars)} materials x {exemplars.n_rows} rows x {exemplars.n_bins} bins"
        + (f", step {exemplars.quant_step_mm:g} mm" if exemplars.quant_step_mm > 0 else ", imported from .npy")
        + ")",
        quick=quick,
        runs=runs,
        per_material=per_material,
        noise_mm=noise_mm,
    )

    fixed_cmd = [str(fixed_exe), "--op", "all"] + (["--reps", "1"] if quick else [])
    if table.is_dir():
        fixed_cmd += ["--db", str(table)]
        res.fixed_db = str(table)
    else:  # it reads .npy folders only: the folder compiled into it
        db = cmake_cache_value(build_dir, "TOFMAT_DB_DIR")
        res.fixed_db = (db or "the folder compiled into it") + " (it reads .npy folders, not .tmx: its compiled-in one)"
    profiles_cmd = [str(profiles_exe), "--profile", "all", "--table", str(table)] + (["--reps", "1"] if quick else [])
    res.commands.append(
        f"# in this Python ({sys.executable}), for B in float, fixed:\n"
        f"tofmat.tools.bench.bench_windows(table, {list(WINDOWS)}, noise_mm={noise_mm:g}, per_material={per_material}, "
        "seed=0, backend=B, repeats=1)"
    )
    res.commands += [shlex.join(fixed_cmd), shlex.join(profiles_cmd)]
    if not fixed_exe.is_file():
        res.fixed_missing = f"`{fixed_exe}` is not built (`make build-cpp` builds it)"
    if not profiles_exe.is_file():
        res.profiles_missing = f"`{profiles_exe}` is not built (`make build-cpp` builds it, with the daemon)"

    # The runs, interleaved, so that a slow period of a shared machine spreads over every benchmark.
    for k in range(runs):
        steps(f"Python classifier, run {k + 1} of {runs}")
        rows = []
        for backend in ("float", "fixed"):
            rows += bench_windows(exemplars, list(WINDOWS), noise_mm, per_material, 0, backend, repeats=1)
        res.python_rows.append(rows)
        raw = raw_dir / f"python_bench.{k + 1}.md"
        raw.write_text(format_markdown(rows, noise_mm) + "\n")
        res.raw_files.append(raw)

        steps(f"tofmat_bench_fixed, run {k + 1} of {runs}")
        if not res.fixed_missing:
            raw = raw_dir / f"bench_fixed.{k + 1}.txt"
            res.raw_files.append(raw)
            text = _run(fixed_cmd, 900, raw)
            res.fixed.append(_parse(cb.parse_bench_fixed, text, raw))

        steps(f"tofmat_bench_profiles, run {k + 1} of {runs}")
        if not res.profiles_missing:
            raw = raw_dir / f"bench_profiles.{k + 1}.txt"
            res.raw_files.append(raw)
            text = _run(profiles_cmd, 1800, raw)
            res.profiles.append(_parse(cb.parse_bench_profiles, text, raw))

    _check_same_errors(res)

    insn_file, prof_file = counts_dir / "insn_counts.md", counts_dir / "profile_counts.md"
    if insn_file.is_file():
        res.insn = _parse(lambda t: cb.parse_insn_counts(t, str(insn_file)), insn_file.read_text(), insn_file)
        res.insn_file = insn_file
    if prof_file.is_file():
        res.profile_counts = _parse(
            lambda t: cb.parse_profile_counts(t, str(prof_file)), prof_file.read_text(), prof_file
        )
        res.profile_counts_file = prof_file

    res.stability = classifier_stability(
        exemplars, quick=quick, noise_mm=noise_mm, tick=lambda w: steps(f"stability: {w}")
    )

    steps("the C++ stages' stiff cases")
    if not res.fixed_missing:
        cmd = [str(fixed_exe), "--op", "stiff"]
        res.commands.append(shlex.join(cmd))
        raw = raw_dir / "bench_fixed.stiff.txt"
        res.raw_files.append(raw)
        res.stiff = _parse(cb.parse_stiff_cases, _run(cmd, 600, raw), raw)

    steps("the decode's C++ error-budget test")
    if decode_test_exe.is_file():
        cmd = [str(decode_test_exe), f"--gtest_filter={cb.DECODE_TEST}"]
        res.commands.append(shlex.join(cmd))
        raw = raw_dir / "test_fixed_decode.txt"
        res.raw_files.append(raw)
        try:
            res.decode_test = cb.parse_decode_test(cb.run_program(cmd, 600, raw))
            if res.decode_test is None:
                res.decode_test_note = f"it ran, but printed no '[ measured ]' line in the expected form (see {raw})"
        except cb.BenchRunError as e:
            res.decode_test_note = f"it failed: {e}"
    else:
        res.decode_test_note = f"`{decode_test_exe}` is not built (`make build-cpp`)"

    families = _families(res)
    for name, caption, fams in families:
        steps(f"figure {name}")
        if any(f.points for f in fams):
            path = plot_families(fig_dir / f"{name}.png", caption, [f for f in fams if f.points])
            res.figures.append((caption, path.relative_to(out_dir)))

    steps("writing the report")
    res.seconds = time.monotonic() - t_start
    if hasattr(os, "getloadavg"):
        res.load_end = " / ".join(f"{v:.2f}" for v in os.getloadavg())
    md = out_dir / REPORT_NAME
    md.write_text(_markdown(res, families))
    steps.finish()
    return md


# ---------------------------------------------------------------- running and checking


def _run(cmd: Sequence[str], timeout_s: float, raw: Path) -> str:
    try:
        return cb.run_program(cmd, timeout_s, raw)
    except cb.BenchRunError as e:
        raise ReportError(str(e)) from e


def _parse(parser: Callable[[str], _T], text: str, raw: Path) -> _T:
    try:
        return parser(text)
    except cb.BenchFormatError as e:
        raise ReportError(
            f"{e}. Its output has changed: sdk/tofmat/report/cppbench.py reads it and needs updating "
            f"(the output is in {raw})"
        ) from e


def _check_same_errors(res: _Results) -> None:
    """Fixed seeds: every run must give the same accuracies and errors (only times may move)."""
    first = res.python_rows[0]
    for rows in res.python_rows[1:]:
        for a, b in zip(first, rows, strict=True):
            if a.accuracy != b.accuracy:
                raise ReportError(
                    f"the Python classifier's accuracy moved between runs ({a.backend}, "
                    f"{a.window_bins} bins): {a.accuracy} vs {b.accuracy}"
                )
    for fb in res.fixed[1:]:
        if [(d.depth_err_mm, d.combined_err_mm) for d in fb.decode] != [
            (d.depth_err_mm, d.combined_err_mm) for d in res.fixed[0].decode
        ] or [(n.float_accuracy, n.fixed_accuracy) for n in fb.nn] != [
            (n.float_accuracy, n.fixed_accuracy) for n in res.fixed[0].nn
        ]:
            raise ReportError("tofmat_bench_fixed's errors or accuracies moved between runs (fixed seeds)")
    for pb in res.profiles[1:]:
        if [(p.truth, p.agrees) for p in pb.profiles] != [(p.truth, p.agrees) for p in res.profiles[0].profiles]:
            raise ReportError("tofmat_bench_profiles's errors moved between runs (fixed scenes and seeds)")


# ---------------------------------------------------------------- families


def _pct_wrong(accuracy: float) -> float:
    return 100.0 * (1.0 - accuracy)


def _families(res: _Results) -> list[tuple[str, str, list[Family]]]:
    """(file name, caption, panels) of every figure."""
    out: list[tuple[str, str, list[Family]]] = []
    runs = len(res.python_rows)

    py = Family(
        "classifier_python",
        "classify() from Python, one query",
        f"us per query (median of {runs} run(s))",
        "% wrong (1 - accuracy)",
        cost_unit="us",
        error_unit="% wrong",
    )
    for i, r in enumerate(res.python_rows[0]):
        cost = Stat.of([rows[i].us_per_query for rows in res.python_rows])
        py.points.append(Point(r.backend, f"{r.window_bins} bins", cost, _pct_wrong(r.accuracy)))
    out.append(("classifier_python", "Classifier per query, Python SDK (bench_windows)", [py]))

    nn = Family(
        "nn_cpp",
        "FloatClassifier / FixedClassifier in C++, one query",
        f"us per query (median of {len(res.fixed)} run(s))",
        "% wrong (1 - accuracy)",
        cost_unit="us",
        error_unit="% wrong",
    )
    dec = Family(
        "decode",
        "decode of a 512x424 frame",
        f"ms per frame (median of {len(res.fixed)} run(s))",
        "max combined-depth error vs float, mm",
        cost_unit="ms",
        error_unit=" mm",
    )
    frame = Family(
        "frame",
        "decode + per-pixel classification, 29 materials",
        f"ms per frame (median of {len(res.fixed)} run(s))",
        "% of pixels not their band's material",
        cost_unit="ms",
        error_unit="% wrong",
    )
    unpack = Family(
        "unpack",
        "11-bit unpack of a depth packet",
        f"ms per packet (median of {len(res.fixed)} run(s))",
        "differs from the definition (0: bit for bit)",
        cost_unit="ms",
        error_unit=" (0: exact)",
    )
    if res.fixed:
        f0 = res.fixed[0]
        for i, q in enumerate(f0.nn):
            for which in ("float", "fixed"):
                cost = Stat.of([(fb.nn[i].float_us if which == "float" else fb.nn[i].fixed_us) for fb in res.fixed])
                acc = q.float_accuracy if which == "float" else q.fixed_accuracy
                nn.points.append(Point(which, f"{q.window} bins", cost, _pct_wrong(acc)))
        for i, d in enumerate(f0.decode):
            cost = Stat.of([fb.decode[i].frame_ms for fb in res.fixed])
            name = "float (reference)" if d.kernel == "float" else f"fixed {d.kernel}"
            dec.points.append(Point(name, "", cost, d.combined_err_mm))
        wrong = 100.0 * (1.0 - f0.composite.right_fraction)
        for i, s in enumerate(f0.stages):
            if _whole_frame(s.stage):
                cost = Stat.of([fb.stages[i].median_ms for fb in res.fixed])
                label = "fused" if "fused" in s.stage else "decode, then classify"
                note = "" if s.kernel == f0.best_kernel else f"the {f0.best_kernel} kernel's labels: bit-exact"
                frame.points.append(Point(f"fixed {s.kernel}", label, cost, wrong, note))
        for i, u in enumerate(f0.unpack):
            cost = Stat.of([fb.unpack[i].whole_ms for fb in res.fixed])
            unpack.points.append(Point(u.kernel, "", cost, 0.0 if u.equals_definition else 1.0))
    out.append(("nn_cpp", "Eq. (12) per query, C++ (tofmat_bench_fixed)", [nn]))
    out.append(("decode", "Decode per frame (tofmat_bench_fixed)", [dec]))
    out.append(("frame", "Decode and its stages per frame (tofmat_bench_fixed)", [frame, unpack]))

    prof: list[Family] = []
    if res.profiles:
        for i, p in enumerate(res.profiles[0].profiles):
            if p.name.startswith("sorting-idle") or math.isnan(p.right_fraction):
                continue
            fam = Family(
                f"profile_{i}",
                p.name,
                f"ms per frame (median of {len(res.profiles)} run(s))",
                "% wrong against the simulator's truth",
                cost_unit="ms",
                error_unit="% wrong",
            )
            cost = Stat.of([pb.profiles[i].median_ms for pb in res.profiles])
            fam.points.append(Point("fixed (the daemon's)", "", cost, 100.0 * (1.0 - p.right_fraction)))
            float_wrong = _float_wrong(res.profiles[0], p.name)
            if not math.isnan(p.float_ms) and not math.isnan(float_wrong):
                cost = Stat.of([pb.profiles[i].float_ms for pb in res.profiles])
                fam.points.append(Point("float backend", "", cost, float_wrong))
            prof.append(fam)
    out.append(("profiles", "Scene profiles per frame (tofmat_bench_profiles)", prof))

    arm: list[Family] = []
    if res.insn is not None:
        arm = _insn_families(res)
    out.append(("aarch64", "aarch64 instructions under qemu (make bench-cross)", arm))
    return out


def _whole_frame(stage: str) -> bool:
    """A composite stage that decodes and classifies a whole frame (the frame family's work)."""
    return "decode" in stage and "classification" in stage


def _float_wrong(pb: cb.ProfilesBench, profile: str) -> float:
    """% of the float backend's final labels that are wrong, from the notes (NaN when not printed)."""
    key = profile.split()[0]
    labels = pb.labels.get(key)
    if not labels:
        return math.nan
    return 100.0 * sum(1 for target, _fx, fl in labels if fl != target) / len(labels)


def _insn_families(res: _Results) -> list[Family]:
    """Instructions per unit (cost) with the error the host measured for the same path: the NEON
    kernels are bit-exact with the scalar ones, so a kernel's error is the host's."""
    assert res.insn is not None
    fams: list[Family] = []
    f0 = res.fixed[0] if res.fixed else None
    dec_err = {d.kernel: d.combined_err_mm for d in f0.decode} if f0 else {}
    fixed_err = next((v for k, v in dec_err.items() if k != "float"), math.nan)
    for row in res.insn.rows:
        if row.op not in ("decode", "nn") or "bins" in row.unit:
            continue
        if row.op == "decode":
            fam = Family(
                "arm_decode",
                f"decode, {row.unit}",
                "aarch64 instructions per frame",
                "max combined-depth error vs float, mm (host)",
                cost_unit="instructions",
                error_unit=" mm",
            )
            errs = (0.0, fixed_err, fixed_err)
        else:
            if f0 is None:
                continue
            n = sum(r.queries for r in f0.nn)
            fl = 100.0 * (1.0 - sum(r.float_accuracy * r.queries for r in f0.nn) / n)
            fx = 100.0 * (1.0 - sum(r.fixed_accuracy * r.queries for r in f0.nn) / n)
            fam = Family(
                "arm_nn",
                f"nn, {row.unit}",
                "aarch64 instructions per query",
                "% wrong over every window (host)",
                cost_unit="instructions",
                error_unit="% wrong",
            )
            errs = (fl, fx, fx)
        for name, insns, err in zip(
            ("float", "fixed scalar", "fixed NEON"),
            (row.float_insns, row.scalar_insns, row.neon_insns),
            errs,
            strict=True,
        ):
            if not math.isnan(insns) and not math.isnan(err):
                fam.points.append(Point(name, "", Stat(insns, insns, insns, 1), err))
        fams.append(fam)
    return fams


# ---------------------------------------------------------------- Markdown


def _f(x: float, fmt: str = "{:.2f}") -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else fmt.format(x)


def _g(x: float) -> str:
    """A small error in a readable form: 0, 3.9e-03."""
    if math.isnan(x):
        return "-"
    return "0" if x == 0 else f"{x:.3g}" if 1e-3 <= abs(x) < 1e4 else f"{x:.2e}"


def _table(header: Sequence[str], rows: Sequence[Sequence[str]], align: str = "") -> list[str]:
    spec = align or "l" + "r" * (len(header) - 1)
    sep = ["---:" if a == "r" else "---" for a in spec]
    return ["| " + " | ".join(header) + " |", "|" + "|".join(sep) + "|"] + ["| " + " | ".join(r) + " |" for r in rows]


def _front_marks(fam: Family) -> list[str]:
    front = set(fam.front())
    return ["**yes**" if i in front else "" for i in range(len(fam.points))]


def _markdown(res: _Results, families: list[tuple[str, str, list[Family]]]) -> str:
    fam = {f.key: f for _n, _c, fs in families for f in fs}
    figs = dict((str(p.stem), (c, p)) for c, p in res.figures)
    L: list[str] = []
    add = L.append

    def table(header: Sequence[str], rows: Sequence[Sequence[str]], align: str = "") -> None:
        L.extend(_table(header, rows, align))

    def figure(name: str) -> None:
        if name in figs:
            caption, path = figs[name]
            add(f"![{caption}]({path.as_posix()})")
            add("")

    add("# tofmat report: error against run time")
    add("")
    add(
        f"Made by `tofmat report` in {res.seconds:.0f} s"
        + (" with `--quick` (tiny runs: the timings are not worth reading)" if res.quick else "")
        + f". Table: {res.table_desc}. Every timing is on one thread of this host; each figure is the median of "
        f"{res.runs} run(s) of its benchmark (the runs interleaved), with the range over the runs beside it. "
        "Errors do not move between runs (fixed seeds; checked)."
    )
    add("")
    add(f"## {SECTIONS[0]}")
    add("")
    table(["what", "this host"], [[k, v] for k, v in res.machine.rows()], "ll")
    add("")

    add(f"## {SECTIONS[1]}")
    add("")
    add("The points that no other point of their family beats on both error and cost:")
    add("")
    for _n, _c, fs in families:
        for f in fs:
            if not f.points:
                continue
            pts = "; ".join(
                f"{f.points[i].series}{(', ' + f.points[i].label) if f.points[i].label else ''}: "
                f"{_g(f.points[i].error)}{f.error_unit} at {_f(f.points[i].cost.median, '{:,.4g}')} {f.cost_unit}"
                for i in f.front()
            )
            add(f"- **{f.title}**: {pts}")
    add("")
    within = sum(r.within_budget for r in res.stability) + sum(r.within for r in res.stiff)
    total = len(res.stability) + len(res.stiff)
    add(
        f"Numerical stability (section 2): {within} of {total} stiff-case rows within the budget of docs/numerics.md"
        + ("." if within == total else " (**not all**: see section 2).")
        + (f" The C++ stages' cases were not measured: {res.fixed_missing}." if not res.stiff else "")
    )
    add("")

    add(f"## {SECTIONS[2]}")
    add("")
    add(
        "Each family holds paths that do the same work; a point is on the Pareto front when no other point of its "
        "family is at most as costly and at most as wrong, and better on one. In the figures the front's points are "
        "filled and joined by a dashed staircase; a horizontal bar spans a point's cost over the runs."
    )
    add("")

    def section_1_1_python() -> None:  # 1.1 Python
        add(f"### {SECTIONS[3]}")
        add("")
        add(
            f"`tofmat.tools.bench.bench_windows` (as `make bench`): windows of consecutive depth bins of the table's own "
            f"curves with N(0, {res.noise_mm:g} mm) noise, {res.per_material} per material and length, seed 0; accuracy "
            "over all materials. Time per query: the median of single `classify()` calls (the Python call and the result "
            "objects included), and `classify_batch()` time over the queries."
        )
        add("")
        py = fam["classifier_python"]
        rows = []
        marks = _front_marks(py)
        for i, r in enumerate(res.python_rows[0]):
            p = py.points[i]
            batch = Stat.of([rr[i].us_per_query_batch for rr in res.python_rows])
            rows.append(
                [
                    r.backend,
                    str(r.window_bins),
                    str(r.queries),
                    f"{100 * r.accuracy:.1f} %",
                    f"{p.error:.1f}",
                    _f(p.cost.median),
                    p.cost.spread("{:.2f}"),
                    _f(batch.median),
                    marks[i],
                ]
            )
        table(
            [
                "backend",
                "window (bins)",
                "queries",
                "accuracy",
                "% wrong",
                "us/query (single)",
                "range over runs",
                "us/query (batch)",
                "Pareto",
            ],
            rows,
            "lrrrrrrrl",
        )
        add("")
        figure("classifier_python")

    def section_1_2_c_nn() -> None:  # 1.2 C++ nn
        add(f"### {SECTIONS[4]}")
        add("")
        if not res.fixed:
            add(f"Not measured: {res.fixed_missing}.")
            add("")
        else:
            f0 = res.fixed[0]
            add(
                f"`tofmat_bench_fixed --op all`, nearest neighbour: `FloatClassifier` against `FixedClassifier` on the "
                f"database {res.fixed_db}, imported at bins 600..1200 mm (fixed step {f0.nn_step_mm:g} mm, compact "
                f"table {f0.compact_bytes:,} bytes), the queries of `make bench` made in C++ (seed 1); C++ calls, no Python. "
                f"Time per query: each run's {f0.nn_reps or 'median'} divided by the queries; this host's kernel for the "
                "distance is the scalar one (NEON is aarch64's)."
            )
            add("")
            nn = fam["nn_cpp"]
            marks = _front_marks(nn)
            rows = []
            for i, p in enumerate(nn.points):
                r = f0.nn[i // 2]
                acc = r.float_accuracy if p.series == "float" else r.fixed_accuracy
                rows.append(
                    [
                        p.series,
                        str(r.window),
                        str(r.queries),
                        f"{100 * acc:.1f} %",
                        f"{p.error:.1f}",
                        _f(p.cost.median),
                        p.cost.spread("{:.2f}"),
                        str(r.labels_differ) if p.series == "fixed" else "",
                        marks[i],
                    ]
                )
            table(
                [
                    "path",
                    "window (bins)",
                    "queries",
                    "accuracy",
                    "% wrong",
                    "us/query",
                    "range over runs",
                    "labels differ from float",
                    "Pareto",
                ],
                rows,
                "lrrrrrrrl",
            )
            add("")
            figure("nn_cpp")

    def section_1_3_decode() -> None:  # 1.3 decode
        add(f"### {SECTIONS[5]}")
        add("")
        if not res.fixed:
            add(f"Not measured: {res.fixed_missing}.")
            add("")
        else:
            f0 = res.fixed[0]
            add(
                "`tofmat_bench_fixed --op all`, decode: a synthetic 512x424 raw frame (depths 500..4500 mm, amplitudes "
                "20..3000 counts, random p0), the float reference `decode_frame` against the fixed-point decode with the "
                f"scalar kernel and the best one of this build ({f0.best_kernel}); errors against the float decode over the "
                f"pixels valid in both (per-frequency depths modulo their range). Full frame: each run's {f0.frame_reps}, "
                "a new frame each time (allocation included)."
            )
            add("")
            dec = fam["decode"]
            marks = _front_marks(dec)
            rows = []
            for i, d in enumerate(f0.decode):
                p = dec.points[i]
                roi = Stat.of([fb.decode[i].roi_us for fb in res.fixed])
                ref = d.kernel == "float"
                rows.append(
                    [
                        p.series,
                        _f(p.cost.median),
                        p.cost.spread("{:.2f}"),
                        _f(roi.median, "{:.1f}"),
                        "(reference)" if ref else " / ".join(f"{e:.5f}" for e in d.depth_err_mm),
                        "" if ref else f"{d.combined_err_mm:.4f}",
                        str(d.valid),
                        "" if ref else str(d.flags_differ),
                        marks[i],
                    ]
                )
            table(
                [
                    "path",
                    "ms per frame",
                    "range over runs",
                    "20x20 ROI, us",
                    "max depth error, mm (80 / 16 / 120 MHz)",
                    "max combined-depth error, mm",
                    "pixels valid in both",
                    "flags differ",
                    "Pareto",
                ],
                rows,
                "lrrrlrrrl",
            )
            add("")
            figure("decode")

    def section_1_4_stages() -> None:  # 1.4 stages
        add(f"### {SECTIONS[6]}")
        add("")
        if not res.fixed:
            add(f"Not measured: {res.fixed_missing}.")
            add("")
        else:
            f0 = res.fixed[0]
            c = f0.composite
            add(
                "`tofmat_bench_fixed --op all`, the composite: a 512x424 frame at 610..1190 mm in 29 vertical bands, one per "
                f"material's curves; every valid pixel classified by its two features at its combined-depth bin (one bin: "
                f"m = 1). Error: {c.classified:,} of {c.pixels:,} pixels classified, {100 * c.right_fraction:.1f} % as their "
                f"band's material, measured on the {f0.best_kernel} kernel's labels; `FloatClassifier` on the same features "
                f"gives another label at {c.differ_from_float} of {c.sampled:,} sampled pixels, all within "
                f"{c.tie_gap_mm2:g} mm^2 of a tie (the features' quantisation). The scalar kernels are bit-exact with the "
                f"{f0.best_kernel} ones (`PixelClassifier.VectorKernelIsBitExactWithScalar`, "
                "`FixedDecode.VectorKernelIsBitExactWithScalar`): their error is that of the same labels, not compared "
                f"again in this run. Times: each run's {f0.frame_reps} per stage."
            )
            add("")
            fr = fam["frame"]
            marks = _front_marks(fr)
            j = 0  # the frame family's points follow the stages that are whole frames
            rows = []
            for i, s in enumerate(f0.stages):
                st = Stat.of([fb.stages[i].median_ms for fb in res.fixed])
                best = Stat.of([fb.stages[i].best_ms for fb in res.fixed])
                err, mark = ("decode: see 1.3" if "decode" in s.stage else "-"), ""
                if _whole_frame(s.stage):
                    pt = fr.points[j]
                    err, mark = f"{pt.error:.1f} % wrong" + (f" ({pt.note})" if pt.note else ""), marks[j]
                    j += 1
                rows.append([s.stage, s.kernel, _f(st.median), st.spread("{:.2f}"), _f(best.median), err, mark])
            table(
                ["stage", "kernel", "ms per frame", "range over runs", "best pass", "error", "Pareto"], rows, "llrrrll"
            )
            add("")
            add(
                "The 11-bit unpack of a depth packet (9 sub-images to int16 raw values), whole packet, the rows of a 48x48 "
                "region at the centre and that region; exact: its error is whether it equals the definition."
            )
            add("")
            up = fam["unpack"]
            marks = _front_marks(up)
            rows = []
            for i, u in enumerate(f0.unpack):
                p = up.points[i]
                rws = Stat.of([fb.unpack[i].rows_ms for fb in res.fixed])
                reg = Stat.of([fb.unpack[i].region_ms for fb in res.fixed])
                rows.append(
                    [
                        u.kernel,
                        _f(p.cost.median, "{:.3f}"),
                        p.cost.spread("{:.3f}"),
                        _f(rws.median, "{:.4f}"),
                        _f(reg.median, "{:.4f}"),
                        "yes" if u.equals_definition else "**NO**",
                        marks[i],
                    ]
                )
            table(
                [
                    "kernel",
                    "whole packet, ms",
                    "range over runs",
                    "48 rows, ms",
                    "48x48 region, ms",
                    "equals the definition",
                    "Pareto",
                ],
                rows,
                "lrrrrll",
            )
            add("")
            figure("frame")

    def section_1_5_profiles() -> None:  # 1.5 profiles
        add(f"### {SECTIONS[7]}")
        add("")
        if not res.profiles:
            add(f"Not measured: {res.profiles_missing}.")
            add("")
        else:
            p0 = res.profiles[0]
            add(
                "`tofmat_bench_profiles --profile all`: each tofmatd scene profile on the simulated Kinect's depth packets, "
                "from the packet (the 11-bit unpack of the profile's region) to the event's bytes, one thread; the profiles "
                "run the fixed-point path, the float backend (where there is one) the same scenes. Error: what the bench's "
                "own short scenes get wrong against the simulator's truth (handheld: the final label of each of 4 sweeps of "
                "6 frames; sorting: each of 4 bursts; segmentation: target pixels), all 29 materials candidates; the float "
                "backend's from the labels the bench prints. These scenes are a handful of frames against all 29 "
                "materials: their error says whether the fixed path labels as the float one does, not how well a "
                "profile labels (`tofmat bench-daemon` measures that on longer scenes). Cost: each run's "
                f"{p0.reps or 'median'} per frame."
            )
            add("")
            prof_fams = [f for k, f in fam.items() if k.startswith("profile_")]
            rows = []
            for i, p in enumerate(p0.profiles):
                st = Stat.of([pb.profiles[i].median_ms for pb in res.profiles])
                fm = next((f for f in prof_fams if f.title == p.name), None)
                marks = _front_marks(fm) if fm else []
                wrong = "-" if math.isnan(p.right_fraction) else f"{100 * (1 - p.right_fraction):.1f}"
                rows.append(
                    [
                        p.name,
                        "fixed (the daemon's)",
                        str(p.frames),
                        _f(st.median, "{:.3f}"),
                        st.spread("{:.3f}"),
                        _f(p.unpack_ms, "{:.4f}"),
                        _f(p.process_ms, "{:.3f}"),
                        _f(p.encode_ms, "{:.4f}"),
                        wrong,
                        p.truth,
                        marks[0] if marks else "",
                    ]
                )
                if fm and len(fm.points) > 1:
                    fl = fm.points[1]
                    rows.append(
                        [
                            p.name,
                            "float backend",
                            str(p.frames),
                            _f(fl.cost.median, "{:.3f}"),
                            fl.cost.spread("{:.3f}"),
                            "",
                            "",
                            "",
                            f"{fl.error:.1f}",
                            f"agreement: {p.agrees}",
                            marks[1],
                        ]
                    )
            table(
                [
                    "profile",
                    "path",
                    "frames / pass",
                    "ms per frame",
                    "range over runs",
                    "unpack",
                    "process",
                    "encode",
                    "% wrong",
                    "as printed",
                    "Pareto",
                ],
                rows,
                "llrrrrrrrll",
            )
            add("")
            add("Segmentation, step by step (ms per frame; each row is the whole of what it names):")
            add("")
            rows = []
            for i, s in enumerate(p0.steps):
                st = Stat.of([pb.steps[i].median_ms for pb in res.profiles])
                rows.append([s.stage, _f(st.median, "{:.3f}"), st.spread("{:.3f}")])
            table(["step", "ms per frame", "range over runs"], rows, "lrr")
            add("")
            figure("profiles")

    def section_1_6_aarch64() -> None:  # 1.6 aarch64
        add(f"### {SECTIONS[8]}")
        add("")
        if res.insn is None:
            add(
                "Not measured here: no kept output of a cross run. `make bench-cross` prints the counts and keeps no file "
                "(tests/bench/insn_counts.sh writes to its standard output and removes its temporary folder). "
                f"`make report-counts` runs `make bench-cross` and `make bench-profiles-cross` (the aarch64 build, qemu "
                f"and its plugin; `make setup-cross` installs the toolchain; tens of minutes) and keeps their output in "
                f"`{Path('build/bench/insn_counts.md')}` and `{Path('build/bench/profile_counts.md')}`, which the next "
                "`tofmat report` reads."
            )
            add("")
        else:
            add(
                f"From `{res.insn_file}` ({res.insn.qemu or 'qemu'}): guest instructions per unit of "
                "`tofmat_bench_fixed` built for aarch64, counted under qemu (instructions, not cycles). Errors are the "
                "host's for the same path (1.2, 1.3): the NEON kernels are bit-exact with the scalar ones "
                "(`make cross-test`)."
            )
            add("")
            rows = [
                [
                    r.op,
                    r.unit,
                    _f(r.float_insns, "{:,.0f}"),
                    _f(r.scalar_insns, "{:,.0f}"),
                    _f(r.neon_insns, "{:,.0f}"),
                    _f(r.scalar_insns / r.neon_insns if r.neon_insns else math.nan),
                ]
                for r in res.insn.rows
            ]
            table(["op", "unit", "float", "fixed scalar", "fixed NEON", "scalar / NEON"], rows, "llrrrr")
            add("")
            figure("aarch64")
        if res.profile_counts:
            add(f"From `{res.profile_counts_file}` (aarch64 instructions per frame of each profile):")
            add("")
            for t in res.profile_counts:
                table(t.header, t.rows)
                add("")

    def section_2_stability() -> None:  # 2 stability
        add(f"## {SECTIONS[9]}")
        add("")
        add(
            "The worst error of each fixed-point stage against the float reference at the stiff and extreme cases of "
            "docs/numerics.md, next to the budget it states. The SDK exposes one fixed-point stage, the Eq. (12) "
            'classifier (`Classifier(table, backend="fixed")`): its cases are computed here, in Python, on synthetic '
            "queries (2.1). The decode's stages, the depth bins and the segmentation's box mean are measured at theirs "
            "by the C++ build, on synthetic raw samples both paths decode (2.2). What only the C++ tests check is "
            "listed with those tests (2.3)."
        )
        add("")
        add(f"### {SECTIONS[10]}")
        add("")
        add(
            "Budget (docs/numerics.md, Eq. (12)): the fixed path quantises each query element to the table's step s "
            "(moving it by at most s/2) and is otherwise exact, so each candidate's mean squared distance moves by at most "
            f"{CLASSIFIER_BUDGET}. Error: |d_fixed - d_float| of every candidate of every query (mm^2); "
            "error / bound at most 1 is within the budget; a label that differs must lie within the bounds of the two "
            "candidates. The table goes through a .tmx file first (the values both paths see, step s = "
            f"{_stability_step(res)}). Where one element sits exactly between two steps the bound is reached "
            "(error / bound 1.0000 up to the doubles' last bits): the budget is tight, not a loose margin."
        )
        add("")
        rows = []
        for r in res.stability:
            rows.append(
                [
                    r.case,
                    r.inputs,
                    str(r.queries),
                    str(r.distances),
                    _g(r.worst_error),
                    _g(r.bound_at_worst),
                    f"{r.worst_ratio:.4f}",
                    f"{r.labels_differ} ({r.labels_outside} outside)",
                    "yes" if r.within_budget else "**NO**",
                    r.note,
                    r.covered_by,
                ]
            )
        table(
            [
                "case",
                "inputs",
                "queries",
                "distances",
                "worst error, mm^2",
                "bound there, mm^2",
                "worst error / bound",
                "labels differ from float",
                "within budget",
                "also",
                "C++ test of the case",
            ],
            rows,
            "llrrrrrlll" + "l",
        )
        add("")
        add(f"### {SECTIONS[11]}")
        add("")
        if res.stiff:
            add(
                "`tofmat_bench_fixed --op stiff` (the cases of tests/cpp/stiff_cases.hpp, which `test_stiff_cases` "
                "asserts in `make test`): each fixed-point stage against its float reference on the same synthetic "
                "raw samples (the phasor model m_j = B + A cos(theta + phi_j), random offsets and per-pixel p0; the "
                "scalar kernels, which every vector kernel equals bit for bit), 200,000 pixels per decode case. A "
                "material's subsurface delay tau enters as its response R per group (docs/simulator-model.md): the "
                "group's phase moves by arg R and its amplitude by |R|. Flags may differ only on a threshold's edge "
                "or at the 16 MHz wrap point (docs/numerics.md); the row counts the others."
            )
            add("")
            table(
                ["stage", "case", "inputs", "compared", "quantity", "worst error", "budget", "within budget"],
                [
                    [
                        r.stage,
                        r.case,
                        r.inputs,
                        f"{r.compared:,}",
                        r.quantity,
                        _g(r.worst),
                        _g(r.budget),
                        "yes" if r.within else "**NO**",
                    ]
                    for r in res.stiff
                ],
                "lllrlrrl",
            )
            add("")
        else:
            add(f"Not measured: {res.fixed_missing}.")
            add("")
        dt = res.decode_test
        if dt is not None:
            add(
                f"The whole range at once, next to the cases above: the decode's error-budget test (`{cb.DECODE_TEST}`, "
                f"run by this report; {'passed' if dt.passed else '**failed**'}): {dt.pixels:,} synthetic pixels, true depths over the whole "
                "9375 mm with a quarter exactly on every frequency's wrap points and a quarter just below the 80 MHz ones, "
                "amplitudes 3 to 8000 counts, random offsets and p0; the scalar kernel (every vector kernel equals it bit "
                "for bit). Its worst errors against the float decode:"
            )
            add("")
            table(
                ["quantity", "worst (the test, now)", "budget (docs/numerics.md)"],
                [
                    ["phase, rad (80 / 16 / 120 MHz)", " / ".join(_g(x) for x in dt.phase_rad), "1e-6"],
                    ["depth, mm (80 / 16 / 120 MHz)", " / ".join(_g(x) for x in dt.depth_mm), "0.002"],
                    ["combined depth, mm", _g(dt.combined_mm), "0.006"],
                    ["features, mm", _g(dt.features_mm), "0.004"],
                    ["amplitude, relative beyond its Q8 step", _g(dt.amplitude_rel), "1e-4"],
                    [
                        "flags differ (pixels)",
                        f"{dt.flags_differ} of {dt.pixels:,}",
                        "only on a threshold's edge or the 16 MHz wrap point",
                    ],
                ],
                "lrl",
            )
            add("")
        else:
            add(f"The decode's error-budget test (`{cb.DECODE_TEST}`) was not run: {res.decode_test_note}.")
            add("")
        if res.fixed:
            d = [x for x in res.fixed[0].decode if x.kernel != "float"]
            add(
                "For comparison, not a stiff case: the decode benchmark's random frame (1.3) gives "
                + "; ".join(
                    f"{x.kernel}: depth {' / '.join(f'{e:.5f}' for e in x.depth_err_mm)} mm, combined "
                    f"{x.combined_err_mm:.4f} mm, {x.flags_differ} flags differ"
                    for x in d
                )
                + "."
            )
            add("")

        add(f"### {SECTIONS[12]}")
        add("")
        add("Checked by the C++ tests in `make test` (the NEON kernels under qemu-aarch64 in `make cross-test`):")
        add("")
        table(
            ["stage", "stiff cases", "budget (docs/numerics.md)", "covered by"],
            [[n.stage, n.cases, n.budget, n.tests] for n in CPP_TESTS_ONLY],
            "llll",
        )
        add("")

    def section_3_how() -> None:  # 3 how
        add(f"## {SECTIONS[13]}")
        add("")
        add("Commands, in the order run (each benchmark once per run, the runs interleaved):")
        add("")
        add("```")
        L.extend(res.commands)
        add("```")
        add("")
        add("The benchmarks' own output, as printed:")
        add("")
        for f in res.raw_files:
            rel = f.relative_to(res.out_dir).as_posix()
            add(f"- [{rel}]({rel})")
        add("")
        add(
            f"Settings: {res.runs} run(s), {res.per_material} windows per material and length, noise {res.noise_mm:g} mm"
            + (", --quick" if res.quick else "")
            + (f". Load average at the end: {res.load_end} (at the start: under Machine)" if res.load_end else "")
            + ". The C++ build is the one under Machine; docs/benchmarks.md's C++ figures come from `make bench-cpp`'s "
            "Release (-O3) build in build/bench, so absolute times may differ from these."
        )
        add("")

    section_1_1_python()
    section_1_2_c_nn()
    section_1_3_decode()
    section_1_4_stages()
    section_1_5_profiles()
    section_1_6_aarch64()
    section_2_stability()
    section_3_how()
    return "\n".join(L)


def _stability_step(res: _Results) -> str:
    """The step of the user's table (the first cases) and, when it differs, the largest table's."""
    if not res.stability:
        return "-"
    main, largest = res.stability[0].step_mm, res.stability[-1].step_mm
    return f"{main:g} mm" + (f"; the largest table's {largest:g} mm" if largest != main else "")


__all__ = ["REPORT_NAME", "SECTIONS", "ReportError", "write_report"]
