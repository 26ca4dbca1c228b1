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

// A still target in front of the camera: every pixel at the same true depth,
// the samples with sensor noise. A pixel's combined depth and its features are
// computed from the same samples, so their errors are correlated; binned by
// its own depth, each bin holds the pixels whose noise put them there and the
// bins' means lean with depth although the target has one depth and features
// 0. The surface's mean at its mean depth is the target's own value in one
// bin: what the tables are recorded as and what RegionMatcher adds.
TEST(FixedDepthBins, AStillTargetsSurfaceIsOneBinAtItsValueWherePixelBinsLean) {
  constexpr std::size_t n = 2304;  // the handheld ROI, 48 x 48
  std::vector<std::int16_t> raw(9 * n);
  std::vector<float> p0(3 * n);
  std::mt19937 rng(5);
  std::normal_distribution<double> noise(0.0, 6.0);
  const double depth[3] = {900.0, 900.0, 900.0};
  const float zero[3] = {0.0f, 0.0f, 0.0f};
  for (std::size_t i = 0; i < n; ++i) {
    tofmat_test::put_synthetic_pixel(raw.data(), p0.data(), n, i, depth, zero, 1000.0, 0.0);
    for (std::size_t k = 0; k < 9; ++k) {
      raw[k * n + i] = tofmat_test::raw_sample(raw[k * n + i] + noise(rng));
    }
  }
  const FixedDecodedFrame x = decode_frame_fixed(raw.data(), FixedDecodeTables(p0, n));
  const DecodedFrame f = decode_frame(raw.data(), n, p0);

  FixedDepthBinAccumulator per_pixel(kDatabaseBins, 2);
  per_pixel.add_frame(x);
  const auto qp = per_pixel.query();
  double lowest = 0.0, highest = 0.0;  // row 0's mean in the nearest and the farthest bin holding 20 pixels
  for (std::uint32_t j = 0; j < kDatabaseBins.count; ++j) {
    if (per_pixel.count(0, j) < 20) continue;
    if (lowest == 0.0) lowest = qp[j];
    highest = qp[j];
  }
  std::cout << "[ measured ] still target, pixels binned by their own depth: " << per_pixel.bins_covered()
            << " bins, row 0 from " << lowest << " to " << highest << " mm\n";
  EXPECT_GE(per_pixel.bins_covered(), 3u);
  EXPECT_GT(std::fabs(highest - lowest), 2.0);

  const FixedSurfaceMean s = surface_mean(x, 900 * 256, 64 * 256);
  FixedDepthBinAccumulator surface(kDatabaseBins, 2);
  EXPECT_EQ(surface.add_surface(s), s.pixels);
  EXPECT_GT(s.pixels, n * 9 / 10);
  EXPECT_EQ(surface.bins_covered(), 1u);
  const auto j = static_cast<std::size_t>(kDatabaseBins.index_of(s.depth_q8 / 256.0));
  const auto q = surface.query();
  EXPECT_NEAR(s.depth_q8 / 256.0, 900.0, 0.5);
  EXPECT_NEAR(q[j], 0.0, 0.3);
  EXPECT_NEAR(q[kDatabaseBins.count + j], 0.0, 0.3);

  // The float reference takes the same pixels to within the fixed decode's error.
  const SurfaceMean g = surface_mean(f, 900.0, 64.0);
  EXPECT_LE(g.pixels > s.pixels ? g.pixels - s.pixels : s.pixels - g.pixels, 2u);
  EXPECT_NEAR(g.depth_mm, s.depth_q8 / 256.0, 0.01);
  EXPECT_NEAR(g.sum_mm[0] / static_cast<double>(g.pixels), q[j], 0.01);
  DepthBinAccumulator fl(kDatabaseBins, 2);
  EXPECT_EQ(fl.add_sums(g.depth_mm, g.sum_mm, g.pixels), static_cast<std::int32_t>(j));
  EXPECT_NEAR(fl.query()[j], q[j], 0.01);
}

TEST(FixedDepthBins, TheSurfaceIsThePixelsWithinTheBandAndOneObservationOfThem) {
  FixedDecodedFrame f;
  f.pixels = 6;
  // Two pixels of the target (901, 903 mm), a background at 1500, one dark, one invalid, one at the band's edge.
  f.combined_q8 = {901 * 256, 903 * 256, 1500 * 256, 902 * 256, kFixedInvalid, 964 * 256};
  f.flags = {0, 0, 0, kDecodeDark, 0, 0};
  f.features_q16[0] = {2 * 65536, 4 * 65536, 100 * 65536, 100 * 65536, 0, 3 * 65536};
  f.features_q16[1] = {-65536, -65536, 0, 0, 0, -65536};
  const FixedSurfaceMean s = surface_mean(f, 900 * 256, 64 * 256);
  EXPECT_EQ(s.pixels, 3u);
  EXPECT_EQ(s.depth_q8, (901 + 903 + 964) * 256 / 3);
  EXPECT_EQ(s.sum_q16[0], 9 * 65536);
  EXPECT_EQ(s.sum_q16[1], -3 * 65536);
  // The mean is floored, toward lower depths, for negative sums too.
  FixedDecodedFrame neg = f;
  neg.combined_q8 = {-1, -2, kFixedInvalid, kFixedInvalid, kFixedInvalid, kFixedInvalid};
  EXPECT_EQ(surface_mean(neg, 0, 10).depth_q8, -2);
  EXPECT_EQ(surface_mean(f, 0, 10).pixels, 0u);  // nothing within the band
  EXPECT_EQ(surface_mean(f, 0, 10).depth_q8, kFixedInvalid);
  EXPECT_THROW(surface_mean(f, 900 * 256, -1), std::invalid_argument);
  FixedDecodedFrame bad = f;
  bad.flags.pop_back();
  EXPECT_THROW(surface_mean(bad, 900 * 256, 64 * 256), std::invalid_argument);

  // One bin takes them all, counted as pixels; a full bin refuses the whole surface.
  FixedDepthBinAccumulator acc(kDatabaseBins, 2, 5);
  EXPECT_EQ(acc.add_surface(s), 3u);
  EXPECT_EQ(acc.bins_covered(), 1u);
  const auto j = static_cast<std::uint32_t>(kDatabaseBins.index_of(s.depth_q8 / 256.0));
  EXPECT_EQ(acc.count(0, j), 3u);
  EXPECT_FLOAT_EQ(acc.query()[j], 3.0f);
  EXPECT_EQ(acc.add_surface(s), 0u);  // 3 + 3 > 5
  EXPECT_EQ(acc.refused(), 3u);
  EXPECT_EQ(acc.add_surface(FixedSurfaceMean{}), 0u);
  FixedSurfaceMean far = s;
  far.depth_q8 = 2000 * 256;
  EXPECT_EQ(acc.add_surface(far), 0u);  // outside the bins

  DepthBinAccumulator fl(kDatabaseBins, 2);
  const double sums[2] = {9.0, -3.0}, inf[2] = {INFINITY, 0.0};
  EXPECT_EQ(fl.add_sums(922.0, sums, 0), -1);
  EXPECT_EQ(fl.add_sums(100.0, sums, 3), -1);
  EXPECT_THROW(fl.add_sums(922.0, inf, 3), std::invalid_argument);
  const std::int32_t k = fl.add_sums(922.0, sums, 3);
  ASSERT_GE(k, 0);
  EXPECT_EQ(fl.count(1, static_cast<std::uint32_t>(k)), 3u);
  EXPECT_FLOAT_EQ(fl.query()[kDatabaseBins.count + static_cast<std::size_t>(k)], -1.0f);
  EXPECT_THROW(surface_mean(DecodedFrame{}, 900.0, NAN), std::invalid_argument);
}

// A surface across the 120 MHz wrap (1250 mm): the features of the pixels
// beyond it are 1250 mm apart (differences of wrapped depths); they would
// drag the mean by hundreds of mm. Only the centre's side counts.
TEST(FixedDepthBins, TheSurfaceKeepsToTheSideOfEveryWrapItsCentreIsOn) {
  FixedDecodedFrame f;
  f.pixels = 5;
  f.combined_q8 = {1240 * 256, 1244 * 256, 1246 * 256, 1256 * 256, 1262 * 256};
  f.flags.assign(5, 0);
  f.features_q16[0] = {7 * 65536, 8 * 65536, 9 * 65536, 1258 * 65536, 1259 * 65536};
  f.features_q16[1] = {-2 * 65536, -2 * 65536, -2 * 65536, 1248 * 65536, 1248 * 65536};
  const FixedSurfaceMean s = surface_mean(f, 1245 * 256, 64 * 256);
  EXPECT_EQ(s.pixels, 3u);
  EXPECT_EQ(s.sum_q16[0], 24 * 65536);
  EXPECT_EQ(s.depth_q8, 1243 * 256 + 85);  // (1240 + 1244 + 1246) / 3 = 1243.33 mm
  const FixedSurfaceMean far = surface_mean(f, 1258 * 256, 64 * 256);
  EXPECT_EQ(far.pixels, 2u);  // the other side, from a centre there
  EXPECT_EQ(far.sum_q16[1], 2496 * 65536);

  DecodedFrame g;
  g.pixels = 5;
  g.flags.assign(5, 0);
  g.combined_mm = {1240.0f, 1244.0f, 1246.0f, 1256.0f, 1262.0f};
  g.features[0] = {7.0f, 8.0f, 9.0f, 1258.0f, 1259.0f};
  g.features[1] = {-2.0f, -2.0f, -2.0f, 1248.0f, 1248.0f};
  const SurfaceMean t = surface_mean(g, 1245.0, 64.0);
  EXPECT_EQ(t.pixels, 3u);
  EXPECT_DOUBLE_EQ(t.sum_mm[0], 24.0);
  EXPECT_NEAR(t.depth_mm, 1243.333, 0.001);
}
