# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The `tofmat` command line, run as a user runs it: a subprocess of the installed entry point."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import tofmat


def tofmat_exe() -> list[str]:
    """The installed `tofmat` console script (next to this Python, else on PATH)."""
    here = Path(sys.executable).parent / "tofmat"
    if here.exists():
        return [str(here)]
    found = shutil.which("tofmat")
    if not found:
        pytest.fail("the `tofmat` command is not installed (neither next to sys.executable nor on PATH)")
    return [found]


def run(*args: str | Path, ok: bool = True) -> subprocess.CompletedProcess[str]:
    p = subprocess.run([*tofmat_exe(), *map(str, args)], capture_output=True, text=True, timeout=120)
    if ok:
        assert p.returncode == 0, f"tofmat {' '.join(map(str, args))} failed ({p.returncode}):\n{p.stdout}\n{p.stderr}"
    return p


def assert_clean_error(p: subprocess.CompletedProcess[str], *words: str) -> str:
    """Non-zero exit, one line on stderr naming the problem, no Python traceback."""
    assert p.returncode != 0
    assert "Traceback" not in p.stderr and "Traceback" not in p.stdout
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, p.stderr
    msg = lines[0]
    assert any(w in msg for w in words), f"none of {words} in: {msg}"
    return msg


@pytest.fixture(scope="module")
def cli_table(db_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("cli") / "db.tmx"
    p = run("table", "import", db_dir, "-o", out)
    assert out.is_file()
    assert str(out.stat().st_size) in p.stdout and "29 materials" in p.stdout
    return out


def test_version_and_help() -> None:
    p = run("--version")
    assert tofmat.__version__ in p.stdout
    p = run("--help")
    for cmd in ("table", "classify", "plot", "bench", "sweeps", "demo", "watch", "status", "record"):
        assert cmd in p.stdout
    # `python -m tofmat` is the same command.
    p2 = subprocess.run([sys.executable, "-m", "tofmat", "--version"], capture_output=True, text=True, timeout=60)
    assert p2.returncode == 0 and tofmat.__version__ in p2.stdout


def test_table_import_writes_a_loadable_table(cli_table: Path, real_table) -> None:
    t = tofmat.ExemplarTable.load(cli_table)
    assert t.materials == real_table.materials
    assert t.rows == real_table.rows and t.bins == real_table.bins
    assert np.array_equal(np.isnan(t.features), np.isnan(real_table.features))
    assert np.nanmax(np.abs(t.features - real_table.features)) <= t.quant_step_mm / 2


def test_table_import_stores_each_curves_noise(cli_table: Path, db_dir: Path, real_table, tmp_path: Path) -> None:
    t = tofmat.ExemplarTable.load(cli_table)
    assert t.noise_mm is not None
    assert np.allclose(t.noise_mm, tofmat.curve_roughness(real_table), rtol=1e-6)
    info = json.loads(run("table", "info", cli_table, "--json").stdout)
    assert info["noise_mm"]["cork"] == pytest.approx(list(t.noise_mm[t.index_of("cork")]))
    assert "noise" in run("table", "info", cli_table).stdout
    # --no-noise writes a version 1.0 file for older readers.
    old = tmp_path / "old.tmx"
    p = run("table", "import", db_dir, "-o", old, "--no-noise")
    assert "without noise" in p.stdout
    assert old.read_bytes()[8:12] == b"\x01\x00\x00\x00"
    assert tofmat.ExemplarTable.load(old).noise_mm is None
    assert json.loads(run("table", "info", old, "--json").stdout)["noise_mm"] is None


def test_table_info_text(cli_table: Path) -> None:
    p = run("table", "info", cli_table)
    assert "29 materials x 2 rows x 200 bins" in p.stdout
    assert "d(16 MHz) - d(120 MHz)" in p.stdout and "d(80 MHz) - d(120 MHz)" in p.stdout
    assert "paper" in p.stdout and "388/400" in p.stdout


def test_table_info_json(cli_table: Path, db_dir: Path, real_table) -> None:
    info = json.loads(run("table", "info", cli_table, "--json").stdout)
    assert len(info["materials"]) == 29
    assert info["materials"] == real_table.materials
    assert info["bins"]["count"] == 200
    assert info["bins"]["start_mm"] == 600.0
    assert info["bins"]["width_mm"] == pytest.approx(600 / 199)
    assert info["rows"] == [{"freq_mhz": 16, "ref_freq_mhz": 120}, {"freq_mhz": 80, "ref_freq_mhz": 120}]
    assert info["bytes"] == cli_table.stat().st_size
    assert info["valid_elements"]["paper"] < 400 and info["valid_elements"]["cork"] == 400
    assert info["quant_step_mm"] > 0
    # A folder of .npy curves is described the same way (unquantised).
    info_dir = json.loads(run("table", "info", db_dir, "--json").stdout)
    assert info_dir["materials"] == info["materials"] and info_dir["quant_step_mm"] == 0


def test_classify_single_query(cli_table: Path, real_table, tmp_path: Path, rng) -> None:
    for name in ("pvc", "copper", "fakebanana"):
        m = real_table.index_of(name)
        q = np.full((2, 200), np.nan)
        q[:, 60:90] = real_table.features[m][:, 60:90] + rng.normal(0, 0.2, (2, 30))
        path = tmp_path / f"{name}.npy"
        np.save(path, q)
        out = json.loads(run("classify", "--table", cli_table, path, "--json").stdout)
        assert out["material"] == name
        assert out["valid"] == 60
        assert out["ranking"][0]["material"] == name
        assert len(out["ranking"]) == 5  # --top default
        d = [x["distance"] for x in out["ranking"]]
        assert d == sorted(d) and out["distance"] == d[0]
        assert 0 < out["confidence"] <= 1 and out["unknown"] is False and "fit" in out  # the session matcher
    # Plain text output names the label.
    p = run("classify", "--table", cli_table, tmp_path / "pvc.npy")
    assert p.stdout.split()[0] == "pvc" and "score" in p.stdout and "confidence" in p.stdout
    # Eq. (12) by name: its distance in mm^2, no fit.
    e = json.loads(run("classify", "--table", cli_table, tmp_path / "pvc.npy", "--json", "--method", "eq12").stdout)
    assert e["material"] == "pvc" and "fit" not in e and e["distance"] < 1.0
    assert "mm^2" in run("classify", "--table", cli_table, tmp_path / "pvc.npy", "--method", "eq12").stdout


def test_classify_batch_query(cli_table: Path, real_table, tmp_path: Path, rng) -> None:
    mats = [3, 11, 20, 27, 0, 14]
    qs = (real_table.features[mats] + rng.normal(0, 0.2, (len(mats), 2, 200))).astype(np.float32)
    qs[2, :, :10] = np.nan
    np.save(tmp_path / "batch.npy", qs)
    out = json.loads(run("classify", "--table", cli_table, tmp_path / "batch.npy", "--json", "--top", "2").stdout)
    assert isinstance(out, list) and len(out) == len(mats)
    assert [o["material"] for o in out] == [real_table.materials[m] for m in mats]
    assert all(len(o["ranking"]) == 2 for o in out)
    # The same as the library on the same queries.
    lib = tofmat.Classifier(tofmat.ExemplarTable.load(cli_table)).classify_batch(qs)
    assert [o["distance"] for o in out] == pytest.approx([r.distance for r in lib], rel=1e-12)


def test_classify_with_materials(cli_table: Path, real_table, tmp_path: Path) -> None:
    np.save(tmp_path / "q.npy", real_table.features[real_table.index_of("copper")])
    out = json.loads(
        run("classify", "--table", cli_table, tmp_path / "q.npy", "--json", "--materials", "pvc,epvc",
            "--open-set").stdout
    )  # fmt: skip
    # Copper is neither: with its open set the session matcher says unknown, and names the nearest.
    assert out["material"] == "unknown" and out["unknown"] is True and out["index"] == -1
    assert out["nearest"] in ("pvc", "epvc")
    assert {x["material"] for x in out["ranking"]} == {"pvc", "epvc"}
    # Without it (the default), and with Eq. (12), the nearest is the label.
    args = ("classify", "--table", cli_table, tmp_path / "q.npy", "--json", "--materials", "pvc,epvc")
    assert json.loads(run(*args).stdout)["material"] in ("pvc", "epvc")
    assert json.loads(run(*args, "--method", "eq12").stdout)["material"] in ("pvc", "epvc")
    assert_clean_error(run(*args, "--method", "eq12", "--open-set", ok=False), "--method session")
    p = run("classify", "--table", cli_table, tmp_path / "q.npy", "--materials", "pvc,granite", ok=False)
    assert_clean_error(p, "granite")


@pytest.mark.parametrize("shape", [(2, 199), (3, 200), (4, 2, 199), (400,)])
def test_classify_bad_query_shape_is_one_line(cli_table: Path, tmp_path: Path, shape) -> None:
    np.save(tmp_path / "bad.npy", np.zeros(shape, np.float32))
    p = run("classify", "--table", cli_table, tmp_path / "bad.npy", ok=False)
    msg = assert_clean_error(p, "expected")
    assert "(2, 200)" in msg or "2, 200)" in msg


@pytest.mark.parametrize(
    "make, words",
    [
        (lambda p: np.save(p, np.zeros((2, 200), np.int32)), ("dtype",)),
        (lambda p: np.save(p, np.full((2, 200), np.nan)), ("no valid element",)),
        (lambda p: np.save(p, np.full((2, 200), np.inf)), ("infinite",)),
        (lambda p: np.save(p, np.array([{"a": 1}], dtype=object), allow_pickle=True), ("npy", "pickle", "object")),
        (lambda p: p.write_bytes(b"not a numpy file"), ("npy", "magic", "readable")),
    ],
)
def test_classify_bad_query_files_are_one_line(cli_table: Path, tmp_path: Path, make, words) -> None:
    path = tmp_path / "bad.npy"
    make(path)
    assert_clean_error(run("classify", "--table", cli_table, path, ok=False), *words)


def test_corrupt_table_is_one_line(cli_table: Path, real_table, tmp_path: Path) -> None:
    np.save(tmp_path / "q.npy", real_table.features[0])
    data = bytearray(cli_table.read_bytes())
    flipped = tmp_path / "flipped.tmx"
    data[len(data) // 2] ^= 0x10
    flipped.write_bytes(bytes(data))
    msg = assert_clean_error(run("classify", "--table", flipped, tmp_path / "q.npy", ok=False), "checksum", "magic")
    assert "flipped.tmx" in msg
    junk = tmp_path / "junk.tmx"
    junk.write_bytes(b"JUNKJUNK" + bytes(data[8:]))
    assert_clean_error(run("classify", "--table", junk, tmp_path / "q.npy", ok=False), "checksum", "magic")
    assert_clean_error(run("table", "info", junk, ok=False), "magic")
    truncated = tmp_path / "short.tmx"
    truncated.write_bytes(bytes(data[:1000]))
    assert_clean_error(run("table", "info", truncated, ok=False), "truncated")


def test_table_import_errors_are_one_line(tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    assert_clean_error(run("table", "import", tmp_path / "empty", "-o", tmp_path / "x.tmx", ok=False), "no .npy")
    assert not (tmp_path / "x.tmx").exists()
    bad = tmp_path / "bad"
    bad.mkdir()
    np.save(bad / "a.npy", np.ones((2, 10), np.int16))
    assert_clean_error(run("table", "import", bad, "-o", tmp_path / "x.tmx", ok=False), "dtype")


def test_table_import_into_missing_folder_is_one_line(db_dir: Path, tmp_path: Path) -> None:
    assert_clean_error(
        run("table", "import", db_dir, "-o", tmp_path / "no" / "x.tmx", ok=False), "no", "cannot", "No such"
    )


def test_plot_table_writes_png(cli_table: Path, tmp_path: Path) -> None:
    out = tmp_path / "plots" / "curves.png"
    run("plot", "table", cli_table, "-o", out)
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert data[12:16] == b"IHDR"
    assert len(data) > 10 * 1024
    width, height = int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
    assert width > 500 and height > 500


def test_bench_json(cli_table: Path) -> None:
    out = json.loads(run("bench", "--table", cli_table, "--windows", "1,10", "--per-material", "3", "--json").stdout)
    assert isinstance(out, list) and [(r["backend"], r["window_bins"]) for r in out] == [
        ("float", 1), ("float", 10), ("fixed", 1), ("fixed", 10)]  # fmt: skip
    for r in out:
        assert 0.0 <= r["accuracy"] <= 1.0
        assert r["queries"] == 3 * 29
        assert r["us_per_query"] > 0 and r["us_per_query_batch"] > 0
    assert out[1]["accuracy"] >= 0.9  # 10-bin windows: measured 100 % here (87 queries)
    assert out[3]["accuracy"] == out[1]["accuracy"]  # the same queries, the same labels
    only = json.loads(run("bench", "--table", cli_table, "--windows", "3", "--per-material", "2", "--backends",
                          "fixed", "--json").stdout)  # fmt: skip
    assert [r["backend"] for r in only] == ["fixed"]
    assert_clean_error(run("bench", "--table", cli_table, "--backends", "fixed,nope", ok=False), "backend")


def test_bench_on_real_database_1_bin_windows_other_seeds(db_dir: Path) -> None:
    # 1-bin windows of paper, plaster or fakeapple can land on one of their missing bins, which
    # makes an all-NaN query. With --seed 1 (the 1-bin windows then use numpy seed 2; 40 windows
    # per material) two windows fall on paper's missing bins 3 and 4; the benchmark must still
    # report (skip or count such windows), not abort with "query has no valid element".
    p = run("bench", "--table", db_dir, "--windows", "1", "--per-material", "40", "--seed", "1", "--json", ok=False)
    assert p.returncode == 0, f"bench aborted: {p.stderr.strip()}"
    out = json.loads(p.stdout)
    assert 0.0 <= out[0]["accuracy"] <= 1.0


def test_sweeps_runs(cli_table: Path) -> None:
    p = run("sweeps", "--table", cli_table, "--sweeps", "3", "--sweep-bins", "30")
    assert "final labels:" in p.stdout
    assert p.stdout.count("sweep ") >= 3


def test_devices_without_a_kinect_exits_1_with_one_line_reason() -> None:
    from click.testing import CliRunner

    from tofmat.cli import main

    r = CliRunner().invoke(main, ["devices"])
    assert r.exit_code == 1
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert lines == [lines[-1]] and "no Kinect v2" in lines[-1]


def test_usb_error_is_an_oserror_with_a_kind() -> None:
    import pytest

    import tofmat
    from tofmat import _tofmat

    with pytest.raises(tofmat.UsbError) as e:
        _tofmat.kinect.open_device()
    assert isinstance(e.value, OSError)
    assert e.value.kind == "no device"


def test_table_calibrate_stores_the_tables_own_calibration(real_table, tmp_path: Path) -> None:
    # Four materials of the real curves, two sessions a material and split: a short calibration.
    from tofmat.evaluation.open_set import subset

    names = ["cork", "pvc", "acryl", "wood"]
    small = subset(real_table, [real_table.index_of(m) for m in names])
    grid = tofmat.BinSpec(450.0, 4.0, 500)
    src = tmp_path / "four.tmx"
    small.with_distortion(grid, np.ones((4, grid.count))).save(src)
    out = tmp_path / "calibrated.tmx"
    p = run("table", "calibrate", src, "-o", out, "--sessions", "2", "--json")
    written = json.loads(p.stdout)
    t = tofmat.ExemplarTable.load(out)
    assert t.calibration == written
    assert set(written["methods"]) == {"eq12", "session"}
    assert len(written["offset_sd_mm"]) == 2 and all(v > 0 for v in written["offset_sd_mm"])
    assert [k[0] for k in written["methods"]["session"]["temperatures"]] == [1.0, 3.0, 10.0, 30.0, 100.0]
    assert written["methods"]["session"]["unknown_fits"]
    # Everything else the table had stays; the matchers take the table's temperatures.
    assert t.materials == names and t.distortion_mm is not None and np.allclose(t.distortion_mm, 1.0)
    q = t.features[0].copy()
    q[:, 50:] = np.nan
    own = tofmat.Classifier(t, method="eq12").classify(q).confidence
    builtin = tofmat.Classifier(t.with_calibration(None), method="eq12").classify(q).confidence
    assert own != builtin
    # A table of one material cannot be calibrated; nothing is written.
    one = tmp_path / "one.tmx"
    subset(real_table, [0]).save(one)
    before = one.read_bytes()
    assert_clean_error(run("table", "calibrate", one, ok=False), "one material")
    assert one.read_bytes() == before


def test_sim_table_calibrates_the_table_it_records(tmp_path: Path) -> None:
    # Two materials, one rendered session a material and split: a short calibration.
    small = ["--materials", "cork,paper", "--bins", "20"]
    cal = tmp_path / "cal.tmx"
    p = run("sim", "table", *small, "--calibration-sessions", "1", "-o", cal)
    assert "calibrated on 1 sessions" in p.stdout, p.stdout
    c = tofmat.ExemplarTable.load(cal).calibration
    assert c is not None and set(c["methods"]) == {"eq12", "session"}
    assert [k[0] for k in c["methods"]["session"]["temperatures"]][:3] == [1.0, 3.0, 10.0]  # (20 bins: no 100)
    # 0: recorded only; --keep-current then calibrates that table in place, its recording kept.
    bare = tmp_path / "bare.tmx"
    assert "not calibrated" in run("sim", "table", *small, "--calibration-sessions", "0", "-o", bare).stdout
    recorded = tofmat.ExemplarTable.load(bare)
    assert recorded.calibration is None
    p = run("sim", "table", "--keep-current", "--calibration-sessions", "1", "-o", bare)
    assert "current, not calibrated; calibrated" in p.stdout, p.stdout
    kept = tofmat.ExemplarTable.load(bare)
    assert kept.calibration is not None and kept.materials == ["cork", "paper"]
    assert np.array_equal(kept.features, recorded.features, equal_nan=True)
    # A calibrated current table is kept as it is.
    before = bare.read_bytes()
    assert "kept" in run("sim", "table", "--keep-current", "-o", bare).stdout
    assert bare.read_bytes() == before
    # The calibration renders with the default simulator: another device with a calibration asked
    # for is a clear error, nothing written; by default such a table is recorded uncalibrated.
    from tofmat.sim import DEFAULT_DEVICE, data_dir

    device = tmp_path / "my_kinect.json"
    shutil.copy(data_dir() / "devices" / f"{DEFAULT_DEVICE}.json", device)
    other = tmp_path / "other.tmx"
    err = assert_clean_error(
        run("sim", "table", *small, "--device", device, "--calibration-sessions", "2", "-o", other, ok=False),
        "--calibration-sessions",
    )
    assert "default device" in err and not other.exists()
    assert "not calibrated" in run("sim", "table", *small, "--device", device, "-o", other).stdout
    assert tofmat.ExemplarTable.load(other).calibration is None
    # One material has nothing to calibrate a choice on.
    assert_clean_error(run("sim", "table", "--materials", "cork", "-o", other, ok=False), "one material")


def test_sim_table_records_every_material_at_each_angle(tmp_path: Path) -> None:
    small = ["--materials", "cork,paper", "--bins", "20"]
    path = tmp_path / "angles.tmx"
    p = run("sim", "table", *small, "--yaws", "0,30", "--calibration-sessions", "0", "-o", path)
    assert "2 materials at 0, 30 degrees, 4 exemplars" in p.stdout and "not calibrated" in p.stdout, p.stdout
    t = tofmat.ExemplarTable.load(path)
    assert t.materials == ["cork@0", "paper@0", "cork@30", "paper@30"] and t.calibration is None
    # Each exemplar is its material at its angle: the 0-degree ones are what --yaw 0 records, the
    # 30-degree curves differ from them, and each carries its own depth distortion.
    one = tmp_path / "zero.tmx"
    run("sim", "table", *small, "--yaw", "0", "--calibration-sessions", "0", "-o", one)
    zero = tofmat.ExemplarTable.load(one)
    assert np.array_equal(t.features[:2], zero.features, equal_nan=True)
    assert not np.allclose(t.features[2:], t.features[:2], equal_nan=True)
    assert t.distortion_mm is not None and zero.distortion_mm is not None
    assert np.array_equal(t.distortion_mm[:2], zero.distortion_mm, equal_nan=True)
    # A label names the material, never the angle.
    r = tofmat.Classifier(t, method="eq12").classify(t.features[3])
    assert r.material == "paper" and [m.material for m in r.ranking] == ["paper", "cork"]
    # --keep-current keeps a table of these materials at these angles, records another again.
    before = path.read_bytes()
    assert "kept" in run("sim", "table", *small, "--yaws", "0,30", "--keep-current", "--calibration-sessions", "0",
                         "-o", path).stdout  # fmt: skip
    assert path.read_bytes() == before
    p = run("sim", "table", *small, "--yaws", "0,20", "--keep-current", "--calibration-sessions", "0", "-o", path)
    assert "recording it again" in p.stderr and tofmat.ExemplarTable.load(path).materials[2] == "cork@20"
    # With a calibration: the first angle's, on every exemplar of the material.
    cal = tmp_path / "cal.tmx"
    p = run("sim", "table", *small, "--yaws", "10,40", "--calibration-sessions", "1", "-o", cal)
    assert "calibrated on 1 sessions" in p.stdout, p.stdout
    c = tofmat.ExemplarTable.load(cal)
    assert c.calibration is not None and c.materials == ["cork@10", "paper@10", "cork@40", "paper@40"]
    # Bad angles: a clear error, nothing written.
    bad = tmp_path / "bad.tmx"
    for yaws, what in (("0,0", "must differ"), ("0,70", "--yaws"), ("x", "--yaws")):
        assert_clean_error(run("sim", "table", *small, "--yaws", yaws, "-o", bad, ok=False), what)
    assert_clean_error(run("sim", "table", *small, "--yaw", "5", "--yaws", "0,30", "-o", bad, ok=False), "not both")
    many = ",".join(str(y) for y in range(0, 60, 5))  # 12 angles x 29 materials > 255 exemplars
    assert_clean_error(run("sim", "table", "--yaws", many, "-o", bad, ok=False), "at most 255")
    assert not bad.exists()


def test_the_commands_own_sim_table_is_calibrated_once(tmp_path: Path) -> None:
    # What `tofmat demo` and the other commands without --table use (build/sim_table.tmx).
    from tofmat.sim.own_table import ensure_sim_table

    path = tmp_path / "sim_table.tmx"
    run("sim", "table", "--materials", "cork,paper", "--bins", "20", "--calibration-sessions", "0", "-o", path)
    recorded, first = tofmat.ExemplarTable.load(path), path.read_bytes()
    assert ensure_sim_table(path, sessions=0) == path and path.read_bytes() == first  # 0: not calibrated, kept
    ensure_sim_table(path, sessions=1)  # current, not calibrated: calibrated, its recording kept
    kept = tofmat.ExemplarTable.load(path)
    assert kept.calibration is not None and kept.materials == ["cork", "paper"]
    assert np.array_equal(kept.features, recorded.features, equal_nan=True)
    before = path.read_bytes()
    ensure_sim_table(path, sessions=1)  # current and calibrated: kept as it is
    assert path.read_bytes() == before
