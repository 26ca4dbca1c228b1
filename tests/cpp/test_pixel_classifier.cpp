// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// PixelClassifier: the per-pixel Eq. (12) (m = 1) in integers. The scalar
// kernel against hand-worked cases and the float classifier; the vector
// kernel against the scalar one bit for bit; the real database's own values
// labelled as their material.
#include "tofmat/core/pixel_classifier.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <iostream>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "synthetic_raw.hpp"
#include "test_util.hpp"
#include "tofmat/core/classifier.hpp"
#include "tofmat/core/compact_table.hpp"
#include "tofmat/core/exemplar_table.hpp"

namespace {

using namespace tofmat;

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
const std::vector<RowSpec> kRows = {{16, 120}, {80, 120}};

// values[k][r][b]; NaN = missing. Step 2^-4 mm.
ExemplarTable make_table(const std::vector<std::vector<std::vector<float>>>& values, std::uint32_t bins) {
  std::vector<std::string> names;
  std::vector<float> flat;
  for (std::size_t k = 0; k < values.size(); ++k) {
    names.push_back("m" + std::to_string(k));
    for (const auto& row : values[k]) flat.insert(flat.end(), row.begin(), row.end());
  }
  return ExemplarTable(names, kRows, BinSpec{600.0, 3.0, bins}, flat, 0.0625);
}

// One pixel's label from its bin and its two features in mm.
std::uint8_t label_of(const PixelClassifier& pc, std::int32_t bin, double f0_mm, double f1_mm, FixedKernel k) {
  const std::int32_t f0 = static_cast<std::int32_t>(std::lround(f0_mm * 65536.0));
  const std::int32_t f1 = static_cast<std::int32_t>(std::lround(f1_mm * 65536.0));
  std::uint8_t label = 0;
  pc.classify(&bin, &f0, &f1, 1, &label, k);
  return label;
}

TEST(PixelClassifier, HandWorkedCases) {
  // bin 0: m0 (1, 1), m1 (3, 1), m2 only row 0 = 2; bin 1: m0 missing, m1 (0, 0), m2 missing;
  // bin 2: nobody.
  const ExemplarTable t = make_table(
      {{{1, kNaN, kNaN}, {1, kNaN, kNaN}}, {{3, 0, kNaN}, {1, 0, kNaN}}, {{2, kNaN, kNaN}, {kNaN, kNaN, kNaN}}}, 3);
  const CompactTable c(t);
  const PixelClassifier pc(c, t.bins());
  for (FixedKernel k : {FixedKernel::kScalar, FixedKernel::kBest}) {
    EXPECT_EQ(label_of(pc, 0, 1.1, 0.9, k), 0);
    EXPECT_EQ(label_of(pc, 0, 2.9, 1.2, k), 1);
    // (2, 1): m0 and m1 both a mean of 0.5 mm^2, m2's one element 0 -> m2.
    EXPECT_EQ(label_of(pc, 0, 2.0, 1.0, k), 2);
    // (1.5, 5): means m0 (0.25 + 16) / 2, m1 (2.25 + 16) / 2, m2 0.25 / 1: m2
    // (Eq. (12) is a mean over the valid elements, not a sum).
    EXPECT_EQ(label_of(pc, 0, 1.5, 5.0, k), 2);
    // (2.6, 0): m0 (2.56 + 1) / 2 = 1.78, m1 (0.16 + 1) / 2 = 0.58, m2 0.36: m2;
    // (3.0, 0): m1 0.5, m2 1.0: m1.
    EXPECT_EQ(label_of(pc, 0, 2.6, 0.0, k), 2);
    EXPECT_EQ(label_of(pc, 0, 3.0, 0.0, k), 1);
    EXPECT_EQ(label_of(pc, 1, 5.0, -3.0, k), 1);                               // the only candidate there
    EXPECT_EQ(label_of(pc, 2, 0.0, 0.0, k), PixelClassifier::kUnclassified);   // nobody has a value
    EXPECT_EQ(label_of(pc, -1, 1.0, 1.0, k), PixelClassifier::kUnclassified);  // no bin
  }
  // Ties go to the lower index: two identical candidates.
  const ExemplarTable twins = make_table({{{1}, {1}}, {{1}, {1}}}, 1);
  const CompactTable ct(twins);
  const PixelClassifier pt(ct, twins.bins());
  for (FixedKernel k : {FixedKernel::kScalar, FixedKernel::kBest}) EXPECT_EQ(label_of(pt, 0, 7.0, -7.0, k), 0);
}

TEST(PixelClassifier, RefusesTablesItCannotServe) {
  const ExemplarTable t = make_table({{{1}, {1}}}, 1);
  const CompactTable c(t);
  EXPECT_THROW(PixelClassifier(c, BinSpec{600.0, 3.0, 2}), std::invalid_argument);  // other bins
  const ExemplarTable one_row({"a"}, {{16, 120}}, BinSpec{600.0, 3.0, 1}, {1.0f}, 0.0625);
  EXPECT_THROW(PixelClassifier(CompactTable(one_row), one_row.bins()), std::invalid_argument);
  const ExemplarTable odd_step({"a"}, kRows, BinSpec{600.0, 3.0, 1}, {1.0f, 1.0f}, 0.1);
  EXPECT_THROW(PixelClassifier(CompactTable(odd_step), odd_step.bins()), std::invalid_argument);
}

TEST(PixelClassifier, AgreesWithTheFloatClassifierUpToTheQuantisation) {
  // Random tables of 1..40 candidates with missing elements (one row, both
  // rows); random features near the values. Where the labels differ, the
  // float distances of the two labels must lie within the quantisation's
  // reach (half a step per element of the query).
  std::mt19937 rng(12);
  std::normal_distribution<float> value(0.0f, 20.0f), noise(0.0f, 3.0f);
  std::size_t compared = 0, differ = 0;
  for (std::size_t K : {1u, 5u, 8u, 9u, 29u, 40u}) {
    const std::uint32_t bins = 16;
    std::vector<std::vector<std::vector<float>>> v(K, std::vector<std::vector<float>>(2, std::vector<float>(bins)));
    for (auto& m : v) {
      for (auto& row : m) {
        for (auto& x : row) x = std::round(value(rng) * 16.0f) / 16.0f;
      }
      for (std::uint32_t b = 0; b < bins; ++b) {
        const auto u = rng() % 10;
        if (u == 0) m[0][b] = kNaN;
        if (u == 1) m[1][b] = kNaN;
        if (u == 2) m[0][b] = m[1][b] = kNaN;
      }
    }
    auto table = std::make_shared<const ExemplarTable>(make_table(v, bins));
    const CompactTable c(*table);
    const PixelClassifier pc(c, table->bins());
    const FloatClassifier fc(table);
    for (int trial = 0; trial < 400; ++trial) {
      const auto b = static_cast<std::int32_t>(rng() % bins);
      const std::size_t src = rng() % K;
      const double f0 =
          (std::isnan(v[src][0][static_cast<std::size_t>(b)]) ? value(rng) : v[src][0][static_cast<std::size_t>(b)]) +
          noise(rng);
      const double f1 =
          (std::isnan(v[src][1][static_cast<std::size_t>(b)]) ? value(rng) : v[src][1][static_cast<std::size_t>(b)]) +
          noise(rng);
      const std::uint8_t label = label_of(pc, b, f0, f1, FixedKernel::kScalar);
      std::vector<float> q(table->elements_per_material(), kNaN);
      q[static_cast<std::size_t>(b)] = static_cast<float>(f0);
      q[bins + static_cast<std::size_t>(b)] = static_cast<float>(f1);
      bool anyone = false;
      for (const auto& m : v)
        anyone =
            anyone || !std::isnan(m[0][static_cast<std::size_t>(b)]) || !std::isnan(m[1][static_cast<std::size_t>(b)]);
      if (!anyone) {
        EXPECT_EQ(label, PixelClassifier::kUnclassified);
        continue;
      }
      ASSERT_NE(label, PixelClassifier::kUnclassified);
      const Classification r = fc.classify(q.data(), q.size());
      ++compared;
      if (r.best().index == label) continue;
      ++differ;
      double mine = 0.0;
      for (const auto& m : r.ranking) {
        if (m.index == label) mine = m.distance;
      }
      // Quantising each element by at most half a step (1/32 mm) moves a
      // mean squared distance by at most 2 (1/32) |d| + (1/32)^2 per element.
      const double reach = 2.0 * (2.0 * (1.0 / 32.0) * 60.0 + 1.0 / 1024.0);
      EXPECT_LE(mine - r.best().distance, reach) << "K " << K << " bin " << b;
    }
  }
  std::cout << "[ measured ] " << differ << " of " << compared
            << " labels differ from the float classifier (near ties)\n";
  EXPECT_LT(differ, compared / 50);
}

TEST(PixelClassifier, VectorKernelIsBitExactWithScalar) {
#if defined(__x86_64__)
  if (!cpu_has_avx2()) GTEST_SKIP() << "this CPU has no AVX2: kBest is the scalar kernel";
  const auto vector_quantise = quantise_features_avx2;
  const auto vector_classify = classify_pixels_avx2;
#elif defined(__aarch64__)
  const auto vector_quantise = quantise_features_neon;
  const auto vector_classify = classify_pixels_neon;
#endif
#if !defined(__x86_64__) && !defined(__aarch64__)
  GTEST_SKIP() << "no vector kernel on this architecture (kBest is the scalar one)";
#else
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> any16(-32768, 32767);
  for (std::size_t K : {1u, 7u, 8u, 9u, 16u, 24u, 29u, 32u, 33u, 64u, 200u, 254u}) {
    for (bool gaps : {false, true}) {
      const std::uint32_t bins = 5;
      // Values over the whole int16 range (step 1/16 mm: +-2048 mm).
      std::vector<std::vector<std::vector<float>>> v(K, std::vector<std::vector<float>>(2, std::vector<float>(bins)));
      for (auto& m : v) {
        for (auto& row : m) {
          for (auto& x : row) x = static_cast<float>(std::max(any16(rng), -32767)) / 16.0f;
          if (gaps) row[rng() % bins] = kNaN;
        }
      }
      const ExemplarTable t = make_table(v, bins);
      const CompactTable c(t);
      const PixelClassifier pc(c, t.bins());
      const std::size_t n = 3001;
      std::vector<std::int32_t> bin(n), f0(n), f1(n);
      const std::int32_t extremes[] = {INT32_MIN, INT32_MIN + 1, -(1 << 30) - 1, -32767 * 4096, 0,        2047,
                                       2048,      32767 * 4096,  (1 << 30) + 1,  INT32_MAX - 1, INT32_MAX};
      for (std::size_t i = 0; i < n; ++i) {
        bin[i] = rng() % 9 == 0 ? -1 : static_cast<std::int32_t>(rng() % bins);
        f0[i] = i % 5 == 0 ? extremes[rng() % 11] : any16(rng) * 4096 + static_cast<std::int32_t>(rng() % 4096);
        f1[i] = i % 7 == 0 ? extremes[rng() % 11] : any16(rng) * 4096 + static_cast<std::int32_t>(rng() % 4096);
      }
      std::vector<std::int32_t> qa(n), qb(n);
      quantise_features_scalar(f0.data(), f1.data(), n, pc.layout().shift, qa.data());
      vector_quantise(f0.data(), f1.data(), n, pc.layout().shift, qb.data());
      ASSERT_EQ(qa, qb) << K;
      std::vector<std::uint8_t> la(n), lb(n);
      const std::size_t na = classify_pixels_scalar(pc.layout(), bin.data(), qa.data(), n, la.data());
      const std::size_t nb = vector_classify(pc.layout(), bin.data(), qa.data(), n, lb.data());
      ASSERT_EQ(la, lb) << K << (gaps ? " with gaps" : "");
      ASSERT_EQ(na, nb);
      EXPECT_GT(na, n / 2);
    }
  }
#endif
}

TEST(PixelClassifier, RealDatabaseValuesAreLabelledAsTheirMaterial) {
  ASSERT_DB_PRESENT();
  const ExemplarTable t = ExemplarTable::from_npy_dir(tofmat_test::db_dir(), kDatabaseBinStartMm, kDatabaseBinStopMm);
  const CompactTable c(t);
  const PixelClassifier pc(c, t.bins());
  const std::size_t K = t.n_materials(), B = t.n_bins();
  std::vector<std::int32_t> bin, f0, f1;
  std::vector<std::size_t> truth;
  for (std::size_t k = 0; k < K; ++k) {
    for (std::size_t b = 0; b < B; ++b) {
      const float v0 = t.material_values(k)[b], v1 = t.material_values(k)[B + b];
      if (std::isnan(v0) || std::isnan(v1)) continue;
      bin.push_back(static_cast<std::int32_t>(b));
      f0.push_back(static_cast<std::int32_t>(std::lround(v0 * 65536.0)));
      f1.push_back(static_cast<std::int32_t>(std::lround(v1 * 65536.0)));
      truth.push_back(k);
    }
  }
  for (FixedKernel kernel : {FixedKernel::kScalar, FixedKernel::kBest}) {
    std::vector<std::uint8_t> labels(bin.size());
    ASSERT_EQ(pc.classify(bin.data(), f0.data(), f1.data(), bin.size(), labels.data(), kernel), bin.size());
    // A material's own value is its nearest unless another, lower-indexed
    // material holds the same quantised pair at that bin (a true tie).
    std::size_t ties = 0;
    for (std::size_t i = 0; i < labels.size(); ++i) {
      if (labels[i] == truth[i]) continue;
      const std::size_t b = static_cast<std::size_t>(bin[i]), p = c.padded_bins();
      ASSERT_LT(labels[i], truth[i]) << t.materials()[truth[i]] << " at bin " << b;
      EXPECT_EQ(c.values(labels[i])[b], c.values(truth[i])[b]) << t.materials()[truth[i]] << " at bin " << b;
      EXPECT_EQ(c.values(labels[i])[p + b], c.values(truth[i])[p + b]) << t.materials()[truth[i]] << " at bin " << b;
      ++ties;
    }
    std::cout << "[ measured ] " << labels.size() - ties << " of " << labels.size()
              << " table values labelled as their material, " << ties << " exact ties with a lower-indexed one\n";
    EXPECT_LE(ties, 4u);
  }
}

TEST(PixelClassifier, FusedFrameEqualsDecodeThenClassify) {
  ASSERT_DB_PRESENT();
  const ExemplarTable t = ExemplarTable::from_npy_dir(tofmat_test::db_dir(), kDatabaseBinStartMm, kDatabaseBinStopMm);
  const CompactTable c(t);
  const PixelClassifier pc(c, t.bins());
  // Depths over the table's bins and beyond, lengths that leave partial tiles.
  for (std::size_t n : {1u, 511u, 512u, 513u, 20000u}) {
    const auto s = tofmat_test::synthetic_frame(n, static_cast<std::uint32_t>(n), false, 550.0, 1250.0, 50.0, 3000.0);
    const FixedDecodeTables tables(s.p0, s.n);
    for (FixedKernel k : {FixedKernel::kScalar, FixedKernel::kBest}) {
      std::vector<std::uint8_t> two_step(n), fused(n);
      const std::size_t a = pc.classify(decode_frame_fixed(s.raw.data(), tables, {}, k), two_step.data(), k);
      const std::size_t b = pc.classify_frame(s.raw.data(), tables, fused.data(), {}, k);
      ASSERT_EQ(two_step, fused) << n;
      ASSERT_EQ(a, b) << n;
      if (n > 1000) {
        EXPECT_GT(a, n / 2) << "most pixels fall in the bins";
      }
    }
  }
}

}  // namespace
