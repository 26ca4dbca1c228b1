// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The 11-bit sample code's table of 16-bit values, its inverse (nearest code), and quantisation of simulated samples.
#include "tofmat/core/raw_lut.hpp"

#include <array>
#include <cmath>
#include <cstring>

namespace tofmat {
namespace {

// Magnitudes v(c), c = 0..1023: v(0) = 0, v(c+1) = v(c) + step(c).
struct Magnitudes {
  std::array<std::int32_t, 1024> v{};
  Magnitudes() {
    for (int c = 0; c < 1023; ++c) {
      const std::int32_t step = c < 256 ? 1 : (1 << (c / 128 - 1));
      v[static_cast<std::size_t>(c + 1)] = v[static_cast<std::size_t>(c)] + step;
    }
  }
};
const Magnitudes& magnitudes() {
  static const Magnitudes m;
  return m;
}

int float_bits(float f) {
  int i;
  std::memcpy(&i, &f, sizeof i);
  return i;
}
float bits_float(int i) {
  float f;
  std::memcpy(&f, &i, sizeof f);
  return f;
}

}  // namespace

std::int16_t raw_code_value(std::uint16_t code) {
  code &= 0x7FF;
  if (code == kRawSaturationCode) return kRawSaturated;
  const auto mag = magnitudes().v[code & 0x3FF];
  return static_cast<std::int16_t>((code & 0x400) ? -mag : mag);
}

std::uint16_t raw_code_nearest(double v) {
  const auto& m = magnitudes().v;
  double a = std::fabs(v);
  if (!(a <= kRawMaxMagnitude)) a = kRawMaxMagnitude;  // also NaN -> clamp
  // Binary search for the nearest magnitude.
  std::size_t lo = 0, hi = m.size() - 1;
  while (hi - lo > 1) {
    const std::size_t mid = (lo + hi) / 2;
    if (m[mid] <= a) {
      lo = mid;
    } else {
      hi = mid;
    }
  }
  const std::size_t c = (a - m[lo] <= m[hi] - a) ? lo : hi;
  if (c == 0) return 0;  // +0 (the negative zero code is the saturation marker)
  return static_cast<std::uint16_t>(v < 0 ? (0x400 | c) : c);
}

// raw_magnitude_nearest with the step taken from the float exponent instead
// of comparisons (GCC turns a chain of comparisons into branches). This file
// is compiled with -fno-trapping-math: the selects below only vectorise when
// a comparison may be evaluated for every lane.
void raw_quantise(const double* samples, std::size_t n, double saturation, std::int16_t* out) {
  const auto top = static_cast<float>(kRawMaxMagnitude);
  const auto sat = static_cast<float>(saturation);
  for (std::size_t c = 0; c < n; ++c) {
    const auto x = static_cast<float>(samples[c]);
    const float av = std::fabs(x);
    const float m = av < top ? av : top;  // NaN -> top (no undefined conversion)
    const int iv = static_cast<int>(m);
    // log2 of the step: bit length of floor(m), less 8, at least 0.
    int e = (float_bits(static_cast<float>(iv | 1)) >> 23) - (127 + 7);
    e &= ~(e >> 31);
    const float step = bits_float((127 + e) << 23);
    const float lo = static_cast<float>(static_cast<int>(m * bits_float((127 - e) << 23))) * step;  // exact
    const float code = lo + (2.0f * m > 2.0f * lo + step ? step : 0.0f);                            // ties go down
    const float value = x < 0.0f ? -code : code;
    out[c] = static_cast<std::int16_t>(!(av <= sat) ? static_cast<float>(kRawSaturated) : value);
  }
}

}  // namespace tofmat
