// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The fixed-point decode against the float reference (frame_decode.hpp) over
// the whole input range, and its NEON kernel against the scalar one bit for
// bit (aarch64 builds, run under qemu-aarch64). Inputs come from the phasor
// model of synthetic_raw.hpp.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <iostream>
#include <random>
#include <vector>

#include "stiff_cases.hpp"
#include "synthetic_raw.hpp"
#include "tofmat/core/decode.hpp"
#include "tofmat/core/fixed_decode.hpp"
#include "tofmat/core/frame_decode.hpp"
#include "tofmat/core/raw_lut.hpp"

namespace {

using namespace tofmat;
constexpr double kTwoPi = 2.0 * kPi;
constexpr const double* kRange = tofmat_test::kGroupRangeMm;

using Synthetic = tofmat_test::SyntheticFrame;
Synthetic random_frame(std::size_t n, std::uint32_t seed, bool exact_wraps) {
  return tofmat_test::synthetic_frame(n, seed, exact_wraps);
}

double wrapped_diff(double a, double b, double period) { return std::remainder(a - b, period); }

TEST(FixedDecode, MatchesTheFloatDecodeWithinTheErrorBudget) {
  const Synthetic s = random_frame(200000, 17, true);
  const DecodedFrame f = decode_frame(s.raw.data(), s.n, s.p0);
  const FixedDecodeTables t(s.p0, s.n);
  const FixedDecodedFrame x = decode_frame_fixed(s.raw.data(), t, {}, FixedKernel::kScalar);
  double worst_phase[3] = {0, 0, 0}, worst_depth[3] = {0, 0, 0}, worst_combined = 0.0, worst_feature = 0.0,
         worst_amp = 0.0;
  std::size_t both_valid = 0, flag_differs = 0;
  for (std::size_t i = 0; i < s.n; ++i) {
    for (std::size_t g = 0; g < 3; ++g) {
      const double ph = x.phase_turns[g][i] * (kTwoPi / 4294967296.0);
      worst_phase[g] = std::max(worst_phase[g], std::fabs(wrapped_diff(ph, f.phase_rad[g][i], kTwoPi)));
      const double a = x.amplitude_q8[g][i] / 256.0;
      // Relative error beyond the Q8 step (1/256 count, truncated).
      worst_amp = std::max(worst_amp, (std::fabs(a - f.amplitude[g][i]) - 1.0 / 256.0) / f.amplitude[g][i]);
    }
    if (x.flags[i] != f.flags[i]) {
      // Only on a threshold's edge: an amplitude rule within 0.01 counts, or
      // an unwrap gap within 0.01 mm (two depths' budget), of its limit
      // (DecodeOptions defaults); or at the 16 MHz wrap point (0 = 9375 mm,
      // within the depth budget), where 0 unwraps consistently and 9375 mm
      // does not (9375 is no multiple of 1250): either side is a right answer.
      ++flag_differs;
      EXPECT_TRUE(tofmat_test::flag_difference_allowed(f, i))
          << "pixel " << i << ": flags " << int(f.flags[i]) << " (float) vs " << int(x.flags[i]) << " (fixed)";
      continue;
    }
    if (f.flags[i]) {
      EXPECT_EQ(x.combined_q8[i], kFixedInvalid);
      continue;
    }
    ++both_valid;
    for (std::size_t g = 0; g < 3; ++g) {
      const double d = x.depth_q16[g][i] / 65536.0;
      worst_depth[g] = std::max(worst_depth[g], std::fabs(wrapped_diff(d, f.depth_mm[g][i], kRange[g])));
    }
    worst_combined = std::max(worst_combined, std::fabs(x.combined_q8[i] / 256.0 - f.combined_mm[i]));
    for (std::size_t k = 0; k < 2; ++k) {
      // A feature is a difference of wrapped depths: at a wrap point the two
      // paths may sit on opposite sides (the wavelength), as in the float path.
      // (Wavelengths are multiples of 625 mm: reduce the difference modulo it.)
      const double fx = x.features_q16[k][i] / 65536.0, ff = f.features[k][i];
      worst_feature = std::max(worst_feature, std::fabs(std::remainder(fx - ff, 625.0)));
    }
  }
  std::cout << "[ measured ] fixed vs float over " << s.n << " pixels: phase " << worst_phase[0] << " / "
            << worst_phase[1] << " / " << worst_phase[2] << " rad, depth " << worst_depth[0] << " / " << worst_depth[1]
            << " / " << worst_depth[2] << " mm (80/16/120 MHz), combined " << worst_combined << " mm, features "
            << worst_feature << " mm, amplitude " << worst_amp << " (relative); flags differ at " << flag_differs
            << " pixels, both valid " << both_valid << "\n";
  // The budget (docs/numerics.md): 1e-6 rad of phase (the residual's cubic
  // term 1.6e-7, the float reference's own half ulp at 2 pi 2.4e-7), 0.002 mm
  // of per-frequency depth (far below the real curves' 0.3 mm roughness), the
  // combined depth's Q8 step (0.004 mm) plus that, features two depths'
  // worth, amplitude 1e-4 relative beyond its Q8 step (the residual angle's
  // cosine: 3.1e-5 at most).
  for (std::size_t g = 0; g < 3; ++g) {
    EXPECT_LT(worst_phase[g], 1e-6) << g;
    EXPECT_LT(worst_depth[g], 0.002) << g;
  }
  EXPECT_LT(worst_combined, 0.004 + 0.002);
  EXPECT_LT(worst_feature, 0.004);
  EXPECT_LT(worst_amp, 1e-4);
  EXPECT_GT(both_valid, s.n / 2);
  EXPECT_LE(flag_differs, s.n / 2000);  // (each checked above to sit on a threshold's edge)
}

TEST(FixedDecode, ExtremeSamplesNeitherOverflowNorDisagree) {
  // Every combination of extreme samples in each group (saturated, largest
  // magnitudes, zero, one count): run under UBSan in the sanitizer build, so a
  // signed overflow anywhere fails it.
  const std::int16_t v[] = {-16320, -16319, -1, 0, 1, 16319, 16320, kRawSaturated};
  std::vector<std::int16_t> raw;
  std::size_t n = 0;
  for (auto a : v) {
    for (auto b : v) {
      for (auto c : v) {
        ++n;
        for (int rep = 0; rep < 9; ++rep) raw.push_back(rep % 3 == 0 ? a : rep % 3 == 1 ? b : c);
      }
    }
  }
  // (raw was built pixel-major: make it sub-image-major.)
  std::vector<std::int16_t> planes(raw.size());
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t k = 0; k < 9; ++k) planes[k * n + i] = raw[i * 9 + k];
  }
  const DecodedFrame f = decode_frame(planes.data(), n, {});
  const FixedDecodedFrame x = decode_frame_fixed(planes.data(), FixedDecodeTables({}, n), {}, FixedKernel::kScalar);
  for (std::size_t i = 0; i < n; ++i) {
    EXPECT_EQ(x.flags[i] & kDecodeSaturated, f.flags[i] & kDecodeSaturated) << i;
    for (std::size_t g = 0; g < 3; ++g) {
      EXPECT_NEAR(x.amplitude_q8[g][i] / 256.0, f.amplitude[g][i], 1e-4 * std::max(1.0f, f.amplitude[g][i]) + 0.004)
          << i;
      if (f.amplitude[g][i] > 1.0f) {
        const double ph = x.phase_turns[g][i] * (kTwoPi / 4294967296.0);
        EXPECT_LT(std::fabs(wrapped_diff(ph, f.phase_rad[g][i], kTwoPi)), 1e-6) << i;
      }
    }
  }
}

TEST(FixedDecode, RegionEqualsTheFramesPixels) {
  const std::size_t w = 64, h = 48;
  Synthetic s = random_frame(w * h, 3, false);
  const FixedDecodeTables t(s.p0, s.n);
  const FixedDecodedFrame full = decode_frame_fixed(s.raw.data(), t);
  const PixelRegion r{5, 7, 42, 30};  // odd width: the NEON kernel's scalar tail too
  const FixedDecodedFrame reg = decode_region_fixed(s.raw.data(), static_cast<int>(w), static_cast<int>(h), t, r);
  std::size_t k = 0;
  for (int y = r.y0; y < r.y1; ++y) {
    for (int x0 = r.x0; x0 < r.x1; ++x0, ++k) {
      const std::size_t i = static_cast<std::size_t>(y) * w + static_cast<std::size_t>(x0);
      ASSERT_EQ(reg.flags[k], full.flags[i]);
      ASSERT_EQ(reg.combined_q8[k], full.combined_q8[i]);
      for (std::size_t g = 0; g < 3; ++g) {
        ASSERT_EQ(reg.phase_turns[g][k], full.phase_turns[g][i]);
        ASSERT_EQ(reg.amplitude_q8[g][k], full.amplitude_q8[g][i]);
        ASSERT_EQ(reg.depth_q16[g][k], full.depth_q16[g][i]);
      }
    }
  }
  EXPECT_THROW(decode_region_fixed(s.raw.data(), static_cast<int>(w), static_cast<int>(h), t, {0, 0, 65, 1}),
               std::invalid_argument);
  EXPECT_THROW(FixedDecodeTables(std::vector<float>(5), 4), std::invalid_argument);
}

TEST(FixedDecode, UnwrapDivisionMagicIsExact) {
  // The AVX2 finishing stage's divisions: every dividend it can see (< 2^14).
  for (const auto& d : {fixed_decode_detail::kDiv80, fixed_decode_detail::kDiv120}) {
    for (std::int32_t m = 0; m < (1 << 14); ++m) ASSERT_EQ((m * d.magic) >> d.shift, m / d.range_mm) << m;
  }
}

// The build's vector kernel (NEON on aarch64, AVX2 on x86-64 CPUs that have
// it) against the scalar definition, bit for bit.
TEST(FixedDecode, VectorKernelIsBitExactWithScalar) {
#if defined(__x86_64__)
  if (!cpu_has_avx2()) GTEST_SKIP() << "this CPU has no AVX2: kBest is the scalar kernel";
  const auto vector_kernel = phase_amplitude_avx2;
#elif defined(__aarch64__)
  const auto vector_kernel = phase_amplitude_neon;
#else
  GTEST_SKIP() << "no vector kernel on this architecture";
  const auto vector_kernel = phase_amplitude_scalar;
#endif
  // Random pixels over the whole range, exact wrap points, extremes, and
  // lengths that leave a scalar tail.
  // The finishing stage too, under every kind of threshold: defaults, none,
  // ones that flag a good share (amplitude and gaps), NaN gaps (every gap fails).
  DecodeOptions none, strict, nan_gaps;
  none.min_amplitude = none.min_mean_amplitude = none.min_unwrap_amplitude = 0.0;
  none.max_gap_16_80_mm = none.max_gap_80_120_mm = 1e30;
  strict.min_amplitude = 200.0;
  strict.min_mean_amplitude = 900.0;
  strict.min_unwrap_amplitude = 500.0;
  strict.max_gap_16_80_mm = 0.05;
  strict.max_gap_80_120_mm = 0.02;
  nan_gaps.max_gap_16_80_mm = std::nan("");
  for (const DecodeOptions& o : {DecodeOptions{}, none, strict, nan_gaps}) {
    for (std::size_t n : {1u, 3u, 4u, 7u, 8u, 9u, 17u, 1000u, 65537u}) {
      const Synthetic s = random_frame(n, static_cast<std::uint32_t>(n), true);
      const FixedDecodeTables t(s.p0, s.n);
      const FixedDecodedFrame a = decode_frame_fixed(s.raw.data(), t, o, FixedKernel::kScalar);
      FixedDecodedFrame b = decode_frame_fixed(s.raw.data(), t, o, FixedKernel::kBest);
      for (int pass = 0; pass < 2; ++pass) {  // the second time into the same (reused) frame
        for (std::size_t g = 0; g < 3; ++g) {
          ASSERT_EQ(a.phase_turns[g], b.phase_turns[g]) << n;
          ASSERT_EQ(a.amplitude_q8[g], b.amplitude_q8[g]) << n;
          ASSERT_EQ(a.depth_q16[g], b.depth_q16[g]) << n;
        }
        ASSERT_EQ(a.flags, b.flags) << n;
        ASSERT_EQ(a.combined_q8, b.combined_q8) << n;
        ASSERT_EQ(a.features_q16[0], b.features_q16[0]) << n;
        ASSERT_EQ(a.features_q16[1], b.features_q16[1]) << n;
        decode_frame_fixed(s.raw.data(), t, b, o, FixedKernel::kBest);
      }
    }
  }
  std::mt19937 rng(9);  // raw samples uniformly over every code value, saturation included
  std::uniform_int_distribution<int> any(-16320, 16320);
  std::vector<std::int16_t> m(3 * 4096);
  for (auto& v : m) v = static_cast<std::int16_t>(rng() % 50 == 0 ? kRawSaturated : any(rng));
  m[0] = m[4096] = m[8192] = 0;  // a zero phasor
  // Every extreme combination (as ExtremeSamplesNeitherOverflowNorDisagree).
  const std::int16_t ext[] = {-16320, -16319, -1, 0, 1, 16319, 16320, kRawSaturated};
  std::size_t k = 1;
  for (auto a : ext) {
    for (auto b : ext) {
      for (auto c : ext) {
        m[k] = a;
        m[4096 + k] = b;
        m[8192 + k] = c;
        ++k;
      }
    }
  }
  std::vector<std::uint32_t> p0(4096);
  for (auto& v : p0) v = static_cast<std::uint32_t>(rng());
  std::vector<std::uint32_t> pa(4096), pb(4096), aa(4096), ab(4096);
  std::vector<std::uint8_t> fa(4096, 0), fb(4096, 0);
  phase_amplitude_scalar(m.data(), m.data() + 4096, m.data() + 8192, p0.data(), 4096, pa.data(), aa.data(), fa.data());
  vector_kernel(m.data(), m.data() + 4096, m.data() + 8192, p0.data(), 4096, pb.data(), ab.data(), fb.data());
  EXPECT_EQ(pa, pb);
  EXPECT_EQ(aa, ab);
  EXPECT_EQ(fa, fb);
}

}  // namespace
