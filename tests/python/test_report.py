# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""tofmat.report: the error-against-run-time report (`tofmat report`, docs/report.md).

One quick report on the real database with the release build's benchmarks (seconds), and the
report's parts on their own: the Pareto front on hand-made points, the stability cases against
their documented budgets, the readers of the benchmarks' output, the command line.
"""

from __future__ import annotations

import math
import re
import stat
import struct
from pathlib import Path

import pytest
from click.testing import CliRunner

import tofmat
from tofmat.report import SECTIONS, ReportError, dominates, pareto_front, write_report
from tofmat.report.cli import report
from tofmat.report.cppbench import (
    BenchFormatError,
    parse_bench_fixed,
    parse_decode_test,
    parse_insn_counts,
    parse_stiff_cases,
)
from tofmat.report.stability import classifier_stability

REPO = Path(__file__).resolve().parents[2]
BUILD = REPO / "build" / "release"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"

# The shape of tests/bench/insn_counts.sh's output (its figures as docs/benchmarks.md quotes them):
# what `make report-counts` keeps in build/bench/insn_counts.md. A sample for the reader, not a measurement.
INSN_SAMPLE = """\
qemu: qemu-aarch64 version 7.2.22 (Debian 1:7.2+dfsg-7+deb12u18+b3); R = 3; instructions per unit = (count(R) - count(0)) / (R x units)

| op | unit | float | fixed scalar | fixed NEON | scalar / NEON | issue's target | met |
|---|---|---:|---:|---:|---:|---|---|
| decode | 512x424 frame | 227130462 | 105920604 | 45029614 | 2.35 | >= 2x fewer | yes |
| roi | 20x20 region | 427200 | 207295 | 96538 | 2.15 | - | - |
| nn | query (quantise + search 29 materials) | 30205 | 31677 | 17105 | 1.85 | - | - |
| dist | query (distance kernel calls only) | - | 18721 | 4148 | 4.51 | >= 4x fewer | yes |
| dist | query of 1 bins (distance kernel calls only) | - | 3754 | 996 | 3.77 | - | - |
"""


@pytest.fixture(scope="module")
def quick_report(real_tmx: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One quick report on the real database (as .tmx) with the release build's benchmarks."""
    counts = tmp_path_factory.mktemp("counts")
    (counts / "insn_counts.md").write_text(INSN_SAMPLE)
    calls: list[tuple[int, int, str]] = []
    md = write_report(
        tmp_path_factory.mktemp("report"),
        real_tmx,
        quick=True,
        progress=lambda done, total, what="": calls.append((done, total, what)),
        build_dir=BUILD,
        counts_dir=counts,
    )
    # The progress callback: a fixed total, steps in order, the last call done == total.
    assert calls and len({t for _d, t, _w in calls}) == 1
    assert [d for d, _t, _w in calls] == sorted(d for d, _t, _w in calls)
    assert calls[-1][0] == calls[-1][1]
    return md


def _links(md: Path, image: bool) -> list[Path]:
    pattern = r"!\[[^\]]*\]\(([^)]+)\)" if image else r"(?<!!)\[[^\]]*\]\(([^)]+)\)"
    return [md.parent / p for p in re.findall(pattern, md.read_text())]


def test_the_report_names_every_section(quick_report: Path) -> None:
    text = quick_report.read_text()
    assert quick_report.name == "report.md" and text.startswith("# ")
    for title in SECTIONS:
        assert re.search(rf"^#+ {re.escape(title)}$", text, re.M), title
    # The machine at the top, with the fields the report promises.
    machine = text.split("## " + SECTIONS[1])[0]
    for field in ("date", "CPU", "cores", "OS", "C++ compiler", "Python", "numpy"):
        assert f"| {field} |" in machine, field


def test_every_linked_png_is_a_real_png(quick_report: Path) -> None:
    pngs = _links(quick_report, image=True)
    names = {p.stem for p in pngs}
    assert {"classifier_python", "aarch64"} <= names
    if (BUILD / "tests" / "bench" / "tofmat_bench_fixed").is_file():
        assert {"nn_cpp", "decode", "frame"} <= names
    for p in pngs:
        data = p.read_bytes()
        assert data[:8] == PNG_MAGIC, p
        width, height = struct.unpack(">II", data[16:24])  # the IHDR chunk
        assert width >= 300 and height >= 200, p
    for p in _links(quick_report, image=False):  # the benchmarks' raw output
        assert p.is_file() and p.stat().st_size > 0, p


def test_the_report_tables_read_as_measured(quick_report: Path) -> None:
    text = quick_report.read_text()
    # The Python classifier: both backends at every window length.
    for backend in ("float", "fixed"):
        for w in (1, 3, 10, 30, 100):
            assert re.search(rf"^\| {backend} \| {w} \| \d+ \| [\d.]+ % \|", text, re.M), (backend, w)
    # The aarch64 counts read from the kept file, with the host's error beside them in a figure.
    assert "| decode | 512x424 frame | 227,130,462 | 105,920,604 | 45,029,614 | 2.35 |" in text
    # Every stiff case within its budget.
    section = text.split("### " + SECTIONS[10])[1].split("### ")[0]
    rows = [r for r in section.splitlines() if r.startswith("| ") and not r.startswith("| case")]
    assert len(rows) == 7 and all("| yes |" in r for r in rows)
    # The C++ stages at their stiff cases: every case the issue names, each row within its budget.
    section = text.split("### " + SECTIONS[11])[1].split("### ")[0]
    first_table = section.split("| stage | case |")[1].split("\n\n")[0]
    rows = [r for r in first_table.splitlines() if r.startswith("| ")]
    assert len(rows) >= 30 and all(r.endswith("| yes |") for r in rows)
    for case in (
        "near-zero amplitude",
        "saturation",
        "largest magnitudes",
        "wrap points",
        "range ends",
        "tiny tau (1 ps)",
        "huge tau (100 ns), half the light",
        "one valid element",
        "widest window at the extremes",
    ):
        assert any(f"| {case} |" in r for r in rows), case
    summary = text.split("## " + SECTIONS[1])[1].split("## ")[0]
    assert re.search(rf"Numerical stability \(section 2\): {7 + len(rows)} of {7 + len(rows)} stiff-case rows", summary)


@pytest.mark.parametrize(
    "points, front",
    [
        ([], []),
        ([(1.0, 1.0)], [0]),
        # A dominated point (2, 2) by (1, 1); (0.5, 3) and (3, 0) trade cost for error.
        ([(1.0, 1.0), (2.0, 2.0), (0.5, 3.0), (3.0, 0.0)], [2, 0, 3]),
        # Exact ties are all on the front; the same error at a higher cost is not, nor the same cost
        # with a higher error.
        ([(1.0, 1.0), (1.0, 1.0), (2.0, 1.0), (1.0, 2.0), (0.5, 5.0)], [4, 0, 1]),
        # NaN is never on the front and beats nothing; an infinite cost can be (nothing beats its error).
        ([(math.nan, 0.0), (1.0, math.nan), (2.0, 1.0), (math.inf, 0.5)], [2, 3]),
        # Zero errors: the cheapest of them only.
        ([(5.0, 0.0), (3.0, 0.0), (1.0, 4.0)], [2, 1]),
    ],
)
def test_the_pareto_front_of_hand_made_points(points: list[tuple[float, float]], front: list[int]) -> None:
    assert pareto_front(points) == front
    on = set(front)
    for i, p in enumerate(points):
        beaten = any(dominates(q, p) for j, q in enumerate(points) if j != i and not any(map(math.isnan, q)))
        assert (i in on) == (not beaten and not any(map(math.isnan, p))), i


def test_the_stability_cases_are_finite_and_within_their_budgets(real_tmx: Path) -> None:
    rows = classifier_stability(tofmat.ExemplarTable.load(real_tmx), quick=True)
    assert len(rows) == 7
    for r in rows:
        assert r.queries > 0 and r.distances > 0, r.case
        for v in (r.worst_error, r.bound_at_worst, r.worst_ratio, r.step_mm):
            assert math.isfinite(v) and v >= 0, (r.case, v)
        assert r.worst_ratio <= 1.0 + 1e-9, r.case  # docs/numerics.md: s * mean|q - e| + s^2 / 4
        assert r.labels_outside == 0 and r.valid_mismatch == 0, r.case
        assert r.within_budget, r.case
    saturated = next(r for r in rows if "saturation" in r.case)
    assert saturated.worst_error < saturated.bound_at_worst
    largest = next(r for r in rows if "largest table" in r.case)
    assert largest.note.endswith(": yes")  # (65534 s)^2 exactly over 2^20 elements
    half = next(r for r in rows if "one valid element" in r.case)
    assert half.worst_ratio > 0.999  # the bound is reached: it is tight


def test_the_decode_tests_figures_are_within_the_documented_budget(quick_report: Path) -> None:
    raw = quick_report.parent / "raw" / "test_fixed_decode.txt"
    if not raw.is_file():
        pytest.skip(f"{BUILD}/tests/cpp/test_fixed_decode is not built")
    f = parse_decode_test(raw.read_text())
    assert f is not None and f.passed
    assert max(f.phase_rad) < 1e-6 and max(f.depth_mm) < 0.002
    assert f.combined_mm < 0.006 and f.features_mm < 0.004 and f.amplitude_rel < 1e-4


STIFF_SAMPLE = """\
## Stiff cases

| stage | case | inputs | compared | quantity | worst error | budget | within budget |
|---|---|---|--:|---|--:|--:|---|
| decode: phase | near-zero amplitude | A 0.01..3 | 271673 | phase, rad | 2.78e-07 | 1e-06 | yes |
| depth bins | one valid element | one pixel a bin | 390 | observations in another bin | 0 | 0 | yes |
"""


def test_the_stiff_cases_reader_and_a_changed_format() -> None:
    rows = parse_stiff_cases(STIFF_SAMPLE)
    assert [(r.case, r.compared, r.worst, r.budget, r.within) for r in rows] == [
        ("near-zero amplitude", 271673, 2.78e-07, 1e-06, True),
        ("one valid element", 390, 0.0, 0.0, True),
    ]
    # A row outside its budget reads as such (the report shows it, it does not hide it).
    bad = parse_stiff_cases(STIFF_SAMPLE.replace("| 2.78e-07 | 1e-06 | yes |", "| 2e-06 | 1e-06 | NO |"))
    assert not bad[0].within
    # The program's verdict must agree with its numbers; a missing table or number is an error.
    with pytest.raises(BenchFormatError, match="within budget 'yes'"):
        parse_stiff_cases(STIFF_SAMPLE.replace("| 2.78e-07 | 1e-06 | yes |", "| 2e-06 | 1e-06 | yes |"))
    with pytest.raises(BenchFormatError, match="no table with the columns"):
        parse_stiff_cases(STIFF_SAMPLE.replace("worst error", "largest"))
    with pytest.raises(BenchFormatError, match="expected a number"):
        parse_stiff_cases(STIFF_SAMPLE.replace("| 390 |", "| - |"))
    with pytest.raises(BenchFormatError, match="no rows"):
        parse_stiff_cases("\n".join(STIFF_SAMPLE.splitlines()[:4]))


def test_the_counts_reader_and_a_changed_format() -> None:
    counts = parse_insn_counts(INSN_SAMPLE, "sample")
    assert [r.op for r in counts.rows] == ["decode", "roi", "nn", "dist", "dist"]
    assert counts.rows[0].neon_insns == 45029614 and math.isnan(counts.rows[3].float_insns)
    assert counts.qemu.startswith("qemu-aarch64 version 7.2")
    with pytest.raises(BenchFormatError, match="fixed neon"):
        parse_insn_counts(INSN_SAMPLE.replace("fixed NEON", "fixed SVE"), "sample")
    with pytest.raises(BenchFormatError, match="best kernel"):
        parse_bench_fixed("some other program's output\n")


def _fake_build(root: Path, bench_output: str) -> Path:
    """A build folder whose tofmat_bench_fixed prints ``bench_output`` (and has no profiles bench)."""
    exe = root / "tests" / "bench" / "tofmat_bench_fixed"
    exe.parent.mkdir(parents=True)
    exe.write_text("#!/bin/sh\ncat <<'EOF'\n" + bench_output + "\nEOF\n")
    exe.chmod(exe.stat().st_mode | stat.S_IXUSR)
    return root


def test_a_changed_benchmark_output_fails_with_a_clear_message(real_tmx: Path, tmp_path: Path) -> None:
    text = (
        "tofmat_bench_fixed: best kernel of this build = avx2; frames 512x424; one thread\n\n"
        "| path | frame time | error |\n|---|---:|---:|\n| float | 1.0 | 0 |\n"
    )
    build = _fake_build(tmp_path / "build", text)
    with pytest.raises(ReportError, match=r"output has changed.*report/cppbench\.py.*bench_fixed\.1\.txt"):
        write_report(tmp_path / "out", real_tmx, quick=True, build_dir=build, counts_dir=tmp_path)


def test_the_command_without_a_build_says_what_was_not_measured(real_tmx: Path, tmp_path: Path) -> None:
    runner = CliRunner()
    out = tmp_path / "out"
    r = runner.invoke(
        report,
        ["--table", str(real_tmx), "-o", str(out), "--quick", "--build-dir", str(tmp_path / "none"),
         "--counts-dir", str(tmp_path / "none")],
    )  # fmt: skip
    assert r.exit_code == 0, r.output
    md = Path(r.output.strip().splitlines()[-1])
    assert md == out / "report.md"
    text = md.read_text()
    assert "tofmat_bench_fixed` is not built" in text and "tofmat_bench_profiles` is not built" in text
    assert "Not measured here: no kept output of a cross run" in text and "make report-counts" in text
    assert "test_fixed_decode` is not built" in text
    for p in _links(md, image=True):
        assert p.read_bytes()[:8] == PNG_MAGIC
    # Numeric options are checked by click.
    for bad in (["--runs", "0"], ["--per-material", "0"], ["--noise", "nan"], ["--noise", "-1"]):
        r = runner.invoke(report, ["--table", str(real_tmx), "-o", str(out), *bad])
        assert r.exit_code == 2, (bad, r.output)
