// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The exemplar table (construction, loading the real database) and its
// compact .tmx file: exact layout, quantisation error bound, every way a
// damaged file can look, and atomic saving.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>

#include "test_util.hpp"
#include "tofmat/core/confidence.hpp"
#include "tofmat/core/error.hpp"
#include "tofmat/core/exemplar_table.hpp"
#include "tofmat/core/session_classifier.hpp"
#include "tofmat/core/table_file.hpp"

namespace {

using tofmat::BinSpec;
using tofmat::ExemplarTable;
using tofmat::FormatError;
using tofmat::IoError;
using tofmat::RowSpec;
using tofmat_test::Bytes;
using tofmat_test::error_of;
using tofmat_test::put_le;

const float kNaN = std::numeric_limits<float>::quiet_NaN();

// Independent CRC-32 (IEEE, reflected, as zlib computes it): the test's own
// oracle for the checksum field.
std::uint32_t crc32_ieee(const std::uint8_t* p, std::size_t n) {
  std::uint32_t c = 0xffffffffu;
  for (std::size_t i = 0; i < n; ++i) {
    c ^= p[i];
    for (int k = 0; k < 8; ++k) c = (c >> 1) ^ (0xedb88320u & (0u - (c & 1u)));
  }
  return ~c;
}

// A table file written field by field, to build files the encoder never would.
struct RawTable {
  std::uint16_t major = 1, minor = 0;
  std::uint32_t n_materials = 1, n_rows = 1, n_bins = 2;
  double start = 600.0, width = 3.0, step = 0.5;
  std::vector<std::pair<std::uint16_t, std::uint16_t>> rows = {{16, 120}};
  std::vector<std::string> names = {"a"};
  std::vector<std::int16_t> q = {1, -2};
  std::vector<float> noise;  // 1.1's block: written when minor >= 1

  Bytes bytes() const {
    Bytes b = {'T', 'O', 'F', 'M', 'A', 'T', 'B', 'L'};
    put_le(b, major, 2);
    put_le(b, minor, 2);
    put_le(b, n_materials, 4);
    put_le(b, n_rows, 4);
    put_le(b, n_bins, 4);
    for (double d : {start, width, step}) {
      std::uint64_t bits;
      std::memcpy(&bits, &d, 8);
      put_le(b, bits, 8);
    }
    for (const auto& r : rows) {
      put_le(b, r.first, 2);
      put_le(b, r.second, 2);
    }
    for (const auto& n : names) {
      b.push_back(static_cast<std::uint8_t>(n.size()));
      b.insert(b.end(), n.begin(), n.end());
    }
    for (std::int16_t v : q) put_le(b, static_cast<std::uint16_t>(v), 2);
    for (float v : noise) {
      std::uint32_t bits;
      std::memcpy(&bits, &v, 4);
      put_le(b, bits, 4);
    }
    put_le(b, crc32_ieee(b.data(), b.size()), 4);
    return b;
  }
};

ExemplarTable decode(const Bytes& b) { return tofmat::decode_table(b.data(), b.size()); }
std::string decode_error(const Bytes& b) {
  return error_of<FormatError>([&] { decode(b); });
}

// 3 materials x 2 rows x 5 bins, with missing elements and one all-missing bin.
ExemplarTable synthetic() {
  std::vector<float> v = {
      1.25f, -3.5f, kNaN, 100.37f,  0.001f,  // alpha row 0
      2.0f,  kNaN,  kNaN, -99.99f,  7.77f,   // alpha row 1
      0.0f,  0.5f,  kNaN, 12.3456f, -0.3f,   // beta row 0
      -1.0f, 1.0f,  kNaN, 3.14159f, 2.71f,   // beta row 1
      kNaN,  kNaN,  kNaN, kNaN,     42.0f,   // gamma row 0: nearly all missing
      kNaN,  kNaN,  kNaN, kNaN,     -42.0f,  // gamma row 1
  };
  return ExemplarTable({"alpha", "beta", "gamma"}, tofmat::kinect2_database_rows(), BinSpec{600.0, 3.0, 5},
                       std::move(v));
}

bool is_power_of_two(double x) {
  int e = 0;
  return x > 0.0 && std::frexp(x, &e) == 0.5;
}

// Decoded values lie within half a quantisation step of the originals, and
// exactly the same elements are missing.
void expect_round_trip(const ExemplarTable& a, const ExemplarTable& b) {
  EXPECT_EQ(b.materials(), a.materials());
  EXPECT_EQ(b.rows(), a.rows());
  EXPECT_EQ(b.bins(), a.bins());
  const double step = b.quant_step_mm();
  EXPECT_TRUE(is_power_of_two(step)) << step;
  EXPECT_EQ(step, tofmat::choose_quant_step_mm(a));
  ASSERT_EQ(b.values().size(), a.values().size());
  // The noise is stored as float32: exactly, NaN (not measured) where it was.
  ASSERT_EQ(b.noise_mm().size(), a.noise_mm().size());
  for (std::size_t i = 0; i < a.noise_mm().size(); ++i) {
    const float x = a.noise_mm()[i], y = b.noise_mm()[i];
    if (std::isnan(x)) {
      EXPECT_TRUE(std::isnan(y)) << "noise " << i;
    } else {
      EXPECT_EQ(x, y) << "noise " << i;
    }
  }
  for (std::size_t i = 0; i < a.values().size(); ++i) {
    const float x = a.values()[i], y = b.values()[i];
    ASSERT_EQ(std::isnan(x), std::isnan(y)) << "element " << i;
    if (!std::isnan(x)) {
      ASSERT_LE(std::fabs(double{x} - double{y}), step / 2) << "element " << i;
    }
  }
}

// ---- ExemplarTable itself ----------------------------------------------------

TEST(ExemplarTable, RejectsInconsistentContent) {
  const auto rows = tofmat::kinect2_database_rows();
  const BinSpec bins{0.0, 1.0, 2};
  auto make = [&](std::vector<std::string> names, std::vector<float> v) {
    return ExemplarTable(std::move(names), rows, bins, std::move(v));
  };
  EXPECT_NO_THROW(make({"a"}, {1, 2, 3, 4}));
  EXPECT_THROW(make({}, {}), std::invalid_argument);
  EXPECT_THROW(make({"a"}, {1, 2, 3}), std::invalid_argument);                      // wrong size
  EXPECT_THROW(make({"a", "a"}, {1, 2, 3, 4, 1, 2, 3, 4}), std::invalid_argument);  // duplicate
  EXPECT_THROW(make({"a b"}, {1, 2, 3, 4}), std::invalid_argument);                 // space
  EXPECT_THROW(make({std::string(65, 'x')}, {1, 2, 3, 4}), std::invalid_argument);  // too long
  EXPECT_THROW(make({"a"}, {1, std::numeric_limits<float>::infinity(), 3, 4}), std::invalid_argument);
  EXPECT_THROW(ExemplarTable({"a"}, {}, bins, {}), std::invalid_argument);  // no rows
  EXPECT_THROW(ExemplarTable({"a"}, rows, BinSpec{0.0, 0.0, 2}, {1, 2, 3, 4}), std::invalid_argument);
  EXPECT_THROW(ExemplarTable({"a"}, rows, bins, {1, 2, 3, 4}, -1.0), std::invalid_argument);
}

TEST(ExemplarTable, FromRealDatabase) {
  ASSERT_DB_PRESENT();
  const auto t = ExemplarTable::from_npy_dir(tofmat_test::db_dir(), 600.0, 1200.0);
  ASSERT_EQ(t.n_materials(), 29u);
  EXPECT_EQ(t.n_rows(), 2u);
  EXPECT_EQ(t.n_bins(), 200u);
  EXPECT_EQ(t.rows(), tofmat::kinect2_database_rows());
  EXPECT_EQ(t.bins(), BinSpec::linspace(600.0, 1200.0, 200));
  EXPECT_EQ(t.quant_step_mm(), 0.0);  // never quantised
  EXPECT_TRUE(std::is_sorted(t.materials().begin(), t.materials().end()));
  EXPECT_EQ(t.materials().front(), "acryl");
  // The all-0.0 "no observation" bins (see the database README) become NaN.
  EXPECT_EQ(t.valid_count(static_cast<std::size_t>(t.index_of("paper"))), 400u - 2 * 6);
  EXPECT_EQ(t.valid_count(static_cast<std::size_t>(t.index_of("plaster"))), 400u - 2 * 2);
  EXPECT_EQ(t.valid_count(static_cast<std::size_t>(t.index_of("fakeapple"))), 400u - 2 * 1);
  EXPECT_EQ(t.valid_count(static_cast<std::size_t>(t.index_of("acryl"))), 400u);
  EXPECT_TRUE(std::isnan(t.material_values(static_cast<std::size_t>(t.index_of("paper")))[0]));
  EXPECT_EQ(t.index_of("nonexistent"), -1);
}

// Writes <name>.npy holding a (rows, bins) '<f8' array.
void write_npy(const std::filesystem::path& dir, const std::string& name, const std::string& shape,
               const std::vector<double>& v) {
  const Bytes b = tofmat_test::npy_file(1, 0, "{'descr': '<f8', 'fortran_order': False, 'shape': " + shape + ", }",
                                        tofmat_test::f8_le(v));
  std::ofstream(dir / (name + ".npy"), std::ios::binary)
      .write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
}

TEST(ExemplarTable, FromNpyDirMissingMeansBothRowsZero) {
  tofmat_test::TempDir dir;
  // bin 0: both rows 0.0 -> missing; bin 1: only row 0 is 0.0 -> a real 0.0; bin 2: ordinary.
  write_npy(dir.path(), "b", "(2, 3)", {0.0, 0.0, 1.5, 0.0, 2.0, -2.5});
  write_npy(dir.path(), "a", "(2, 3)", {1, 2, 3, 4, 5, 6});
  std::ofstream(dir.path() / "notes.txt") << "ignored";
  const auto t = ExemplarTable::from_npy_dir(dir.path(), 0.0, 20.0);
  EXPECT_EQ(t.materials(), (std::vector<std::string>{"a", "b"}));  // sorted by name
  EXPECT_EQ(t.bins(), (BinSpec{0.0, 10.0, 3}));
  const float* b = t.material_values(1);
  EXPECT_TRUE(std::isnan(b[0]));
  EXPECT_TRUE(std::isnan(b[3]));
  EXPECT_EQ(b[1], 0.0f);
  EXPECT_EQ(b[4], 2.0f);
  EXPECT_EQ(b[5], -2.5f);
  EXPECT_EQ(t.rows(), tofmat::kinect2_database_rows());  // two rows: the Kinect v2 default
}

TEST(ExemplarTable, FromNpyDirErrors) {
  tofmat_test::TempDir dir;
  EXPECT_THROW(ExemplarTable::from_npy_dir(dir.path() / "missing", 600, 1200), IoError);
  EXPECT_THROW(ExemplarTable::from_npy_dir(dir.path(), 600, 1200), IoError);  // no .npy files

  tofmat_test::TempDir mixed;
  write_npy(mixed.path(), "a", "(2, 3)", {1, 2, 3, 4, 5, 6});
  write_npy(mixed.path(), "b", "(3, 2)", {1, 2, 3, 4, 5, 6});
  EXPECT_CONTAINS(error_of<FormatError>([&] { ExemplarTable::from_npy_dir(mixed.path(), 0, 1); }), "differs");

  tofmat_test::TempDir flat;
  write_npy(flat.path(), "a", "(6,)", {1, 2, 3, 4, 5, 6});
  EXPECT_CONTAINS(error_of<FormatError>([&] { ExemplarTable::from_npy_dir(flat.path(), 0, 1); }), "2-D");

  tofmat_test::TempDir inf;
  write_npy(inf.path(), "a", "(2, 2)", {1, std::numeric_limits<double>::infinity(), 3, 4});
  EXPECT_CONTAINS(error_of<FormatError>([&] { ExemplarTable::from_npy_dir(inf.path(), 0, 1); }), "infinite");

  tofmat_test::TempDir rows;
  write_npy(rows.path(), "a", "(2, 2)", {1, 2, 3, 4});
  EXPECT_THROW(ExemplarTable::from_npy_dir(rows.path(), 0, 1, {{16, 120}}), std::invalid_argument);
}

// A finite float64 beyond the float32 range cannot be stored; it must be
// refused, never stored as Inf or converted with undefined behaviour.
TEST(ExemplarTable, FromNpyDirValueBeyondFloatRange) {
  tofmat_test::TempDir dir;
  write_npy(dir.path(), "a", "(2, 2)", {1, 1e300, 3, 4});
  EXPECT_CONTAINS(error_of<FormatError>([&] { ExemplarTable::from_npy_dir(dir.path(), 0, 1); }), "float32 range");
}

// ---- file format -------------------------------------------------------------

TEST(TableFile, EncoderWritesTheDocumentedLayout) {
  // max |v| = 1 -> smallest step with round(1/step) <= 32767 is 2^-14 (2^-15 gives 32768).
  const ExemplarTable t({"a"}, {{16, 120}}, BinSpec{600.0, 3.0, 2}, {0.5f, -1.0f});
  RawTable raw;
  raw.step = std::ldexp(1.0, -14);
  raw.q = {8192, -16384};
  EXPECT_EQ(tofmat::encode_table(t), raw.bytes());
}

// 3 x 2 noise values for synthetic(): one not measured.
ExemplarTable synthetic_with_noise() { return synthetic().with_noise({0.25f, 0.5f, 1.5f, kNaN, 0.125f, 3.0f}); }

// Four samples at 505, 515, 525 and 535 mm for each of the three materials; gamma has none.
tofmat::DepthDistortion synthetic_distortion() {
  return {BinSpec{500.0, 10.0, 4}, {10.0f, 20.0f, kNaN, -5.5f, -1.0f, -2.0f, -3.0f, -4.0f, kNaN, kNaN, kNaN, kNaN}};
}

TEST(TableFile, DistortionRoundTripsInVersion12WithOrWithoutNoise) {
  for (const auto& base : {synthetic(), synthetic_with_noise()}) {
    const auto t = base.with_distortion(synthetic_distortion());
    const auto b = tofmat::encode_table(t);
    EXPECT_EQ(b[10], 2);  // minor 2
    const auto back = decode(b);
    expect_round_trip(t, back);  // (noise absent stays absent: 1.2 writes NaN for it)
    ASSERT_TRUE(back.distortion());
    EXPECT_EQ(back.distortion()->grid, (BinSpec{500.0, 10.0, 4}));
    const auto& mm = back.distortion()->mm;
    ASSERT_EQ(mm.size(), 12u);
    for (std::size_t i = 0; i < mm.size(); ++i) {
      const float x = synthetic_distortion().mm[i];
      if (std::isnan(x)) {
        EXPECT_TRUE(std::isnan(mm[i])) << i;
      } else {
        EXPECT_EQ(mm[i], x) << i;
      }
    }
    // A table without a distortion is written as before.
    EXPECT_LT(tofmat::encode_table(base)[10], 2);
    EXPECT_FALSE(decode(tofmat::encode_table(base)).distortion());
  }
}

tofmat::TableCalibration synthetic_calibration() {
  tofmat::TableCalibration c;
  c.offset_sd_mm = {1.5, 0.5};
  c.drift1_sd_mm = 4.0;
  c.drift2_sd_mm = 2.0;
  c.noise_scale = 1.25;
  c.floor_mm = 0.4;
  c.huber_k = 3.0;
  c.iterations = 3;
  c.methods = {{"eq12", {{1, 6.0}, {10, 8.0}}, {}}, {"session", {{1, 0.5}, {100, 12.0}}, {{1, 1.1}, {100, 27.0}}}};
  return c;
}

// Format 1.3: the table's own calibration, with or without a distortion and
// noise; older content kept, a table without one written as before.
TEST(TableFile, CalibrationRoundTripsInVersion13) {
  for (const bool with_distortion : {false, true}) {
    for (const auto& base : {synthetic(), synthetic_with_noise()}) {
      SCOPED_TRACE(std::string(with_distortion ? "distortion, " : "") + (base.has_noise() ? "noise" : "no noise"));
      const auto d = with_distortion ? base.with_distortion(synthetic_distortion()) : base;
      const auto t = d.with_calibration(synthetic_calibration());
      const auto b = tofmat::encode_table(t);
      EXPECT_EQ(b[10], 3);
      const auto back = decode(b);
      expect_round_trip(t, back);
      EXPECT_EQ(back.distortion().has_value(), with_distortion);
      ASSERT_TRUE(back.calibration());
      const auto& c = *back.calibration();
      EXPECT_EQ(c.offset_sd_mm, (std::vector<double>{1.5, 0.5}));
      EXPECT_EQ(c.drift1_sd_mm, 4.0);
      EXPECT_EQ(c.floor_mm, 0.4);
      EXPECT_EQ(c.iterations, 3u);
      ASSERT_EQ(c.methods.size(), 2u);
      ASSERT_NE(c.method("session"), nullptr);
      EXPECT_EQ(c.method("session")->unknown_fits, (std::vector<std::pair<double, double>>{{1, 1.1}, {100, 27.0}}));
      EXPECT_EQ(c.method("onnx"), nullptr);
      // Editing the table keeps it.
      EXPECT_TRUE(back.with_noise({}).calibration());
      EXPECT_TRUE(back.with_distortion(std::nullopt).calibration());
      EXPECT_FALSE(back.with_calibration(std::nullopt).calibration());
      EXPECT_LT(tofmat::encode_table(d)[10], 3);
      // Every truncation of it is a format error, never a crash.
      for (std::size_t n = 0; n < b.size(); ++n) EXPECT_THROW(tofmat::decode_table(b.data(), n), tofmat::FormatError);
    }
  }
}

TEST(TableFile, TheTablesCalibrationIsWhatTheMatchersUse) {
  const auto t = synthetic().with_calibration(synthetic_calibration());
  const auto eq12 = tofmat::Calibration::tuned("eq12", t);
  EXPECT_EQ(eq12.temperatures, (std::vector<std::pair<double, double>>{{1, 6.0}, {10, 8.0}}));
  EXPECT_EQ(tofmat::SessionPrior::tuned(t).offset_sd_mm, (std::vector<double>{1.5, 0.5}));
  EXPECT_EQ(tofmat::SessionPrior::tuned(t).noise_scale, 1.25);
  // Without one (or without the method), the built-in tuned settings.
  EXPECT_EQ(tofmat::Calibration::tuned("eq12", synthetic()).temperatures,
            tofmat::Calibration::tuned("eq12").temperatures);
  auto only_session = synthetic_calibration();
  only_session.methods.erase(only_session.methods.begin());
  EXPECT_EQ(tofmat::Calibration::tuned("eq12", synthetic().with_calibration(only_session)).temperatures,
            tofmat::Calibration::tuned("eq12").temperatures);
}

TEST(TableFile, RejectsBadCalibrations) {
  const auto bad = [](const std::function<void(tofmat::TableCalibration&)>& edit) {
    auto c = synthetic_calibration();
    edit(c);
    return c;
  };
  const tofmat::TableCalibration cases[] = {
      bad([](auto& c) { c.offset_sd_mm = {1.0}; }),
      bad([](auto& c) { c.offset_sd_mm[0] = -1.0; }),
      bad([](auto& c) { c.drift1_sd_mm = NAN; }),
      bad([](auto& c) { c.noise_scale = 0.0, c.floor_mm = 0.0; }),
      bad([](auto& c) { c.huber_k = 0.0; }),
      bad([](auto& c) { c.iterations = 0; }),
      bad([](auto& c) { c.methods[0].method = "onnx"; }),
      bad([](auto& c) { c.methods[1].method = "eq12"; }),
      bad([](auto& c) { c.methods[0].temperatures = {}; }),
      bad([](auto& c) {
        c.methods[0].temperatures = {{10, 1.0}, {1, 1.0}};
      }),
      bad([](auto& c) {
        c.methods[0].temperatures = {{1, -1.0}};
      }),
      bad([](auto& c) {
        c.methods[0].temperatures.assign(65, {1, 1.0});
      }),
  };
  for (const auto& c : cases) EXPECT_THROW(synthetic().with_calibration(c), std::invalid_argument);
  // Behind a valid checksum, the same is a format error naming the content.
  auto good = tofmat::encode_table(synthetic().with_calibration(synthetic_calibration()));
  // The last method's last knot's value (before the CRC): a NaN threshold is refused.
  const double nan = NAN;
  std::memcpy(good.data() + good.size() - 4 - 8, &nan, 8);
  const std::uint32_t crc = crc32_ieee(good.data(), good.size() - 4);
  std::memcpy(good.data() + good.size() - 4, &crc, 4);
  EXPECT_CONTAINS(decode_error(good), "inconsistent content");
}

TEST(ExemplarTable, DistortionIsInterpolatedBetweenItsSamples) {
  const auto t = synthetic().with_distortion(synthetic_distortion());
  EXPECT_DOUBLE_EQ(t.distortion_mm(0, 505.0), 10.0);  // a sample
  EXPECT_DOUBLE_EQ(t.distortion_mm(0, 510.0), 15.0);  // half way
  EXPECT_DOUBLE_EQ(t.distortion_mm(1, 532.5), -3.75);
  EXPECT_DOUBLE_EQ(t.distortion_mm(1, 535.0), -4.0);   // the last sample
  EXPECT_TRUE(std::isnan(t.distortion_mm(0, 520.0)));  // next to an unknown sample
  EXPECT_TRUE(std::isnan(t.distortion_mm(0, 504.9)));  // outside the samples
  EXPECT_TRUE(std::isnan(t.distortion_mm(1, 535.1)));
  EXPECT_TRUE(std::isnan(t.distortion_mm(2, 515.0)));  // a material without one
  EXPECT_TRUE(std::isnan(t.distortion_mm(3, 515.0)));  // no such material
  EXPECT_TRUE(std::isnan(t.distortion_mm(0, NAN)));
  EXPECT_TRUE(std::isnan(synthetic().distortion_mm(0, 515.0)));  // no distortion at all
  EXPECT_FALSE(t.with_distortion(std::nullopt).distortion());
  EXPECT_TRUE(t.with_noise({0.25f, 0.5f, 1.5f, kNaN, 0.125f, 3.0f}).distortion());  // kept
}

TEST(ExemplarTable, RejectsDistortionsOfTheWrongShapeOrValue) {
  const auto t = synthetic();
  auto d = synthetic_distortion();
  d.mm.pop_back();
  EXPECT_CONTAINS(error_of<std::invalid_argument>([&] { t.with_distortion(d); }), "holds 11 values");
  for (float bad : {std::numeric_limits<float>::infinity(), 10001.0f}) {
    d = synthetic_distortion();
    d.mm[3] = bad;
    EXPECT_CONTAINS(error_of<std::invalid_argument>([&] { t.with_distortion(d); }), "distortion");
  }
  d = synthetic_distortion();
  d.grid.width_mm = 0.0;
  EXPECT_THROW(t.with_distortion(d), std::invalid_argument);
  // In a file: the grid's count, and a value behind a valid checksum.
  auto b = tofmat::encode_table(t.with_distortion(synthetic_distortion()));
  const std::size_t grid = b.size() - 4 - 12 * 4 - 20;
  Bytes zero_count = b;
  for (int i = 0; i < 4; ++i) zero_count[grid + 16 + static_cast<std::size_t>(i)] = 0;
  EXPECT_CONTAINS(decode_error(zero_count), "distortion grid count 0");
  Bytes huge = b;
  const float v = 1e6f;
  std::memcpy(huge.data() + grid + 20, &v, 4);
  const std::uint32_t crc = crc32_ieee(huge.data(), huge.size() - 4);
  std::memcpy(huge.data() + huge.size() - 4, &crc, 4);
  EXPECT_CONTAINS(decode_error(huge), "distortion");
}

TEST(TableFile, ATableWithoutNoiseIsWrittenAsVersion10) {
  // Readers older than 1.1 still load every table that carries no noise.
  const auto b = tofmat::encode_table(synthetic());
  EXPECT_EQ(b[10], 0);
  EXPECT_EQ(b[11], 0);
  EXPECT_TRUE(decode(b).noise_mm().empty());
}

TEST(TableFile, NoiseRoundTripsInVersion11) {
  const auto t = synthetic_with_noise();
  const auto b = tofmat::encode_table(t);
  EXPECT_EQ(b[10], 1);  // minor 1
  // Exactly 6 float32 more than the same table without noise.
  EXPECT_EQ(b.size(), tofmat::encode_table(synthetic()).size() + 6 * 4);
  expect_round_trip(t, decode(b));
}

TEST(TableFile, DecodesHandWrittenVersion11) {
  RawTable raw;
  raw.minor = 1;
  raw.noise = {0.75f};
  const auto t = decode(raw.bytes());
  ASSERT_EQ(t.noise_mm().size(), 1u);
  EXPECT_EQ(t.noise_mm()[0], 0.75f);
  EXPECT_EQ(t.values()[0], 0.5f);
}

TEST(TableFile, RejectsBadNoiseBlocks) {
  RawTable missing;  // 1.1 without its block
  missing.minor = 1;
  EXPECT_CONTAINS(decode_error(missing.bytes()), "truncated");
  RawTable extra;  // 1.0 with a block it must not have
  extra.noise = {0.5f};
  EXPECT_CONTAINS(decode_error(extra.bytes()), "trailing");
  for (float bad : {0.0f, -1.0f, std::numeric_limits<float>::infinity()}) {
    SCOPED_TRACE(bad);
    RawTable r;
    r.minor = 1;
    r.noise = {bad};
    EXPECT_CONTAINS(decode_error(r.bytes()), "noise");
  }
}

TEST(ExemplarTable, RejectsNoiseOfTheWrongShapeOrValue) {
  const auto t = synthetic();
  EXPECT_CONTAINS(error_of<std::invalid_argument>([&] { t.with_noise({1.0f}); }), "noise holds 1 values");
  EXPECT_CONTAINS(error_of<std::invalid_argument>([&] { t.with_noise(std::vector<float>(6, -0.5f)); }), "noise");
  EXPECT_TRUE(t.with_noise({}).noise_mm().empty());
  EXPECT_EQ(synthetic_with_noise().with_noise({}).values().size(), t.values().size());
}

TEST(TableFile, DecodesHandWrittenFile) {
  RawTable raw;
  raw.q = {5, tofmat::kTableMissing};
  const auto t = decode(raw.bytes());
  EXPECT_EQ(t.materials(), std::vector<std::string>{"a"});
  EXPECT_EQ(t.rows(), (std::vector<RowSpec>{{16, 120}}));
  EXPECT_EQ(t.bins(), (BinSpec{600.0, 3.0, 2}));
  EXPECT_EQ(t.quant_step_mm(), 0.5);
  EXPECT_EQ(t.values()[0], 2.5f);
  EXPECT_TRUE(std::isnan(t.values()[1]));
}

TEST(TableFile, SyntheticRoundTripWithinHalfAStep) {
  const auto t = synthetic();
  const auto bytes = tofmat::encode_table(t);
  expect_round_trip(t, decode(bytes));
  // The step is the smallest power of two that still fits: half of it would overflow int16.
  const double step = tofmat::choose_quant_step_mm(t);
  EXPECT_GT(std::nearbyint(100.37 / (step / 2)), 32767.0);
}

TEST(TableFile, ExtremeMagnitudesRoundTrip) {
  for (float big : {1e-30f, 1.0f, 32767.0f, 1e30f, 1e38f}) {
    SCOPED_TRACE(big);
    const ExemplarTable t({"m"}, {{0, 0}}, BinSpec{0.0, 1.0, 3}, {big, -big, big / 3});
    expect_round_trip(t, decode(tofmat::encode_table(t)));
  }
  const ExemplarTable all_missing({"m"}, {{0, 0}}, BinSpec{0.0, 1.0, 2}, {kNaN, kNaN});
  expect_round_trip(all_missing, decode(tofmat::encode_table(all_missing)));
}

// Any table the constructor accepts must survive encode/decode, including
// finite values next to FLT_MAX: rounding to the nearest step must not push
// a value past the float range (decode would then see Inf).
TEST(TableFile, FloatMaxRoundTrip) {
  const float big = std::numeric_limits<float>::max();
  const ExemplarTable t({"m"}, {{0, 0}}, BinSpec{0.0, 1.0, 2}, {big, -big});
  const auto bytes = tofmat::encode_table(t);
  try {
    expect_round_trip(t, decode(bytes));
  } catch (const FormatError& e) {
    ADD_FAILURE() << "encode_table wrote a file decode_table refuses (step " << tofmat::choose_quant_step_mm(t)
                  << " mm, FLT_MAX / step = " << double{big} / tofmat::choose_quant_step_mm(t) << "): " << e.what();
  }
}

TEST(TableFile, RealDatabaseRoundTripWithinHalfAStep) {
  ASSERT_DB_PRESENT();
  const auto t = ExemplarTable::from_npy_dir(tofmat_test::db_dir(), 600.0, 1200.0);
  const auto bytes = tofmat::encode_table(t);
  const auto back = decode(bytes);
  expect_round_trip(t, back);
  // Values reach 162 mm (fakeleather): 2^-7 mm is the finest step that fits int16.
  EXPECT_EQ(back.quant_step_mm(), std::ldexp(1.0, -7));
}

TEST(TableFile, ChecksumFieldIsCrc32OfEverythingBefore) {
  const auto b = tofmat::encode_table(synthetic());
  std::uint32_t stored = 0;
  for (int i = 3; i >= 0; --i) stored = (stored << 8) | b[b.size() - 4 + static_cast<std::size_t>(i)];
  EXPECT_EQ(stored, crc32_ieee(b.data(), b.size() - 4));
}

TEST(TableFile, EveryTruncationIsAFormatError) {
  for (const auto& full : {tofmat::encode_table(synthetic()), tofmat::encode_table(synthetic_with_noise()),
                           tofmat::encode_table(synthetic().with_distortion(synthetic_distortion()))}) {
    for (std::size_t n = 0; n < full.size(); ++n) {
      const Bytes cut(full.begin(), full.begin() + static_cast<std::ptrdiff_t>(n));  // exact-size heap copy for ASan
      EXPECT_THROW(decode(cut), FormatError) << "prefix of " << n << " bytes";
    }
  }
}

// CRC-32 detects every single-byte error, so no damaged file may decode; the
// message must point at the first field that gave the damage away.
TEST(TableFile, EveryByteFlipIsAFormatError) {
  for (const auto& full : {tofmat::encode_table(synthetic()), tofmat::encode_table(synthetic_with_noise()),
                           tofmat::encode_table(synthetic_with_noise().with_distortion(synthetic_distortion())),
                           tofmat::encode_table(synthetic().with_calibration(synthetic_calibration()))}) {
    for (std::size_t i = 0; i < full.size(); ++i) {
      for (int mask : {0x01, 0x80, 0xff}) {
        Bytes b = full;
        b[i] = static_cast<std::uint8_t>(b[i] ^ mask);
        const std::string msg = decode_error(b);
        SCOPED_TRACE("byte " + std::to_string(i) + " mask " + std::to_string(mask) + ": " + msg);
        if (i < 8) {
          EXPECT_CONTAINS(msg, "magic");
        } else if (i == 10 && mask == 0x01 && full[10] < 2) {
          // 1.0 <-> 1.1, both known: the noise block is then missing or left over.
          const bool sized = msg.find("truncated") != std::string::npos || msg.find("trailing") != std::string::npos;
          EXPECT_TRUE(sized) << "a changed minor version not caught by the file's size";
        } else if (i == 10 && mask == 0x01) {
          // 1.2 <-> 1.3, both known: a calibration read from the distortion's checksum, or left over, or
          // 1.3's empty distortion grid read as 1.2's.
          const bool sized = msg.find("calibration") != std::string::npos ||
                             msg.find("trailing") != std::string::npos || msg.find("truncated") != std::string::npos ||
                             msg.find("grid count 0") != std::string::npos;
          EXPECT_TRUE(sized) << "a changed minor version not caught by the file's size";
        } else if (i < 12) {
          EXPECT_CONTAINS(msg, "version");  // major and minor: only 1.0 to 1.3 are read (docs/table-format.md)
        } else {
          const bool named = msg.find("checksum") != std::string::npos || msg.find("count") != std::string::npos ||
                             msg.find("truncated") != std::string::npos || msg.find("trailing") != std::string::npos ||
                             msg.find("name length") != std::string::npos || msg.find("limit") != std::string::npos ||
                             msg.find("quantisation step") != std::string::npos ||
                             msg.find("calibration") != std::string::npos;
          EXPECT_TRUE(named) << "payload damage reported without naming checksum or a dimension";
        }
      }
    }
  }
}

TEST(TableFile, RejectsOtherVersions) {
  // A reader reads only the versions it knows: 1.0 to 1.3 (docs/table-format.md).
  const std::pair<int, int> versions[] = {{0, 0}, {2, 0}, {0xffff, 0}, {1, 4}, {1, 7}, {1, 0xffff}};
  for (const auto& [major, minor] : versions) {
    SCOPED_TRACE(std::to_string(major) + "." + std::to_string(minor));
    RawTable raw;
    raw.major = static_cast<std::uint16_t>(major);
    raw.minor = static_cast<std::uint16_t>(minor);
    EXPECT_CONTAINS(decode_error(raw.bytes()), "version");
  }
}

TEST(TableFile, RejectsDimensionsOverLimits) {
  struct Case {
    std::uint32_t m, r, b;
    const char* needle;
  };
  const Case cases[] = {
      {0, 1, 2, "material count"},
      {256, 1, 2, "material count"},
      {0xffffffffu, 1, 2, "material count"},
      {1, 0, 2, "row count"},
      {1, 17, 2, "row count"},
      {1, 1, 0, "bin count"},
      {1, 1, 65536, "bin count"},
      {255, 16, 65535, "file size limit"},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.needle);
    RawTable raw;
    raw.n_materials = c.m;
    raw.n_rows = c.r;
    raw.n_bins = c.b;
    EXPECT_CONTAINS(decode_error(raw.bytes()), c.needle);
  }
}

TEST(TableFile, RejectsOversizedInputBeforeParsing) {
  Bytes huge(tofmat::kTableMaxFileBytes + 1, 0);
  EXPECT_CONTAINS(decode_error(huge), "limit");
}

TEST(TableFile, RejectsTrailingBytes) {
  Bytes b = tofmat::encode_table(synthetic());
  b.push_back(0);
  EXPECT_CONTAINS(decode_error(b), "trailing");
}

TEST(TableFile, RejectsBadContentBehindAValidChecksum) {
  struct Case {
    RawTable raw;
    const char* needle;
  };
  std::vector<Case> cases;
  auto add = [&](const char* needle, auto&& edit) {
    RawTable r;
    edit(r);
    cases.push_back({r, needle});
  };
  add("quantisation step", [](RawTable& r) { r.step = 0.0; });
  add("quantisation step", [](RawTable& r) { r.step = std::numeric_limits<double>::quiet_NaN(); });
  add("quantisation step", [](RawTable& r) { r.step = -0.5; });
  add("inconsistent", [](RawTable& r) { r.width = 0.0; });
  add("inconsistent", [](RawTable& r) { r.start = std::numeric_limits<double>::infinity(); });
  add("inconsistent", [](RawTable& r) { r.names = {"a b"}; });
  add("inconsistent", [](RawTable& r) {
    r.n_materials = 2;
    r.names = {"a", "a"};
    r.q = {1, 2, 3, 4};
  });
  add("exceeds the float range", [](RawTable& r) { r.step = 1e300; });  // q * step overflows float
  add("name length", [](RawTable& r) { r.names = {""}; });
  add("name length", [](RawTable& r) { r.names = {std::string(65, 'x')}; });
  for (const auto& c : cases) {
    SCOPED_TRACE(c.needle);
    EXPECT_CONTAINS(decode_error(c.raw.bytes()), c.needle);
  }
}

// ---- saving and loading ------------------------------------------------------

Bytes file_bytes(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return Bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

TEST(TableFile, SaveLoadAndReplace) {
  tofmat_test::TempDir dir;
  const auto path = dir.path() / "db.tmx";
  const auto a = synthetic();
  tofmat::save_table(a, path);
  EXPECT_EQ(file_bytes(path), tofmat::encode_table(a));
  expect_round_trip(a, tofmat::load_table(path));

  const ExemplarTable b({"other"}, {{16, 120}}, BinSpec{0.0, 1.0, 2}, {1.0f, 2.0f});
  tofmat::save_table(b, path);  // over the existing file
  EXPECT_EQ(tofmat::load_table(path).materials(), std::vector<std::string>{"other"});
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"db.tmx"}) << "a temporary file was left behind";
}

TEST(TableFile, SaveIntoMissingDirectoryIsIoError) {
  tofmat_test::TempDir dir;
  const auto path = dir.path() / "no_such_dir" / "db.tmx";
  const std::string msg = error_of<IoError>([&] { tofmat::save_table(synthetic(), path); });
  EXPECT_CONTAINS(msg, "no_such_dir");
  EXPECT_TRUE(dir.entries().empty()) << "something was created beside the missing directory";
}

TEST(TableFile, SaveOverADirectoryFailsAndCleansUp) {
  tofmat_test::TempDir dir;
  const auto path = dir.path() / "occupied";
  std::filesystem::create_directory(path);
  std::ofstream(path / "keep") << "x";
  EXPECT_THROW(tofmat::save_table(synthetic(), path), IoError);  // rename onto a directory fails
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"occupied"}) << "temporary file left behind";
  EXPECT_TRUE(std::filesystem::exists(path / "keep"));
}

// A write that fails half way (here: the file size limit, which binds even
// root) must leave the previous file byte-for-byte intact and no temp file.
TEST(TableFile, FailedWriteKeepsTheOldFile) {
  tofmat_test::TempDir dir;
  const auto path = dir.path() / "db.tmx";
  const auto old_table = synthetic();
  tofmat::save_table(old_table, path);
  const Bytes before = file_bytes(path);

  std::vector<float> big(2 * 1000, 1.0f);  // ~4 KB file, over the 1 KB limit set below
  const ExemplarTable bigger({"big"}, tofmat::kinect2_database_rows(), BinSpec{0.0, 1.0, 1000}, big);

  rlimit old_limit{};
  ASSERT_EQ(::getrlimit(RLIMIT_FSIZE, &old_limit), 0);
  rlimit small = old_limit;
  small.rlim_cur = 1024;
  void (*old_handler)(int) = ::signal(SIGXFSZ, SIG_IGN);  // get EFBIG instead of being killed
  ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &small), 0);
  // Nothing may print while the limit is active (stdout could be a file).
  std::string caught;
  try {
    tofmat::save_table(bigger, path);
    caught = "none";
  } catch (const IoError& e) {
    caught = e.what();
  } catch (const std::exception& e) {
    caught = std::string("wrong type: ") + e.what();
  }
  ::setrlimit(RLIMIT_FSIZE, &old_limit);
  ::signal(SIGXFSZ, old_handler);

  EXPECT_CONTAINS(caught, "cannot write");
  EXPECT_EQ(file_bytes(path), before);
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"db.tmx"}) << "temporary file left behind";
  expect_round_trip(old_table, tofmat::load_table(path));
}

TEST(TableFile, LoadErrors) {
  tofmat_test::TempDir dir;
  EXPECT_THROW(tofmat::load_table(dir.path() / "missing.tmx"), IoError);
  EXPECT_THROW(tofmat::load_table(dir.path()), IoError);
  const auto path = dir.path() / "bad.tmx";
  Bytes b = tofmat::encode_table(synthetic());
  b[b.size() / 2] ^= 0x10;
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
  const std::string msg = error_of<FormatError>([&] { tofmat::load_table(path); });
  EXPECT_CONTAINS(msg, path.string());
  EXPECT_CONTAINS(msg, "checksum");
}

}  // namespace
