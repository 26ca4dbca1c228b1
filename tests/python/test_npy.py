# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The core's .npy reader (tofmat.read_npy) and folder import (ExemplarTable.from_npy_dir)."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

import tofmat


def npy_bytes(header: str, data: bytes, version: tuple[int, int] = (1, 0)) -> bytes:
    """A .npy file written by hand: magic, version, header length, header padded with spaces
    and ended by '\\n' so that the data starts at a multiple of 64 bytes (npy format 1.0/2.0)."""
    len_size = 2 if version[0] == 1 else 4
    raw = header.encode("latin1")
    pad = (-(6 + 2 + len_size + len(raw) + 1)) % 64
    raw += b" " * pad + b"\n"
    length = struct.pack("<H", len(raw)) if len_size == 2 else struct.pack("<I", len(raw))
    out = b"\x93NUMPY" + bytes(version) + length + raw + data
    assert (len(out) - len(data)) % 64 == 0
    return out


def write(path: Path, content: bytes) -> Path:
    path.write_bytes(content)
    return path


PY2_HEADER = "{'descr': '<f8', 'fortran_order': False, 'shape': (2L, 3L), }"


def test_python2_header_with_long_suffixes(tmp_path, rng) -> None:
    a = rng.normal(0, 100, (2, 3))
    p = write(tmp_path / "py2.npy", npy_bytes(PY2_HEADER, a.astype("<f8").tobytes()))
    out = tofmat.read_npy(p)
    assert out.dtype == np.float64
    assert out.shape == (2, 3)
    np.testing.assert_array_equal(out, a)
    # numpy agrees on what the file holds.
    with pytest.warns(UserWarning):
        np.testing.assert_array_equal(np.load(p), a)
    assert np.array_equal(tofmat.read_npy(str(p)), a)


@pytest.mark.parametrize(
    "header, shape",
    [
        ("{'descr': '<f8', 'fortran_order': False, 'shape': (5L,), }", (5,)),
        ("{'descr': '<f8', 'fortran_order': False, 'shape': (1L, 2L, 3L), }", (1, 2, 3)),
        ('{"descr": "<f8", "fortran_order": False, "shape": (2, 3)}', (2, 3)),
        ("{'shape': (3, 2), 'fortran_order': False, 'descr': '<f8'}", (3, 2)),
        ("{'descr':'<f8','fortran_order':False,'shape':(2,3,),}", (2, 3)),
    ],
)
def test_header_variants(tmp_path, header, shape) -> None:
    a = np.arange(np.prod(shape), dtype="<f8").reshape(shape) - 2.5
    p = write(tmp_path / "v.npy", npy_bytes(header, a.tobytes()))
    np.testing.assert_array_equal(tofmat.read_npy(p), a)


@pytest.mark.parametrize("version", [(2, 0), (3, 0)])
def test_format_versions_2_and_3(tmp_path, version) -> None:
    a = np.linspace(-1, 1, 8).reshape(2, 4)
    header = "{'descr': '<f8', 'fortran_order': False, 'shape': (2, 4), }"
    p = write(tmp_path / "v.npy", npy_bytes(header, a.tobytes(), version))
    np.testing.assert_array_equal(tofmat.read_npy(p), a)


def test_files_written_by_numpy(tmp_path, rng) -> None:
    for dtype in (np.float64, np.float32):
        a = rng.normal(0, 1, (2, 200)).astype(dtype)
        a[0, 3] = np.nan
        np.save(tmp_path / "n.npy", a)
        out = tofmat.read_npy(tmp_path / "n.npy")
        assert out.dtype == np.float64
        np.testing.assert_array_equal(out, a.astype(np.float64))


def test_every_real_file_reads_like_numpy(db_files) -> None:
    import warnings

    for name, path in db_files.items():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ref = np.load(path)
        assert b"L, 200L" in path.read_bytes()[:128], name  # really Python 2 headers
        np.testing.assert_array_equal(tofmat.read_npy(path), ref, err_msg=name)


def test_rejects_int_dtype(tmp_path) -> None:
    header = "{'descr': '<i4', 'fortran_order': False, 'shape': (2L, 3L), }"
    p = write(tmp_path / "i4.npy", npy_bytes(header, np.arange(6, dtype="<i4").tobytes()))
    assert issubclass(tofmat.FormatError, ValueError)
    with pytest.raises(tofmat.FormatError, match=r"<i4") as e:
        tofmat.read_npy(p)
    assert "dtype" in str(e.value)
    assert "i4.npy" in str(e.value)


@pytest.mark.parametrize("cut", [1, 8, 47])
def test_rejects_truncated_data(tmp_path, cut) -> None:
    full = npy_bytes(PY2_HEADER, np.ones(6).tobytes())
    p = write(tmp_path / "t.npy", full[:-cut])
    with pytest.raises(tofmat.FormatError, match="truncated"):
        tofmat.read_npy(p)


@pytest.mark.parametrize("keep", [0, 3, 7, 9, 30])
def test_rejects_truncated_header(tmp_path, keep) -> None:
    full = npy_bytes(PY2_HEADER, np.ones(6).tobytes())
    p = write(tmp_path / "t.npy", full[:keep])
    with pytest.raises(tofmat.FormatError, match="truncated"):
        tofmat.read_npy(p)


@pytest.mark.parametrize(
    "content, match",
    [
        (npy_bytes(PY2_HEADER, np.ones(7).tobytes()), r"does not match"),  # extra data
        (b"\x93NUMPZ" + npy_bytes(PY2_HEADER, np.ones(6).tobytes())[6:], r"magic"),
        (npy_bytes(PY2_HEADER, np.ones(6).tobytes(), (4, 0)), r"version"),
        (npy_bytes(PY2_HEADER.replace("<f8", ">f8"), np.ones(6).tobytes()), r"dtype"),
        (npy_bytes(PY2_HEADER.replace("<f8", "|O"), np.ones(6).tobytes()), r"dtype"),
        (npy_bytes(PY2_HEADER.replace("False", "True"), np.ones(6).tobytes()), r"Fortran"),
        (npy_bytes("{'descr': '<f8', 'fortran_order': False, 'shape': (), }", np.ones(1).tobytes()), r"0-dim"),
        (
            npy_bytes("{'descr': '<f8', 'fortran_order': False, 'shape': (1, 1, 1, 1, 1), }", np.ones(1).tobytes()),
            r"dimensions",
        ),
        (
            npy_bytes("{'descr': '<f8', 'fortran_order': False, 'shape': (2, 3), 'x': 1}", np.ones(6).tobytes()),
            r"unknown key",
        ),
        (npy_bytes("{'descr': '<f8', 'shape': (2, 3)}", np.ones(6).tobytes()), r"lacks"),
        (npy_bytes("{'descr': '<f8', 'fortran_order': False, 'shape': (99999999999999999999999, 3), }", b""), r"large"),
        (npy_bytes("{'descr': '<f8', 'fortran_order': False, 'shape': (65536, 65536, 65536, 65536), }", b""), r"large"),
        (npy_bytes("{'descr': '<f8', 'fortran_order': False, 'shape': (-2, 3), }", b""), r"shape"),
    ],
)
def test_rejects_malformed_files(tmp_path, content, match) -> None:
    p = write(tmp_path / "bad.npy", content)
    with pytest.raises(tofmat.FormatError, match=match):
        tofmat.read_npy(p)


def test_missing_file_and_directory_are_oserror(tmp_path) -> None:
    with pytest.raises(FileNotFoundError):
        tofmat.read_npy(tmp_path / "nope.npy")
    with pytest.raises(IsADirectoryError):
        tofmat.read_npy(tmp_path)


# ---------------------------------------------------------------------------------------------
# from_npy_dir on synthetic folders
# ---------------------------------------------------------------------------------------------
def test_from_npy_dir_synthetic(tmp_path, rng) -> None:
    curves = {name: rng.normal(0, 10, (2, 50)) for name in ("zinc", "apple", "mud")}
    curves["apple"][:, 3] = 0.0  # both rows 0.0: missing
    curves["mud"][0, 7] = 0.0  # only one row 0.0: a real value
    for name, c in curves.items():
        np.save(tmp_path / f"{name}.npy", c)
    (tmp_path / "notes.txt").write_text("not a curve")
    (tmp_path / "sub.npy").mkdir()  # a folder named like a curve is not a curve
    t = tofmat.ExemplarTable.from_npy_dir(tmp_path, bin_start_mm=100.0, bin_stop_mm=198.0)
    assert t.materials == sorted(curves)  # sorted by name
    assert t.rows == [(16, 120), (80, 120)]
    assert t.bins.start_mm == 100.0 and t.bins.count == 50
    assert t.bins.width_mm == pytest.approx(2.0)
    for i, name in enumerate(t.materials):
        expected = curves[name].astype(np.float32)
        if name == "apple":
            expected[:, 3] = np.nan
        np.testing.assert_array_equal(t.features[i], expected)
    assert t.valid_counts == [98, 100, 100]


def test_from_npy_dir_other_row_counts_have_unknown_rows(tmp_path) -> None:
    np.save(tmp_path / "a.npy", 1.0 + np.arange(30.0).reshape(3, 10))  # (curves: a constant row is refused)
    np.save(tmp_path / "b.npy", 2.0 + np.arange(30.0).reshape(3, 10))
    t = tofmat.ExemplarTable.from_npy_dir(tmp_path)
    assert t.n_rows == 3 and t.rows == [(0, 0)] * 3


def test_from_npy_dir_errors(tmp_path) -> None:
    with pytest.raises(FileNotFoundError, match="no such directory"):
        tofmat.ExemplarTable.from_npy_dir(tmp_path / "nope")
    (tmp_path / "file").write_text("x")
    with pytest.raises(NotADirectoryError):
        tofmat.ExemplarTable.from_npy_dir(tmp_path / "file")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(FileNotFoundError, match=r"no \.npy files"):
        tofmat.ExemplarTable.from_npy_dir(empty)

    mixed = tmp_path / "mixed"
    mixed.mkdir()
    np.save(mixed / "a.npy", np.ones((2, 10)))
    np.save(mixed / "b.npy", np.ones((2, 11)))
    with pytest.raises(tofmat.FormatError, match="differs"):
        tofmat.ExemplarTable.from_npy_dir(mixed)

    flat = tmp_path / "flat"
    flat.mkdir()
    np.save(flat / "a.npy", np.ones(10))
    with pytest.raises(tofmat.FormatError, match="2-D"):
        tofmat.ExemplarTable.from_npy_dir(flat)

    inf = tmp_path / "inf"
    inf.mkdir()
    a = np.ones((2, 10))
    a[1, 4] = np.inf
    np.save(inf / "a.npy", a)
    with pytest.raises(tofmat.FormatError, match="infinite"):
        tofmat.ExemplarTable.from_npy_dir(inf)

    ints = tmp_path / "ints"
    ints.mkdir()
    np.save(ints / "a.npy", np.ones((2, 10), np.int64))
    with pytest.raises(tofmat.FormatError, match="dtype"):
        tofmat.ExemplarTable.from_npy_dir(ints)

    spaced = tmp_path / "spaced"
    spaced.mkdir()
    np.save(spaced / "white glass.npy", np.ones((2, 10)))
    with pytest.raises(ValueError, match="name"):
        tofmat.ExemplarTable.from_npy_dir(spaced)


def test_from_npy_dir_bin_arguments(db_dir) -> None:
    t = tofmat.ExemplarTable.from_npy_dir(db_dir, bin_start_mm=0.0, bin_stop_mm=199.0)
    assert (t.bins.start_mm, t.bins.width_mm, t.bins.count) == (0.0, 1.0, 200)
    for start, stop in ((1200.0, 600.0), (600.0, 600.0), (float("nan"), 600.0), (600.0, float("inf"))):
        with pytest.raises(ValueError):
            tofmat.ExemplarTable.from_npy_dir(db_dir, bin_start_mm=start, bin_stop_mm=stop)
