# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The compact table file (.tmx): round trip, byte layout (docs/table-format.md), damaged files,
atomic saving."""

from __future__ import annotations

import fcntl
import math
import os
import signal
import struct
import subprocess
import sys
import time
import types
import zlib
from pathlib import Path

import numpy as np
import pytest

import tofmat
import tofmat.client

HEADER = struct.Struct("<8sHHIIIddd")  # magic, major, minor, n_materials, n_rows, n_bins, start, width, step
MISSING = -32768


def parse_tmx(data: bytes) -> dict:
    """An independent reader of the documented layout (no validation beyond what it needs)."""
    magic, major, minor, n_m, n_r, n_b, start, width, step = HEADER.unpack_from(data, 0)
    off = HEADER.size
    rows = [struct.unpack_from("<HH", data, off + 4 * i) for i in range(n_r)]
    off += 4 * n_r
    names = []
    for _ in range(n_m):
        n = data[off]
        names.append(data[off + 1 : off + 1 + n].decode("ascii"))
        off += 1 + n
    names_end = off
    values = np.frombuffer(data, "<i2", n_m * n_r * n_b, off).reshape(n_m, n_r, n_b)
    off += 2 * values.size
    (crc,) = struct.unpack_from("<I", data, off)
    return dict(
        magic=magic,
        major=major,
        minor=minor,
        start=start,
        width=width,
        step=step,
        rows=rows,
        names=names,
        values=values,
        crc=crc,
        crc_offset=off,
        names_end=names_end,
        size=off + 4,
    )


def with_crc(body: bytes) -> bytes:
    """Bytes before the checksum + a correct CRC-32: damage that only the field checks can catch."""
    return body + struct.pack("<I", zlib.crc32(body))


def patch(data: bytes, offset: int, fmt: str, value) -> bytes:
    """Overwrite one field and fix the checksum."""
    b = bytearray(data[:-4])
    struct.pack_into(fmt, b, offset, value)
    return with_crc(bytes(b))


def load_bytes(tmp_path: Path, data: bytes, name: str = "bad.tmx") -> tofmat.ExemplarTable:
    p = tmp_path / name
    p.write_bytes(data)
    return tofmat.ExemplarTable.load(p)


def is_power_of_two(x: float) -> bool:
    m, _ = math.frexp(x)
    return x > 0 and m == 0.5


# ---------------------------------------------------------------------------------------------
# Round trip of the real database
# ---------------------------------------------------------------------------------------------
def test_round_trip_real_database(real_table, real_tmx) -> None:
    t2 = tofmat.ExemplarTable.load(real_tmx)
    assert t2.materials == real_table.materials
    assert t2.rows == real_table.rows
    assert t2.bins == real_table.bins
    assert (t2.bins.start_mm, t2.bins.width_mm, t2.bins.count) == (
        real_table.bins.start_mm,
        real_table.bins.width_mm,
        real_table.bins.count,
    )
    step = t2.quant_step_mm
    assert step > 0 and is_power_of_two(step)
    a, b = real_table.features, t2.features
    assert b.dtype == np.float32 and b.shape == a.shape
    assert np.array_equal(np.isnan(a), np.isnan(b))
    assert t2.valid_counts == real_table.valid_counts
    ok = ~np.isnan(a)
    assert np.max(np.abs(a[ok].astype(np.float64) - b[ok])) <= step / 2
    # The step is the smallest power of two that fits the largest value in int16.
    max_abs = np.max(np.abs(a[ok]).astype(np.float64))
    assert round(max_abs / step) <= 32767 < round(max_abs / (step / 2))
    assert real_tmx.stat().st_size < 24 * 1024


def test_loaded_table_classifies_like_the_original(real_table, real_tmx) -> None:
    t2 = tofmat.ExemplarTable.load(real_tmx)
    clf = tofmat.Classifier(t2, method="eq12")
    for i, name in enumerate(real_table.materials):
        r = clf.classify(real_table.features[i])
        assert r.material == name
        assert r.distance <= (t2.quant_step_mm / 2) ** 2


def test_resaving_a_loaded_table_is_byte_identical(real_tmx, tmp_path) -> None:
    t2 = tofmat.ExemplarTable.load(real_tmx)
    again = tmp_path / "again.tmx"
    t2.save(again)
    assert again.read_bytes() == real_tmx.read_bytes()


def test_byte_layout_matches_the_documentation(real_table, real_tmx) -> None:
    data = real_tmx.read_bytes()
    f = parse_tmx(data)
    assert f["magic"] == b"TOFMATBL"
    assert (f["major"], f["minor"]) == (1, 0)
    assert f["size"] == len(data)
    assert f["start"] == real_table.bins.start_mm and f["width"] == real_table.bins.width_mm
    assert f["rows"] == real_table.rows
    assert f["names"] == real_table.materials
    assert f["crc"] == zlib.crc32(data[: f["crc_offset"]])
    step = f["step"]
    feats = real_table.features.astype(np.float64)
    expected = np.where(np.isnan(feats), MISSING, np.rint(np.nan_to_num(feats) / step)).astype(np.int16)
    np.testing.assert_array_equal(f["values"], expected)
    assert np.all(np.abs(f["values"][f["values"] != MISSING].astype(int)) <= 32767)


@pytest.mark.parametrize("scale", [1e-9, 1e-3, 1.0, 250.0, 1e6, 3e37])
def test_round_trip_synthetic_scales(tmp_path, rng, scale) -> None:
    feats = (rng.normal(0, 1, (3, 2, 17)) * scale).astype(np.float32)
    feats[1, 0, 5:9] = np.nan
    feats[2] = np.nan  # a material with no valid value survives the round trip
    bins = tofmat.BinSpec(-12.5, 0.75, 17)
    t = tofmat.ExemplarTable(["a", "b", "c"], feats, bins, [(20, 100), (0, 0)])
    p = tmp_path / "s.tmx"
    t.save(p)
    t2 = tofmat.ExemplarTable.load(p)
    step = t2.quant_step_mm
    assert is_power_of_two(step) and step >= 2.0**-24
    assert t2.materials == ["a", "b", "c"] and t2.rows == [(20, 100), (0, 0)] and t2.bins == bins
    assert np.array_equal(np.isnan(t2.features), np.isnan(feats))
    ok = ~np.isnan(feats)
    assert np.max(np.abs(feats[ok].astype(np.float64) - t2.features[ok])) <= step / 2 * (1 + 1e-6)
    max_abs = float(np.max(np.abs(feats[ok])))
    assert round(max_abs / step) <= 32767
    if step > 2.0**-24:
        assert round(max_abs / (step / 2)) > 32767


def test_round_trip_all_missing_table(tmp_path) -> None:
    t = tofmat.ExemplarTable(["a"], np.full((1, 1, 4), np.nan, np.float32), tofmat.BinSpec(0.0, 1.0, 4), [(16, 120)])
    t.save(tmp_path / "n.tmx")
    t2 = tofmat.ExemplarTable.load(tmp_path / "n.tmx")
    assert np.isnan(t2.features).all() and t2.valid_counts == [0]


# ---------------------------------------------------------------------------------------------
# Damaged files
# ---------------------------------------------------------------------------------------------
def test_truncated_files(real_tmx, tmp_path) -> None:
    data = real_tmx.read_bytes()
    names_end = parse_tmx(data)["names_end"]
    for cut in [
        0,
        1,
        7,
        8,
        9,
        11,
        20,
        47,
        48,
        55,
        names_end - 3,
        names_end,
        names_end + 1,
        len(data) // 2,
        len(data) - 5,
        len(data) - 1,
    ]:
        with pytest.raises(tofmat.FormatError, match="truncated") as e:
            load_bytes(tmp_path, data[:cut])
        assert "bad.tmx" in str(e.value), cut


def test_flipped_byte_is_a_checksum_error(real_tmx, tmp_path) -> None:
    data = bytearray(real_tmx.read_bytes())
    for pos in (len(data) // 2, len(data) // 3, len(data) - 5):
        bad = bytearray(data)
        bad[pos] ^= 0x01
        with pytest.raises(tofmat.FormatError, match="checksum"):
            load_bytes(tmp_path, bytes(bad))
    bad = bytearray(data)
    bad[-1] ^= 0x80  # the checksum itself
    with pytest.raises(tofmat.FormatError, match="checksum"):
        load_bytes(tmp_path, bytes(bad))


def test_wrong_magic(real_tmx, tmp_path) -> None:
    data = real_tmx.read_bytes()
    for magic in (b"TOFMATBX", b"\x00" * 8, b"\x93NUMPY\x01\x00"):
        with pytest.raises(tofmat.FormatError, match="magic"):
            load_bytes(tmp_path, with_crc(magic + data[8:-4]))
    with pytest.raises(tofmat.FormatError, match="magic"):
        load_bytes(tmp_path, b"PK\x03\x04" + b"\x00" * 200)


@pytest.mark.parametrize("major", [0, 2, 0xFFFF])
def test_wrong_major_version(real_tmx, tmp_path, major) -> None:
    data = real_tmx.read_bytes()
    with pytest.raises(tofmat.FormatError, match="version"):
        load_bytes(tmp_path, patch(data, 8, "<H", major))


def test_unknown_minor_version(real_tmx, tmp_path) -> None:
    # docs/table-format.md: minor version 0 to 3, else "unsupported version".
    data = real_tmx.read_bytes()
    for minor in (4, 0xFFFF):
        with pytest.raises(tofmat.FormatError, match="version"):
            load_bytes(tmp_path, patch(data, 10, "<H", minor))
    # A 1.0 file relabelled 1.1 lacks the noise block.
    with pytest.raises(tofmat.FormatError, match="truncated"):
        load_bytes(tmp_path, patch(data, 10, "<H", 1))


def test_noise_round_trips_in_a_version_1_1_file(real_table, real_tmx, tmp_path) -> None:
    noise = tofmat.curve_roughness(real_table)
    assert noise.shape == (29, 2) and np.all(noise > 0)
    t = real_table.with_noise(noise)
    path = tmp_path / "noisy.tmx"
    t.save(path)
    data = path.read_bytes()
    assert struct.unpack_from("<HH", data, 8) == (1, 1)
    assert len(data) == real_tmx.stat().st_size + 29 * 2 * 4  # one float32 per material and row
    back = tofmat.ExemplarTable.load(path)
    assert back.noise_mm is not None
    assert np.array_equal(back.noise_mm, noise.astype(np.float32).astype(np.float64))
    assert np.array_equal(back.features, tofmat.ExemplarTable.load(real_tmx).features, equal_nan=True)
    # A table without noise says so, and keeps writing 1.0.
    assert real_table.noise_mm is None and back.with_noise(None).noise_mm is None
    assert struct.unpack_from("<HH", real_tmx.read_bytes(), 8) == (1, 0)


def test_the_session_matcher_takes_the_tables_noise(real_table) -> None:
    stored = np.full((29, 2), np.nan)
    stored[3] = [0.9, 1.1]  # one material measured, the rest left to the roughness
    c = tofmat.Classifier(real_table.with_noise(stored), method="session")
    assert c.noise_mm is not None
    rough = tofmat.curve_roughness(real_table)
    assert np.allclose(c.noise_mm[3], [0.9, 1.1])
    assert np.array_equal(np.delete(c.noise_mm, 3, axis=0), np.delete(rough, 3, axis=0))


@pytest.mark.parametrize(
    ("noise", "match"),
    [
        (np.ones((29, 1)), "noise_mm"),
        (np.ones((28, 2)), "noise_mm"),
        (-np.ones((29, 2)), "noise"),
        (np.zeros((29, 2)), "noise"),
        (np.full((29, 2), np.inf), "noise"),
    ],
)
def test_bad_noise_is_a_clear_error(real_table, noise, match) -> None:
    with pytest.raises(ValueError, match=match):
        real_table.with_noise(noise)


def test_trailing_bytes(real_tmx, tmp_path) -> None:
    data = real_tmx.read_bytes()
    with pytest.raises(tofmat.FormatError, match="trailing"):
        load_bytes(tmp_path, data + b"\x00")
    with pytest.raises(tofmat.FormatError, match="trailing"):
        load_bytes(tmp_path, with_crc(data[:-4] + b"\x00\x00"))


def small_tmx(tmp_path: Path) -> bytes:
    t = tofmat.ExemplarTable(
        ["ab", "cd"],
        np.arange(2 * 1 * 3, dtype=np.float32).reshape(2, 1, 3),
        tofmat.BinSpec(600.0, 3.0, 3),
        [(16, 120)],
    )
    t.save(tmp_path / "small.tmx")
    return (tmp_path / "small.tmx").read_bytes()


@pytest.mark.parametrize(
    "offset, fmt, value",
    [
        (12, "<I", 0),  # no material
        (12, "<I", 4097),
        (12, "<I", 0xFFFFFFFF),
        (16, "<I", 0),  # no row
        (16, "<I", 17),
        (20, "<I", 0),  # no bin
        (20, "<I", 70000),
        (32, "<d", 0.0),  # bin width
        (32, "<d", -3.0),
        (32, "<d", float("nan")),
        (24, "<d", float("inf")),  # bin start
        (40, "<d", 0.0),  # quantisation step
        (40, "<d", -0.5),
        (40, "<d", float("nan")),
        (40, "<d", float("inf")),
        (52, "<B", 0),  # first name length
        (52, "<B", 200),
        (53, "<2s", b"cd"),  # duplicate name
        (53, "<2s", b"a "),  # name with a space
        (53, "<2s", b"\x00x"),
    ],
)
def test_bad_fields_with_a_valid_checksum(tmp_path, offset, fmt, value) -> None:
    data = small_tmx(tmp_path)
    assert data[52] == 2 and data[53:55] == b"ab"  # layout of this small file
    with pytest.raises(tofmat.FormatError) as e:
        load_bytes(tmp_path, patch(data, offset, fmt, value))
    assert "bad.tmx" in str(e.value)


def test_huge_dimensions_are_refused_quickly(tmp_path) -> None:
    data = small_tmx(tmp_path)
    b = patch(data, 12, "<I", 255)
    b = patch(b, 16, "<I", 16)
    b = patch(b, 20, "<I", 65535)
    with pytest.raises(tofmat.FormatError):
        load_bytes(tmp_path, b)


def test_missing_file_is_file_not_found_error(tmp_path) -> None:
    with pytest.raises(FileNotFoundError, match=r"nope\.tmx") as e:
        tofmat.ExemplarTable.load(tmp_path / "nope.tmx")
    assert not isinstance(e.value, ValueError)
    with pytest.raises(IsADirectoryError):
        tofmat.ExemplarTable.load(tmp_path)  # a folder


def test_unreadable_file_is_permission_error(real_table, tmp_path) -> None:
    path = tmp_path / "t.tmx"
    real_table.save(path)
    path.chmod(0)
    try:
        if os.access(path, os.R_OK):  # root reads it anyway: check as another user
            pid = os.fork()
            if pid == 0:
                os.setuid(12345)
                try:
                    tofmat.ExemplarTable.load(path)
                    os._exit(1)
                except PermissionError:
                    os._exit(0)
                except BaseException:
                    os._exit(2)
            assert os.waitpid(pid, 0)[1] == 0
        else:
            with pytest.raises(PermissionError):
                tofmat.ExemplarTable.load(path)
    finally:
        path.chmod(0o644)


def test_empty_file_is_format_error(tmp_path) -> None:
    with pytest.raises(tofmat.FormatError, match="truncated"):
        load_bytes(tmp_path, b"")


# ---------------------------------------------------------------------------------------------
# Saving
# ---------------------------------------------------------------------------------------------
def test_save_replaces_existing_file_and_leaves_no_temporaries(real_table, tmp_path) -> None:
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    target = out_dir / "table.tmx"
    small = tofmat.ExemplarTable(["x"], np.zeros((1, 2, 5), np.float32), tofmat.BinSpec(0.0, 1.0, 5), real_table.rows)
    small.save(target)
    assert tofmat.ExemplarTable.load(target).materials == ["x"]
    real_table.save(target)
    assert tofmat.ExemplarTable.load(target).materials == real_table.materials
    assert os.listdir(out_dir) == ["table.tmx"]
    assert (target.stat().st_mode & 0o777) == 0o644
    # Saving over a plain (non-table) file replaces it too.
    target.write_bytes(b"old junk")
    small.save(str(target))
    assert tofmat.ExemplarTable.load(target).materials == ["x"]
    assert os.listdir(out_dir) == ["table.tmx"]


def test_save_relative_path(real_table, tmp_path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    real_table.save("rel.tmx")
    assert sorted(os.listdir(tmp_path)) == ["rel.tmx"]
    assert tofmat.ExemplarTable.load("rel.tmx").materials == real_table.materials


def test_save_into_missing_directory_is_oserror(real_table, tmp_path) -> None:
    target = tmp_path / "no" / "such" / "dir" / "t.tmx"
    with pytest.raises(OSError):
        real_table.save(target)
    assert not (tmp_path / "no").exists()
    assert os.listdir(tmp_path) == []


def test_save_over_a_directory_is_oserror_and_cleans_up(real_table, tmp_path) -> None:
    (tmp_path / "t.tmx").mkdir()
    with pytest.raises(OSError):
        real_table.save(tmp_path / "t.tmx")
    assert os.listdir(tmp_path) == ["t.tmx"]
    assert (tmp_path / "t.tmx").is_dir()


def test_a_later_save_removes_what_a_killed_writer_left(real_table, tmp_path) -> None:
    # (issue 33) Temporaries of the target that no writer holds and that are older than 2 s go; one a
    # live writer holds locked stays, and so do another target's.
    stale = tmp_path / ".t.tmx.tmp.a1b2c3"
    held = tmp_path / ".t.tmx.tmp.d4e5f6"
    other = tmp_path / ".u.tmx.tmp.a1b2c3"
    for p in (stale, held, other):
        p.write_bytes(b"half a table")
        os.utime(p, (1e9, 1e9))
    with open(held, "rb") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        real_table.save(tmp_path / "t.tmx")
        assert sorted(os.listdir(tmp_path)) == sorted([held.name, other.name, "t.tmx"])
    real_table.save(tmp_path / "t.tmx")  # (no longer held)
    assert sorted(os.listdir(tmp_path)) == sorted([other.name, "t.tmx"])


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_an_import_killed_midway_leaves_nothing(db_dir, tmp_path, sig) -> None:
    # (issue 33) Killed at several points of `tofmat table import`, the folder holds the table or
    # nothing: never a temporary. SIGTERM ends it as Ctrl-C does (status 143, or 0 if it was done).
    target = tmp_path / "t.tmx"
    for delay in (0.4, 0.8, 1.2, 1.6, 2.0):
        p = subprocess.Popen([sys.executable, "-m", "tofmat", "table", "import", str(db_dir), "-o", str(target)],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)  # fmt: skip
        time.sleep(delay)
        p.send_signal(sig)
        _, err = p.communicate(timeout=60)
        assert sorted(os.listdir(tmp_path)) in ([], ["t.tmx"]), (delay, os.listdir(tmp_path))
        if sig == signal.SIGTERM:  # (-15: it came before the interpreter had started the command)
            assert p.returncode in (0, 143, -15) and b"Traceback" not in err, (p.returncode, err)


@pytest.mark.parametrize(
    ("curve", "says"),
    [("nan", "has no measured value"), ("zero", "has no measured value"), ("constant", "row 0 constant")],
)
def test_a_curve_that_is_no_measurement_is_refused_alike_by_import_and_tofmatd(db_files, tmp_path, curve, says) -> None:
    # (issue 33) One check, naming the file and the material: `tofmat table import` and tofmatd
    # refuse the same folder (tofmatd used to serve it), and the SDK's Classifier the same table.
    folder = tmp_path / "db"
    folder.mkdir()
    for name in ("cork", "wood"):
        (folder / f"{name}.npy").write_bytes(db_files[name].read_bytes())
    shape = tofmat.ExemplarTable.from_npy_dir(folder).features.shape[1:]  # (rows, bins)
    bad = np.full(shape, {"nan": np.nan, "zero": 0.0, "constant": 3.5}[curve])
    np.save(folder / "paper.npy", bad)
    p = subprocess.run([sys.executable, "-m", "tofmat", "table", "import", str(folder), "-o", str(tmp_path / "t.tmx")],
                       capture_output=True, text=True, timeout=120)  # fmt: skip
    assert p.returncode == 2 and "paper.npy" in p.stderr and 'material "paper"' in p.stderr and says in p.stderr, (
        p.stderr
    )
    assert not (tmp_path / "t.tmx").exists()
    d = subprocess.run([str(tofmat.client.daemon_binary()), "--source", "sim:static,material=cork", "--table",
                        str(folder), "--socket", str(tmp_path / "d.sock")], capture_output=True, text=True, timeout=60)  # fmt: skip
    assert d.returncode != 0 and "paper.npy" in d.stderr and says in d.stderr, (d.returncode, d.stderr)


def test_oversized_file_is_refused_before_reading(tmp_path) -> None:
    p = tmp_path / "big.tmx"
    with open(p, "wb") as f:
        f.truncate(64 * 1024 * 1024 + 1)  # sparse: one byte over the 64 MiB limit
    with pytest.raises(tofmat.FormatError, match="limit"):
        tofmat.ExemplarTable.load(p)


def test_longest_names_and_many_materials_round_trip(tmp_path) -> None:
    names = ["x" * 64] + [f"m{i}" for i in range(254)]  # 255 materials: the limit (the protocol's)
    feats = np.arange(255, dtype=np.float32).reshape(255, 1, 1)
    t = tofmat.ExemplarTable(names, feats, tofmat.BinSpec(0.0, 1.0, 1), [(16, 120)])
    t.save(tmp_path / "many.tmx")
    t2 = tofmat.ExemplarTable.load(tmp_path / "many.tmx")
    assert t2.materials == names
    np.testing.assert_array_equal(t2.features, feats)  # integers up to 254: exact with any step <= 1
    with pytest.raises(ValueError, match="255"):
        tofmat.ExemplarTable(
            [*names, "one_more"], np.zeros((256, 1, 1), np.float32), tofmat.BinSpec(0.0, 1.0, 1), [(16, 120)]
        )
    with pytest.raises(ValueError, match="ASCII"):
        tofmat.ExemplarTable(["café"], np.zeros((1, 1, 1), np.float32), tofmat.BinSpec(0.0, 1.0, 1), [(16, 120)])


def test_index_of_an_unknown_material_is_key_error_naming_the_table(real_table) -> None:
    assert real_table.index_of("cork") == real_table.materials.index("cork")
    with pytest.raises(KeyError, match="unknown material 'unobtainium'; the table has: acryl"):
        real_table.index_of("unobtainium")


def test_devices_are_typed_records(monkeypatch: pytest.MonkeyPatch) -> None:
    """tofmat.devices() is public: the driver's listing as Device records (none here: no Kinect)."""
    found = tofmat.devices()
    assert isinstance(found, list) and all(isinstance(d, tofmat.Device) for d in found)
    listing = [{"bus": 2, "port": "2-1", "product_id": 0x02D8, "serial": "0123", "accessible": False,
                "problem": "busy"}]  # fmt: skip
    monkeypatch.setattr(tofmat._tofmat, "kinect", types.SimpleNamespace(list_devices=lambda: listing))
    (d,) = tofmat.devices()
    assert d == tofmat.Device(bus=2, port="2-1", product_id=0x02D8, serial="0123", accessible=False, problem="busy")
    assert d.as_dict() == listing[0]


CALIBRATION = {
    "offset_sd_mm": [1.0, 0.4],
    "drift_sd_mm": [4.0, 2.0],
    "noise_scale": 1.2,
    "floor_mm": 0.3,
    "huber_k": 3.0,
    "iterations": 3,
    "methods": {
        "eq12": {"temperatures": [[1.0, 50.0], [100.0, 50.0]], "unknown_fits": []},
        "session": {"temperatures": [[1.0, 0.5], [100.0, 10.0]], "unknown_fits": [[1.0, 1.0], [100.0, 30.0]]},
    },
}


def test_a_tables_calibration_round_trips_in_a_version_1_3_file(real_table, tmp_path) -> None:
    grid = tofmat.BinSpec(450.0, 4.0, 500)
    t = real_table.with_distortion(grid, np.zeros((len(real_table), grid.count))).with_calibration(CALIBRATION)
    path = tmp_path / "calibrated.tmx"
    t.save(path)
    assert path.read_bytes()[10] == 3
    back = tofmat.ExemplarTable.load(path)
    assert back.calibration == CALIBRATION
    assert back.distortion_mm is not None and back.noise_mm is None
    # Everything else a table carries keeps it; None drops it.
    assert back.with_noise(None).calibration == CALIBRATION
    assert back.with_calibration(None).calibration is None
    real_table.save(tmp_path / "plain.tmx")
    assert (tmp_path / "plain.tmx").read_bytes()[10] == 0


def test_the_classifier_takes_the_tables_calibration(real_table) -> None:
    q = real_table.features[real_table.index_of("cork")].copy()
    q[:, 60:] = np.nan
    plain = tofmat.Classifier(real_table, backend="float", method="eq12").classify(q)
    own = tofmat.Classifier(real_table.with_calibration(CALIBRATION), backend="float", method="eq12").classify(q)
    at_50 = tofmat.Classifier(
        real_table, backend="float", method="eq12", calibration=tofmat.Calibration([(1.0, 50.0)])
    ).classify(q)
    assert plain.material == own.material == "cork"
    # The table's temperature of 50, not the built-in one (hundreds: Eq. (12) is made safe at every session size).
    assert own.confidence == pytest.approx(at_50.confidence, rel=1e-12)
    assert own.confidence > plain.confidence


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        ({"offset_sd_mm": [1.0]}, "row offsets"),
        ({"huber_k": 0.0}, "huber_k"),
        ({"methods": {"onnx": {"temperatures": [[1.0, 1.0]]}}}, "unknown method"),
        ({"methods": {"eq12": {"temperatures": []}}}, "temperature"),
        ({"drift_sd_mm": [1.0]}, "drift"),
        ({"colour": "red"}, "unknown key"),
    ],
)
def test_a_bad_calibration_is_a_clear_error(real_table, edit, match) -> None:
    with pytest.raises(ValueError, match=match):
        real_table.with_calibration({**CALIBRATION, **edit})
