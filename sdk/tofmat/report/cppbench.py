# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Running the C++ benchmarks of tests/bench and reading the Markdown they print.

``tofmat_bench_fixed --op all`` and ``tofmat_bench_profiles --profile all`` print Markdown tables
for people; this module finds those tables by their column names and reads their cells. When a
table or a column it needs is not there (the benchmark's output has changed), it raises
:class:`BenchFormatError` naming what it looked for and where the output was saved, rather than
guessing. The aarch64 instruction counts of ``make bench-cross`` (tests/bench/insn_counts.sh) and
``make bench-profiles-cross`` (profile_counts.sh) are read the same way from files, when a run
kept them (``make report-counts``, mk/report.mk).
"""

from __future__ import annotations

import math
import re
import subprocess
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

_SEPARATOR = re.compile(r"^\|(\s*:?-+:?\s*\|)+\s*$")
_NUMBER = re.compile(r"[-+]?(?:\d[\d,]*\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


class BenchFormatError(RuntimeError):
    """A benchmark printed something the report cannot read: its output format has changed."""


class BenchRunError(RuntimeError):
    """A benchmark could not be run or exited with an error."""


# ---------------------------------------------------------------- Markdown tables


@dataclass(frozen=True)
class MdTable:
    """A Markdown table of a benchmark's output, with the last heading before it."""

    heading: str
    header: list[str]
    rows: list[list[str]]
    source: str  # the program, for messages

    def col(self, *needles: str) -> int:
        """The first column whose name holds every needle (case-insensitive)."""
        for i, h in enumerate(self.header):
            if all(n.lower() in h.lower() for n in needles):
                return i
        raise BenchFormatError(
            f"{self.source}: its table {self.header!r} has no column named like {' '.join(needles)!r}"
        )


def parse_tables(text: str, source: str) -> list[MdTable]:
    """Every Markdown table in ``text`` (a header line, a |---| line, then rows starting with '|')."""
    lines = text.splitlines()
    tables: list[MdTable] = []
    heading = ""
    i = 0
    while i < len(lines):
        line = lines[i].strip()
        if line.startswith("#"):
            heading = line.lstrip("#").strip()
        if line.startswith("|") and i + 1 < len(lines) and _SEPARATOR.match(lines[i + 1].strip()):
            header = _cells(line)
            rows = []
            i += 2
            while i < len(lines) and lines[i].strip().startswith("|"):
                cells = _cells(lines[i].strip())
                rows.append(cells + [""] * (len(header) - len(cells)))
                i += 1
            tables.append(MdTable(heading, header, rows, source))
            continue
        i += 1
    return tables


def _cells(line: str) -> list[str]:
    body = line.strip()
    body = body[1:] if body.startswith("|") else body
    body = body[:-1] if body.endswith("|") else body
    return [c.strip() for c in body.split("|")]


def find_table(tables: Sequence[MdTable], source: str, *columns: str) -> MdTable:
    """The first table that has a column named like each of ``columns``."""
    for t in tables:
        if all(any(c.lower() in h.lower() for h in t.header) for c in columns):
            return t
    seen = "; ".join(" | ".join(t.header) for t in tables) or "no table at all"
    raise BenchFormatError(f"{source}: no table with the columns {list(columns)!r} in its output (tables seen: {seen})")


def number(cell: str) -> float:
    """The first number in a cell ('**3.65**', '81.6 %', '23,702'); NaN for '-' or an empty cell."""
    m = _NUMBER.search(cell.replace("*", ""))
    return float(m.group(0).replace(",", "")) if m else math.nan


def numbers(cell: str) -> list[float]:
    return [float(m.replace(",", "")) for m in _NUMBER.findall(cell.replace("*", ""))]


def _found(pattern: str, text: str) -> str:
    """What ``pattern`` matches in ``text``, "" when nothing does."""
    m = re.search(pattern, text)
    return m.group(0) if m else ""


def _need(value: float, what: str, source: str) -> float:
    if math.isnan(value):
        raise BenchFormatError(f"{source}: expected a number for {what}, found none")
    return value


# ---------------------------------------------------------------- running


def run_program(cmd: Sequence[str], timeout_s: float, raw_file: Path | None = None) -> str:
    """Runs a benchmark and returns its standard output (saved to ``raw_file`` first, when given)."""
    try:
        run = subprocess.run(list(cmd), capture_output=True, text=True, timeout=timeout_s, check=False)
    except FileNotFoundError as e:
        raise BenchRunError(f"{cmd[0]} not found: make build-cpp builds it") from e
    except subprocess.TimeoutExpired as e:
        raise BenchRunError(f"{' '.join(cmd)} took longer than {timeout_s:.0f} s") from e
    if raw_file is not None:
        raw_file.parent.mkdir(parents=True, exist_ok=True)
        raw_file.write_text(f"$ {' '.join(cmd)}\n{run.stdout}" + (f"\n[stderr]\n{run.stderr}" if run.stderr else ""))
    if run.returncode != 0:
        tail = "; ".join(run.stderr.strip().splitlines()[-3:]) or "no message"
        raise BenchRunError(f"{' '.join(cmd)} exited with status {run.returncode}: {tail}")
    return run.stdout


# ---------------------------------------------------------------- tofmat_bench_fixed --op all


@dataclass(frozen=True)
class DecodeRow:
    path: str  # as printed: "float (`decode_frame`, ...)", "fixed scalar", "fixed best (= avx2)"
    kernel: str  # float, scalar, or the best kernel's name (avx2, neon, scalar)
    frame_ms: float
    roi_us: float
    depth_err_mm: tuple[float, float, float]  # 80 / 16 / 120 MHz (0 for the reference)
    combined_err_mm: float
    valid: int
    flags_differ: int


@dataclass(frozen=True)
class NnRow:
    window: int
    queries: int
    float_us: float
    fixed_us: float
    float_accuracy: float  # fraction
    fixed_accuracy: float
    labels_differ: int


@dataclass(frozen=True)
class StageRow:
    stage: str  # the row's name without its kernel and emphasis
    kernel: str  # scalar or the best kernel's name
    median_ms: float
    best_ms: float


@dataclass(frozen=True)
class UnpackRow:
    kernel: str  # definition, scalar, or the best kernel's name
    whole_ms: float
    rows_ms: float
    region_ms: float  # NaN for the definition (whole rows only)
    equals_definition: bool


@dataclass(frozen=True)
class Composite:
    classified: int
    pixels: int
    right_fraction: float  # of the classified pixels, as their band's material
    differ_from_float: int
    sampled: int
    tie_gap_mm2: float


@dataclass(frozen=True)
class FixedBench:
    best_kernel: str
    decode: list[DecodeRow]
    nn: list[NnRow]
    nn_step_mm: float
    compact_bytes: int
    stages: list[StageRow]
    composite: Composite
    unpack: list[UnpackRow]
    frame_reps: str  # "median of 11" as printed
    nn_reps: str


_FIXED = "tofmat_bench_fixed"


def _kernel_of(text: str, best: str) -> str:
    """The kernel named in a row: '(scalar)', '(best = avx2)', '(`classify_frame`, best = avx2)', 'fixed best (= avx2)'."""
    m = re.search(r"best\s*\(?=\s*(\w+)", text)
    if m:
        return m.group(1)
    if "scalar" in text:
        return "scalar"
    if re.search(r"\bbest\b", text):
        return best
    raise BenchFormatError(f"{_FIXED}: cannot tell the kernel of the row {text!r}")


def parse_bench_fixed(text: str) -> FixedBench:
    """Reads the tables of ``tofmat_bench_fixed --op all``."""
    m = re.search(r"best kernel of this build = (\w+)", text)
    if not m:
        raise BenchFormatError(f"{_FIXED}: no 'best kernel of this build = ...' line in its output")
    best = m.group(1)
    tables = parse_tables(text, _FIXED)

    t = find_table(tables, _FIXED, "full frame", "ROI", "depth error", "combined")
    c_path, c_full, c_roi = t.col("path"), t.col("full frame"), t.col("roi")
    c_depth, c_comb, c_valid, c_flags = t.col("depth error"), t.col("combined"), t.col("valid"), t.col("flags")
    frame_reps = _found(r"median of \d+", t.header[c_full])
    decode: list[DecodeRow] = []
    for r in t.rows:
        path = r[c_path]
        is_ref = path.startswith("float")
        errs = numbers(r[c_depth])
        if not is_ref and len(errs) != 3:
            raise BenchFormatError(f"{_FIXED}: expected three depth errors (80 / 16 / 120 MHz) in {r[c_depth]!r}")
        decode.append(
            DecodeRow(
                path=path,
                kernel="float" if is_ref else _kernel_of(path, best),
                frame_ms=_need(number(r[c_full]), "a decode's full-frame ms", _FIXED),
                roi_us=_need(number(r[c_roi]), "a decode's ROI us", _FIXED),
                depth_err_mm=(0.0, 0.0, 0.0) if is_ref else (errs[0], errs[1], errs[2]),
                combined_err_mm=0.0 if is_ref else _need(number(r[c_comb]), "a combined-depth error", _FIXED),
                valid=int(number(r[c_valid])),
                flags_differ=0 if is_ref else int(_need(number(r[c_flags]), "flags differ", _FIXED)),
            )
        )
    if [d.kernel for d in decode][:1] != ["float"] or len(decode) < 2:
        raise BenchFormatError(f"{_FIXED}: the decode table should start with the float reference, then fixed rows")

    t = find_table(tables, _FIXED, "window", "float us/query", "fixed us/query")
    cw, cq = t.col("window"), t.col("queries")
    cfu, cxu, cfa, cxa, cd = (
        t.col("float us"),
        t.col("fixed us"),
        t.col("float accuracy"),
        t.col("fixed accuracy"),
        t.col("differ"),
    )
    nn = [
        NnRow(
            window=int(_need(number(r[cw]), "a window", _FIXED)),
            queries=int(_need(number(r[cq]), "queries", _FIXED)),
            float_us=_need(number(r[cfu]), "float us/query", _FIXED),
            fixed_us=_need(number(r[cxu]), "fixed us/query", _FIXED),
            float_accuracy=_need(number(r[cfa]), "float accuracy", _FIXED) / 100.0,
            fixed_accuracy=_need(number(r[cxa]), "fixed accuracy", _FIXED) / 100.0,
            labels_differ=int(_need(number(r[cd]), "labels differ", _FIXED)),
        )
        for r in t.rows
    ]
    nn_reps = _found(r"median of \d+ passes", t.heading)
    step = re.search(r"fixed step ([\d.eE+-]+) mm", t.heading)
    size = re.search(r"compact table (\d+) bytes", t.heading)

    t = find_table(tables, _FIXED, "stage", "ms per frame", "best")
    cs, cm, cb = t.col("stage"), t.col("ms per frame"), t.col("best")
    stages = []
    for r in t.rows:
        name = r[cs].replace("**", "")
        kernel = _kernel_of(name, best)
        stage = re.sub(r"\s*\((?:`[^`]*`,\s*)?(?:scalar|best = \w+)\)", "", name).strip()
        stages.append(StageRow(stage, kernel, _need(number(r[cm]), name, _FIXED), _need(number(r[cb]), name, _FIXED)))

    m = re.search(
        r"(\d+) of (\d+) pixels classified, ([\d.]+) % of them as their band's material.*?another label at (\d+) of "
        r"(\d+) sampled pixels.*?differ by at most ([\d.eE+-]+) mm\^2",
        text,
        re.S,
    )
    if not m:
        raise BenchFormatError(
            f"{_FIXED}: the composite's sentence ('N of M pixels classified, P % of them as their band's material; "
            "... another label at A of B sampled pixels ... differ by at most G mm^2') is not in its output"
        )
    composite = Composite(
        int(m.group(1)),
        int(m.group(2)),
        float(m.group(3)) / 100.0,
        int(m.group(4)),
        int(m.group(5)),
        float(m.group(6)),
    )

    t = find_table(tables, _FIXED, "kernel", "whole packet", "equals the definition")
    ck, cwp, ceq = t.col("kernel"), t.col("whole packet"), t.col("equals")
    crows = next((i for i, h in enumerate(t.header) if h.lower().startswith("rows")), -1)
    creg = next((i for i, h in enumerate(t.header) if "region" in h.lower()), -1)
    if crows < 0 or creg < 0:
        raise BenchFormatError(f"{_FIXED}: the unpack table {t.header!r} lacks its rows or region column")
    unpack = []
    for r in t.rows:
        name = r[ck]
        kernel = "definition" if name.startswith("definition") else _kernel_of(name, best)
        unpack.append(
            UnpackRow(
                kernel,
                _need(number(r[cwp]), name, _FIXED),
                _need(number(r[crows]), name, _FIXED),
                number(r[creg]),
                r[ceq].strip().lower() == "yes",
            )
        )
    return FixedBench(
        best_kernel=best,
        decode=decode,
        nn=nn,
        nn_step_mm=float(step.group(1)) if step else math.nan,
        compact_bytes=int(size.group(1)) if size else 0,
        stages=stages,
        composite=composite,
        unpack=unpack,
        frame_reps=frame_reps,
        nn_reps=nn_reps,
    )


# ---------------------------------------------------------------- tofmat_bench_profiles --profile all


@dataclass(frozen=True)
class ProfileRow:
    name: str  # as printed: "handheld", "sorting-idle (between bursts)", "segmentation (smooth 9)"
    frames: int
    median_ms: float
    best_ms: float
    unpack_ms: float
    process_ms: float
    encode_ms: float
    truth: str  # the error column as printed
    right_fraction: float  # what it says is right, as a fraction (NaN: no truth)
    agrees: str
    float_ms: float  # NaN: no float backend


@dataclass(frozen=True)
class ProfilesBench:
    profiles: list[ProfileRow]
    steps: list[StageRow]  # kernel "" (the profiles' own)
    # profile -> [(target, fixed label, float label)] from the notes ("-": none)
    labels: dict[str, list[tuple[str, str, str]]] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    reps: str = ""


_PROFILES = "tofmat_bench_profiles"


def _right_fraction(cell: str) -> float:
    m = re.search(r"(\d+)\s*/\s*(\d+)", cell)
    if m and int(m.group(2)) > 0:
        return int(m.group(1)) / int(m.group(2))
    m = re.search(r"([\d.]+)\s*%", cell)
    return float(m.group(1)) / 100.0 if m else math.nan


def parse_bench_profiles(text: str) -> ProfilesBench:
    """Reads the tables and notes of ``tofmat_bench_profiles --profile all``."""
    tables = parse_tables(text, _PROFILES)
    t = find_table(tables, _PROFILES, "profile", "ms per frame", "error vs truth", "float backend")
    cp, cf, cm, cb = t.col("profile"), t.col("frames"), t.col("ms per frame"), t.col("best")
    cu, cpr, ce = t.col("unpack"), t.col("process"), t.col("encode")
    ct, ca, cfl = t.col("truth"), t.col("agrees"), t.col("float backend")
    profiles = [
        ProfileRow(
            name=r[cp],
            frames=int(_need(number(r[cf]), "frames / pass", _PROFILES)),
            median_ms=_need(number(r[cm]), "ms per frame", _PROFILES),
            best_ms=number(r[cb]),
            unpack_ms=number(r[cu]),
            process_ms=number(r[cpr]),
            encode_ms=number(r[ce]),
            truth=r[ct],
            right_fraction=_right_fraction(r[ct]),
            agrees=r[ca],
            float_ms=number(r[cfl]),
        )
        for r in t.rows
    ]
    if not any(p.name.startswith("handheld") for p in profiles):
        raise BenchFormatError(f"{_PROFILES}: no handheld row in its profile table")
    st = find_table(tables, _PROFILES, "step", "ms per frame")
    cs, cm2, cb2 = st.col("step"), st.col("ms per frame"), st.col("best")
    steps = [StageRow(r[cs], "", _need(number(r[cm2]), r[cs], _PROFILES), number(r[cb2])) for r in st.rows]
    labels: dict[str, list[tuple[str, str, str]]] = {}
    notes = []
    for line in text.splitlines():
        if not line.startswith("- "):
            continue
        notes.append(line[2:].strip())
        m = re.match(r"- (\S+) labels \(target: fixed / float\):(.*)$", line)
        if m:
            pairs = re.findall(r"\s*([^:;]+):\s*([^/;]+?)\s*/\s*([^;]+?)\s*;", m.group(2))
            labels[m.group(1)] = [(a.strip(), b.strip(), c.strip()) for a, b, c in pairs]
    reps = re.search(r"median of (\d+) passes", text)
    return ProfilesBench(profiles, steps, labels, notes, f"median of {reps.group(1)} passes" if reps else "")


# ---------------------------------------------------------------- aarch64 instruction counts (files)


@dataclass(frozen=True)
class InsnRow:
    op: str
    unit: str
    float_insns: float  # NaN: not counted
    scalar_insns: float
    neon_insns: float


@dataclass(frozen=True)
class InsnCounts:
    qemu: str  # the "qemu: ..." line
    rows: list[InsnRow]
    extra_tables: list[MdTable]  # the unpack table, and profile_counts.sh's tables


def parse_insn_counts(text: str, source: str) -> InsnCounts:
    """Reads tests/bench/insn_counts.sh's output (``make bench-cross``), kept in a file."""
    tables = parse_tables(text, source)
    t = find_table(tables, source, "op", "unit", "float", "fixed scalar", "fixed neon")
    co, cu, cf, cs, cn = t.col("op"), t.col("unit"), t.col("float"), t.col("fixed scalar"), t.col("fixed neon")
    rows = [
        InsnRow(
            r[co],
            r[cu],
            number(r[cf]),
            _need(number(r[cs]), f"{r[co]} scalar", source),
            _need(number(r[cn]), f"{r[co]} NEON", source),
        )
        for r in t.rows
    ]
    m = re.search(r"^qemu: (.*)$", text, re.M)
    return InsnCounts(m.group(1).strip() if m else "", rows, [x for x in tables if x is not t])


def parse_profile_counts(text: str, source: str) -> list[MdTable]:
    """The tables of tests/bench/profile_counts.sh's output (``make bench-profiles-cross``), kept in a file."""
    tables = parse_tables(text, source)
    find_table(tables, source, "profile", "scalar unpack")
    return tables


# ---------------------------------------------------------------- the decode's C++ test ("[ measured ]")


@dataclass(frozen=True)
class DecodeTestFigures:
    pixels: int
    phase_rad: tuple[float, float, float]
    depth_mm: tuple[float, float, float]  # 80 / 16 / 120 MHz
    combined_mm: float
    features_mm: float
    amplitude_rel: float
    flags_differ: int
    both_valid: int
    passed: bool
    line: str  # as printed


@dataclass(frozen=True)
class StiffCaseRow:
    """One row of ``tofmat_bench_fixed --op stiff``: a stage's worst error at one stiff case."""

    stage: str
    case: str
    inputs: str
    compared: int  # pixels, bins or windows the worst is taken over
    quantity: str  # with its unit
    worst: float
    budget: float  # docs/numerics.md

    @property
    def within(self) -> bool:
        return self.worst <= self.budget


STIFF_SOURCE = "tofmat_bench_fixed --op stiff"


def parse_stiff_cases(text: str) -> list[StiffCaseRow]:
    """The rows of ``tofmat_bench_fixed --op stiff`` (its "Stiff cases" table).

    The program states whether each row is within its budget; that is checked against the numbers
    it printed, so a disagreement (a changed format or rounding) is an error here, not a quiet pass.
    """
    t = find_table(parse_tables(text, STIFF_SOURCE), STIFF_SOURCE, "stage", "case", "worst error", "budget")
    cols = [t.col(c) for c in ("stage", "case", "inputs", "compared", "quantity", "worst error", "budget", "within")]
    rows: list[StiffCaseRow] = []
    for cells in t.rows:
        stage, case, inputs, compared, quantity, worst, budget, within = (cells[i] for i in cols)
        row = StiffCaseRow(
            stage=stage,
            case=case,
            inputs=inputs,
            compared=int(_need(number(compared), "compared", STIFF_SOURCE)),
            quantity=quantity,
            worst=_need(number(worst), f"the worst error of {stage}, {case}", STIFF_SOURCE),
            budget=_need(number(budget), f"the budget of {stage}, {case}", STIFF_SOURCE),
        )
        if row.within != (within.strip().lower() == "yes"):
            raise BenchFormatError(
                f"{STIFF_SOURCE}: {stage}, {case}, {quantity}: it says within budget {within!r} "
                f"for worst {worst} against budget {budget}"
            )
        rows.append(row)
    if not rows:
        raise BenchFormatError(f"{STIFF_SOURCE}: its table has no rows")
    return rows


DECODE_TEST = "FixedDecode.MatchesTheFloatDecodeWithinTheErrorBudget"


def parse_decode_test(text: str) -> DecodeTestFigures | None:
    """The '[ measured ]' line of FixedDecode.MatchesTheFloatDecodeWithinTheErrorBudget (None: not in it)."""
    f = r"([-+\d.eE]+)"
    m = re.search(
        rf"\[ measured \] fixed vs float over (\d+) pixels: phase {f} / {f} / {f} rad, depth {f} / {f} / {f} mm "
        rf"\(80/16/120 MHz\), combined {f} mm, features {f} mm, amplitude {f} \(relative\); flags differ at (\d+) "
        r"pixels, both valid (\d+)",
        text,
    )
    if not m:
        return None
    g = [float(x) for x in m.groups()]
    passed = re.search(r"\[\s+OK\s+\]\s+" + re.escape(DECODE_TEST), text) is not None
    return DecodeTestFigures(
        pixels=int(g[0]),
        phase_rad=(g[1], g[2], g[3]),
        depth_mm=(g[4], g[5], g[6]),
        combined_mm=g[7],
        features_mm=g[8],
        amplitude_rel=g[9],
        flags_differ=int(g[10]),
        both_valid=int(g[11]),
        passed=passed,
        line=m.group(0),
    )


__all__ = [
    "DECODE_TEST",
    "STIFF_SOURCE",
    "BenchFormatError",
    "BenchRunError",
    "Composite",
    "DecodeRow",
    "DecodeTestFigures",
    "FixedBench",
    "InsnCounts",
    "InsnRow",
    "MdTable",
    "NnRow",
    "ProfileRow",
    "ProfilesBench",
    "StageRow",
    "StiffCaseRow",
    "UnpackRow",
    "find_table",
    "number",
    "numbers",
    "parse_bench_fixed",
    "parse_bench_profiles",
    "parse_decode_test",
    "parse_insn_counts",
    "parse_profile_counts",
    "parse_stiff_cases",
    "parse_tables",
    "run_program",
]
