// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The .npy reader: the real database's files, the header dialects NumPy has
// written over the years, and everything a hostile or damaged file can say.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <iterator>
#include <limits>

#include "test_util.hpp"
#include "tofmat/core/error.hpp"
#include "tofmat/core/npy.hpp"

namespace {

using tofmat::FormatError;
using tofmat::parse_npy;
using tofmat_test::Bytes;
using tofmat_test::error_of;
using tofmat_test::f4_le;
using tofmat_test::f8_le;
using tofmat_test::npy_file;

const std::vector<double> kSix = {1.5, -2.25, 0.0, 1e-300, -7.0, 123456.75};

std::string dict(const std::string& descr, const std::string& order, const std::string& shape) {
  return "{'descr': '" + descr + "', 'fortran_order': " + order + ", 'shape': " + shape + ", }";
}

// A small valid file: 2x3 '<f8', NumPy 1.0 layout (176 bytes).
Bytes small_f8() { return npy_file(1, 0, dict("<f8", "False", "(2, 3)"), f8_le(kSix)); }

std::string parse_error(const Bytes& b) {
  return error_of<FormatError>([&] { parse_npy(b.data(), b.size()); });
}

TEST(Npy, ReadsEveryRealDatabaseFile) {
  ASSERT_DB_PRESENT();
  for (const auto& f : tofmat_test::db_files()) {
    SCOPED_TRACE(f.string());
    const auto a = tofmat::read_npy_file(f);
    ASSERT_EQ(a.shape, (std::vector<std::size_t>{2, 200}));
    ASSERT_EQ(a.data.size(), 400u);
    for (double v : a.data) ASSERT_TRUE(std::isfinite(v));
  }
}

TEST(Npy, RealDatabaseValuesAreBitExact) {
  ASSERT_DB_PRESENT();
  // Reference values read with NumPy 2.4 (np.load('acryl.npy')[r, c].hex()).
  const auto a = tofmat::read_npy_file(tofmat_test::db_dir() / "acryl.npy");
  EXPECT_EQ(a.data[0], 0x1.bfc67717f3b08p+6);    // row 0, bin 0
  EXPECT_EQ(a.data[399], 0x1.318f770111500p+2);  // row 1, bin 199
  const auto p = tofmat::read_npy_file(tofmat_test::db_dir() / "paper.npy");
  for (std::size_t b = 0; b < 6; ++b) EXPECT_EQ(p.data[b], 0.0) << "paper misses bins 0..5 (all-0.0 marker)";
}

TEST(Npy, Python2LongSuffixParses) {
  const Bytes b = npy_file(1, 0, dict("<f8", "False", "(2L, 3L)"), f8_le(kSix));
  const auto a = parse_npy(b.data(), b.size());
  EXPECT_EQ(a.shape, (std::vector<std::size_t>{2, 3}));
  EXPECT_EQ(a.data, kSix);
}

TEST(Npy, FormatVersions1To3) {
  for (std::uint8_t major : {std::uint8_t{1}, std::uint8_t{2}, std::uint8_t{3}}) {
    SCOPED_TRACE(int{major});
    const Bytes b = npy_file(major, 0, dict("<f8", "False", "(6,)"), f8_le(kSix));
    const auto a = parse_npy(b.data(), b.size());
    EXPECT_EQ(a.shape, (std::vector<std::size_t>{6}));
    EXPECT_EQ(a.data, kSix);
  }
}

TEST(Npy, HeaderVariantsNumpyWrites) {
  // Double quotes, keys in another order, no trailing comma, tab/no spaces.
  const Bytes b = npy_file(1, 0, "{\"shape\":(1,2,3),\t\"fortran_order\":False,\"descr\":\"<f8\"}", f8_le(kSix));
  const auto a = parse_npy(b.data(), b.size());
  EXPECT_EQ(a.shape, (std::vector<std::size_t>{1, 2, 3}));
  EXPECT_EQ(a.data, kSix);
}

TEST(Npy, Float32IsWidened) {
  const std::vector<float> v = {0.1f, -3.5f, 1e30f, -0.0f};
  const Bytes b = npy_file(1, 0, dict("<f4", "False", "(2, 2)"), f4_le(v));
  const auto a = parse_npy(b.data(), b.size());
  ASSERT_EQ(a.data.size(), 4u);
  for (std::size_t i = 0; i < v.size(); ++i) EXPECT_EQ(a.data[i], static_cast<double>(v[i]));
  EXPECT_TRUE(std::signbit(a.data[3]));
}

TEST(Npy, NanIsPassedThrough) {
  // The reader does not judge values; missing-data policy belongs to the table loader.
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const Bytes b = npy_file(1, 0, dict("<f8", "False", "(2,)"), f8_le({nan, 1.0}));
  const auto a = parse_npy(b.data(), b.size());
  EXPECT_TRUE(std::isnan(a.data[0]));
  EXPECT_EQ(a.data[1], 1.0);
}

TEST(Npy, ZeroSizedArrayIsEmpty) {
  const Bytes b = npy_file(1, 0, dict("<f8", "False", "(0, 200)"), {});
  const auto a = parse_npy(b.data(), b.size());
  EXPECT_EQ(a.shape, (std::vector<std::size_t>{0, 200}));
  EXPECT_TRUE(a.data.empty());
}

TEST(Npy, RejectsOtherDtypes) {
  for (const char* descr : {"<i4", ">f8", "|u1", ">f4", "<f2", "<c16", "f8", ""}) {
    SCOPED_TRACE(descr);
    const Bytes b = npy_file(1, 0, dict(descr, "False", "(6,)"), f8_le(kSix));
    EXPECT_CONTAINS(parse_error(b), "dtype");
  }
}

TEST(Npy, RejectsFortranOrder) {
  const Bytes b = npy_file(1, 0, dict("<f8", "True", "(2, 3)"), f8_le(kSix));
  EXPECT_CONTAINS(parse_error(b), "Fortran");
}

TEST(Npy, RejectsTruncatedData) {
  Bytes b = small_f8();
  b.pop_back();
  EXPECT_CONTAINS(parse_error(b), "truncated");
}

TEST(Npy, RejectsTrailingBytes) {
  Bytes b = small_f8();
  b.push_back(0);
  EXPECT_CONTAINS(parse_error(b), "data size");
}

TEST(Npy, RejectsAbsurdShapes) {
  for (const char* shape : {"(100000000, 100000000)", "(16777217,)", "(99999999999999999999999999,)", "(4096, 4096, 2)",
                            "(18446744073709551616,)"}) {
    SCOPED_TRACE(shape);
    const Bytes b = npy_file(1, 0, dict("<f8", "False", shape), f8_le(kSix));
    EXPECT_CONTAINS(parse_error(b), "absurdly large");
  }
}

TEST(Npy, RejectsMoreThanFourDims) {
  const Bytes b = npy_file(1, 0, dict("<f8", "False", "(1, 1, 1, 1, 6)"), f8_le(kSix));
  EXPECT_CONTAINS(parse_error(b), "dimensions");
}

TEST(Npy, RejectsZeroDims) {
  const Bytes b = npy_file(1, 0, dict("<f8", "False", "()"), f8_le({1.0}));
  EXPECT_CONTAINS(parse_error(b), "0-dimensional");
}

TEST(Npy, RejectsBadMagic) {
  Bytes b = small_f8();
  b[1] = 'n';
  EXPECT_CONTAINS(parse_error(b), "magic");
  const Bytes short_file = {0x93, 'N', 'U'};
  EXPECT_CONTAINS(parse_error(short_file), "magic");
}

TEST(Npy, RejectsUnsupportedVersions) {
  EXPECT_CONTAINS(parse_error(npy_file(4, 0, dict("<f8", "False", "(6,)"), f8_le(kSix))), "version");
  EXPECT_CONTAINS(parse_error(npy_file(0, 0, dict("<f8", "False", "(6,)"), f8_le(kSix))), "version");
  EXPECT_CONTAINS(parse_error(npy_file(1, 1, dict("<f8", "False", "(6,)"), f8_le(kSix))), "version");
}

TEST(Npy, RejectsMalformedHeaders) {
  struct Case {
    const char* dict;
    const char* needle;
  };
  const Case cases[] = {
      {"{'descr': '<f8', 'fortran_order': False}", "lacks"},
      {"{'descr': '<f8', 'fortran_order': False, 'shape': (6,), 'extra': 1}", "unknown key"},
      {"{'descr': '<f8', 'descr': '<f8', 'fortran_order': False, 'shape': (6,)}", "repeats"},
      {"{'descr': '<f8', 'fortran_order': 0, 'shape': (6,)}", "True or False"},
      {"{'descr': '<f8', 'fortran_order': False, 'shape': (-6,)}", "non-negative"},
      {"{'descr': '<f8', 'fortran_order': False, 'shape': (6,)} x", "trailing"},
      {"{'descr': '<f8, 'fortran_order': False, 'shape': (6,)}", "header"},
      {"['descr', '<f8']", "expected '{'"},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.dict);
    EXPECT_CONTAINS(parse_error(npy_file(1, 0, c.dict, f8_le(kSix))), c.needle);
  }
}

TEST(Npy, RejectsHeaderLengthPastEnd) {
  Bytes b = small_f8();
  b[8] = 0xff;  // header length 0xff.. > file
  b[9] = 0xff;
  EXPECT_CONTAINS(parse_error(b), "truncated");
  Bytes v2 = npy_file(2, 0, dict("<f8", "False", "(6,)"), f8_le(kSix));
  v2[11] = 0x7f;  // header length ~2 GiB: over the header limit, refused before any read
  EXPECT_CONTAINS(parse_error(v2), "exceeds the limit");
}

TEST(Npy, RejectsNonTextHeader) {
  Bytes b = small_f8();
  b[12] = 0x01;  // inside the dict
  EXPECT_CONTAINS(parse_error(b), "non-text");
}

// Every proper prefix of a valid file is a truncated file: it must be
// refused with FormatError, never read out of bounds or accepted.
TEST(Npy, EveryTruncationIsAFormatError) {
  std::vector<Bytes> files = {small_f8(), npy_file(2, 0, dict("<f4", "False", "(3,)"), f4_le({1, 2, 3}))};
  for (const Bytes& full : files) {
    for (std::size_t n = 0; n < full.size(); ++n) {
      // A fresh heap copy of exactly n bytes, so ASan sees any read past its end.
      const Bytes cut(full.begin(), full.begin() + static_cast<std::ptrdiff_t>(n));
      EXPECT_THROW(parse_npy(cut.data(), cut.size()), FormatError) << "prefix of " << n << " bytes";
    }
  }
}

TEST(Npy, RealFileEveryTruncationIsAFormatError) {
  ASSERT_DB_PRESENT();
  const auto full = tofmat::read_npy_file(tofmat_test::db_dir() / "cork.npy");  // proves the file is valid
  std::ifstream in(tofmat_test::db_dir() / "cork.npy", std::ios::binary);
  const Bytes bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_EQ(bytes.size(), 3280u);
  for (std::size_t n = 0; n < bytes.size(); ++n) {
    const Bytes cut(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(n));
    EXPECT_THROW(parse_npy(cut.data(), cut.size()), FormatError) << "prefix of " << n << " bytes";
  }
}

// A damaged byte anywhere either still parses to a self-consistent array
// (e.g. a changed data value) or is a FormatError; nothing else may escape.
TEST(Npy, EveryByteFlipParsesOrIsAFormatError) {
  const Bytes full = small_f8();
  const std::size_t header_end = full.size() - kSix.size() * 8;
  for (std::size_t i = 0; i < full.size(); ++i) {
    for (int mask : {0x01, 0x20, 0x80, 0xff}) {
      Bytes b = full;
      b[i] = static_cast<std::uint8_t>(b[i] ^ mask);
      try {
        const auto a = parse_npy(b.data(), b.size());
        std::size_t n = 1;
        for (std::size_t d : a.shape) n *= d;
        EXPECT_EQ(a.data.size(), n) << "byte " << i;
        if (i >= header_end) {
          EXPECT_EQ(a.shape, (std::vector<std::size_t>{2, 3})) << "data byte " << i;
        }
      } catch (const FormatError&) {
        // refused: fine
      } catch (const std::exception& e) {
        ADD_FAILURE() << "byte " << i << " mask " << mask << ": non-format exception " << e.what();
      }
    }
  }
}

TEST(Npy, ReadFileErrors) {
  EXPECT_THROW(tofmat::read_npy_file("/nonexistent/dir/x.npy"), tofmat::IoError);
  tofmat_test::TempDir dir;
  EXPECT_THROW(tofmat::read_npy_file(dir.path()), tofmat::IoError);  // a directory, not a file
  const auto path = dir.path() / "bad.npy";
  std::ofstream(path, std::ios::binary) << "not an npy file";
  const std::string msg = error_of<FormatError>([&] { tofmat::read_npy_file(path); });
  EXPECT_CONTAINS(msg, path.string());  // the message names the file
  EXPECT_CONTAINS(msg, "magic");
}

}  // namespace
