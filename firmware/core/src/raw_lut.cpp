#include "tofmat/core/raw_lut.hpp"

#include <array>
#include <cmath>

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

}  // namespace tofmat
