// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Synthetic raw Kinect v2 frames for the decode tests, from the phasor model
// m_j = B + A cos(theta + phi_j), whose decoded phasor is 1.5 A e^{i theta}
// (the three steps cancel the e^{-i theta} term): the float and fixed-point
// decodes are checked against each other on these, never against themselves.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "tofmat/core/decode.hpp"
#include "tofmat/core/raw_lut.hpp"

namespace tofmat_test {

// Unambiguous range of each group (80, 16, 120 MHz) with the device's c.
inline constexpr double kGroupRangeMm[3] = {1875.0, 9375.0, 1250.0};

// A frame of `n` pixels: raw (9 x n, sub-image-major) and p0 (3 x n).
struct SyntheticFrame {
  std::size_t n = 0;
  std::vector<std::int16_t> raw;
  std::vector<float> p0;
};

inline std::int16_t raw_sample(double v) {
  return static_cast<std::int16_t>(std::clamp(std::nearbyint(v), -static_cast<double>(tofmat::kRawMaxMagnitude),
                                              static_cast<double>(tofmat::kRawMaxMagnitude)));
}

// Pixel i of a frame of n pixels (raw: 9 x n, p0_out: 3 x n): group g sees
// depth_mm[g] (a material distorts each frequency differently) through the
// per-pixel correction p0[g]; samples B + A cos(theta + phi_j), rounded and
// clamped to the 11-bit code's range.
inline void put_synthetic_pixel(std::int16_t* raw, float* p0_out, std::size_t n, std::size_t i,
                                const double depth_mm[3], const float p0[3], double amp, double offset) {
  for (std::size_t g = 0; g < 3; ++g) {
    p0_out[g * n + i] = p0[g];
    const double theta = 2.0 * tofmat::kPi * depth_mm[g] / kGroupRangeMm[g] + static_cast<double>(p0[g]);
    for (std::size_t j = 0; j < 3; ++j) {
      raw[(3 * g + j) * n + i] = raw_sample(offset + amp * std::cos(theta + tofmat::kPhaseStepsRad[j]));
    }
  }
}

// Pixels at true depths drawn from [min_depth, max_depth) mm (per group phase
// = depth / range turns, plus p0), amplitudes log-uniform over [min_amp,
// max_amp] counts, offsets as large as the range allows, random p0. With
// exact_wraps, a quarter of the pixels sit exactly on multiples of 1250 mm
// (every group's wrap points) and a quarter just below the 80 MHz ones.
inline SyntheticFrame synthetic_frame(std::size_t n, std::uint32_t seed, bool exact_wraps, double min_depth = 0.0,
                                      double max_depth = 9375.0, double min_amp = 3.0, double max_amp = 8000.0) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> depth(min_depth, max_depth), p0d(-tofmat::kPi, tofmat::kPi), u01(0.0, 1.0);
  SyntheticFrame s;
  s.n = n;
  s.raw.assign(9 * n, 0);
  s.p0.assign(3 * n, 0.0f);
  for (std::size_t i = 0; i < n; ++i) {
    double d = depth(rng);
    if (exact_wraps && i % 4 == 0) d = kGroupRangeMm[2] * static_cast<double>((i / 4) % 7);
    if (exact_wraps && i % 4 == 1) d = kGroupRangeMm[0] * static_cast<double>((i / 4) % 5) - 1e-7;
    const double amp = std::exp(std::log(min_amp) + u01(rng) * (std::log(max_amp) - std::log(min_amp)));
    const double offset = (u01(rng) - 0.5) * 2.0 * std::max(0.0, 16000.0 - amp);
    float p0[3];
    for (float& v : p0) v = static_cast<float>(p0d(rng));
    const double dg[3] = {d, d, d};
    put_synthetic_pixel(s.raw.data(), s.p0.data(), n, i, dg, p0, amp, offset);
  }
  return s;
}

}  // namespace tofmat_test
