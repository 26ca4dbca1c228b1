// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Depth-bin accumulation in fixed point against the float DepthBinAccumulator
// fed by the float decode of the same frames, its NEON bin kernel against the
// scalar one bit for bit (aarch64), the per-bin cap, and bad bins.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <iostream>
#include <random>
#include <vector>

#include "synthetic_raw.hpp"
#include "tofmat/core/depth_bins.hpp"
#include "tofmat/core/fixed_decode.hpp"
#include "tofmat/core/fixed_depth_bins.hpp"
#include "tofmat/core/frame_decode.hpp"

namespace {

using namespace tofmat;

const BinSpec kDatabaseBins = BinSpec::linspace(600.0, 1200.0, 200);  // the real database's bins

TEST(FixedDepthBins, MatchesTheFloatAccumulatorOnDecodedFrames) {
  DepthBinAccumulator fl(kDatabaseBins, 2);
  FixedDepthBinAccumulator fx(kDatabaseBins, 2);
  std::size_t added_float = 0, added_fixed = 0;
  for (std::uint32_t frame = 0; frame < 4; ++frame) {  // a sweep: 50,000 pixels a frame, 550..1250 mm
    const auto s = tofmat_test::synthetic_frame(50000, 100 + frame, false, 550.0, 1250.0, 20.0, 3000.0);
    const DecodedFrame f = decode_frame(s.raw.data(), s.n, s.p0);
    const FixedDecodedFrame x = decode_frame_fixed(s.raw.data(), FixedDecodeTables(s.p0, s.n));
    for (std::size_t i = 0; i < s.n; ++i) {
      if (f.flags[i]) continue;
      const float v[2] = {f.features[0][i], f.features[1][i]};
      added_float += fl.add(f.combined_mm[i], v) >= 0;
    }
    added_fixed += fx.add_frame(x);
  }
  // A pixel may land in the neighbouring bin only when its combined depth is
  // within the fixed path's error (0.006 mm, mostly the Q8 floor) of a bin
  // edge: about 0.2 % of them for 3 mm bins. A bin's mean then differs by
  // what the swapped pixels bring, far below the 0.3 mm roughness of the real
  // curves (measured: 308 of 344,738 observations moved, worst mean 0.008 mm).
  std::uint64_t moved = 0;
  double worst_mean = 0.0;
  const auto qf = fl.query(), qx = fx.query();
  for (std::uint32_t r = 0; r < 2; ++r) {
    for (std::uint32_t j = 0; j < kDatabaseBins.count; ++j) {
      const auto a = fl.count(r, j), b = fx.count(r, j);
      moved += a > b ? a - b : b - a;
      if (a == b && a > 0) {
        const std::size_t k = r * kDatabaseBins.count + j;
        worst_mean = std::max(worst_mean, std::fabs(static_cast<double>(qf[k]) - qx[k]));
      }
    }
  }
  std::cout << "[ measured ] fixed vs float accumulation: " << added_fixed << " / " << added_float << " pixels added, "
            << moved << " observations in a neighbouring bin, worst bin mean difference " << worst_mean << " mm\n";
  EXPECT_GT(added_fixed, 100000u);
  EXPECT_LE(added_fixed > added_float ? added_fixed - added_float : added_float - added_fixed, added_float / 10000);
  EXPECT_LE(moved, 2 * added_float / 200);  // 2 rows x 0.5 %
  EXPECT_LT(worst_mean, 0.03);
  EXPECT_EQ(fx.bins_covered(), fl.bins_covered());
  EXPECT_EQ(fx.refused(), 0u);
}

TEST(FixedDepthBins, FullBinsRefuseFurtherObservations) {
  FixedDepthBinAccumulator fx(kDatabaseBins, 2, 3);
  FixedDecodedFrame f;
  f.pixels = 10;
  f.combined_q8.assign(10, 900 * 256);  // all in one bin
  f.flags.assign(10, 0);
  f.features_q16[0].assign(10, 5 * 65536);
  f.features_q16[1].assign(10, -2 * 65536);
  EXPECT_EQ(fx.add_frame(f), 3u);
  const std::int32_t j = kDatabaseBins.index_of(900.0);
  EXPECT_EQ(fx.count(0, static_cast<std::uint32_t>(j)), 3u);
  EXPECT_EQ(fx.refused(), 14u);  // 7 pixels x 2 rows
  const auto q = fx.query();
  EXPECT_FLOAT_EQ(q[static_cast<std::size_t>(j)], 5.0f);
  EXPECT_FLOAT_EQ(q[kDatabaseBins.count + static_cast<std::size_t>(j)], -2.0f);
  EXPECT_TRUE(std::isnan(fx.query(4)[static_cast<std::size_t>(j)]));
  // Invalid pixels and depths outside the bins add nothing.
  f.flags[0] = kDecodeDark;
  f.combined_q8[1] = kFixedInvalid;
  f.combined_q8[2] = 100 * 256;
  f.combined_q8[3] = 1300 * 256;
  fx.reset();
  FixedDepthBinAccumulator wide(kDatabaseBins, 2);
  EXPECT_EQ(wide.add_frame(f), 6u);
  EXPECT_THROW(FixedDepthBinAccumulator(kDatabaseBins, 3), std::invalid_argument);
  EXPECT_THROW(FixedDepthBinAccumulator(BinSpec{600.0, 0.001, 10}), std::invalid_argument);
  EXPECT_THROW(FixedDepthBinAccumulator(BinSpec{600.0, 1.0 / 128.0, 10}), std::invalid_argument);  // inv would be 2^31
  EXPECT_THROW(FixedDepthBinAccumulator(BinSpec{1e7, 3.0, 10}), std::invalid_argument);
  EXPECT_THROW(wide.count(2, 0), std::out_of_range);
}

// The build's vector kernel (NEON on aarch64, AVX2 on x86-64 CPUs that have
// it) against the scalar definition.
TEST(FixedDepthBins, VectorBinKernelIsBitExactWithScalar) {
#if defined(__x86_64__)
  if (!cpu_has_avx2()) GTEST_SKIP() << "this CPU has no AVX2: kBest is the scalar kernel";
#elif !defined(__aarch64__)
  GTEST_SKIP() << "no vector kernel on this architecture";
#endif
  std::mt19937 rng(4);
  std::uniform_int_distribution<std::int32_t> any(INT32_MIN, INT32_MAX), near(500 * 256, 1300 * 256);
  for (const BinSpec& b : {kDatabaseBins, BinSpec{-4000.0, 1.0 / 64.0, 65535}, BinSpec{0.0, 4000.0, 3}}) {
    const FixedBinning fb = FixedBinning::from(b);
    for (std::size_t n : {1u, 4u, 7u, 8u, 9u, 5003u}) {
      std::vector<std::int32_t> d(n), a(n), c(n);
      std::vector<std::uint8_t> flags(n);
      for (std::size_t i = 0; i < n; ++i) {
        d[i] = i % 3 ? near(rng) : any(rng);
        if (i % 11 == 0) d[i] = kFixedInvalid;
        if (i % 13 == 0) d[i] = fb.start_q8;  // exactly on the first edge
        flags[i] = static_cast<std::uint8_t>(i % 17 == 0 ? kDecodeUnwrap : 0);
      }
      bin_indices_scalar(d.data(), flags.data(), n, fb, a.data());
      bin_indices(FixedKernel::kBest, d.data(), flags.data(), n, fb, c.data());
      ASSERT_EQ(a, c) << n;
    }
  }
}

}  // namespace
