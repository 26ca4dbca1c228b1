// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The Kinect v2's 11-bit sample code and its 16-bit value: bit 10 is the
// sign, the low 10 bits a companded magnitude (steps of 1 up to 256, then 2,
// 4, ..., 64 per 128-code block, reaching 16320); code 1024 ("minus zero") is
// the saturation marker 32767. Facts: shared/docs/kinect2-protocol.md 2.4.
#pragma once

#include <cstddef>
#include <cstdint>

namespace tofmat {

inline constexpr std::int16_t kRawSaturated = 32767;
inline constexpr std::int32_t kRawMaxMagnitude = 16320;
inline constexpr std::uint16_t kRawSaturationCode = 1024;

// Value of an 11-bit code (only the low 11 bits are used).
std::int16_t raw_code_value(std::uint16_t code);

// The code whose value is nearest to v; |v| > 16320 clamps to +-16320 (the
// saturation marker is set by the caller, who knows whether the pixel saturated).
std::uint16_t raw_code_nearest(double v);

// The value of raw_code_nearest(av) for a magnitude av in [0, 16320], from the
// bit length instead of a search or a table (the simulator quantises two
// million samples a frame, and a 16321-entry table misses L1 on noisy ones):
// steps of 1 below 256, then 2 on [256, 512), 4 on [512, 1024), ..., 64 on
// [8192, 16320]; ties go down.
inline int raw_magnitude_nearest(double av) {
  const auto iv = static_cast<std::uint32_t>(av);
  const int bits = 32 - __builtin_clz(iv | 1u);  // bit length of floor(av)
  const int shift = bits > 8 ? bits - 8 : 0;     // log2 of the step
  const int lo = static_cast<int>((iv >> shift) << shift);
  const int hi = lo + (1 << shift);
  // Branch-free select: with noise the choice is a coin flip per sample.
  return lo + static_cast<int>(2.0 * av > static_cast<double>(lo + hi)) * (hi - lo);
}

// A row of samples to the camera's values: the nearest code's value with the
// sample's sign (raw_magnitude_nearest), 32767 where |v| > saturation or v is
// NaN. The simulator's hot loop: it runs in float and without branches so it
// vectorises (4 samples an instruction with SSE2). A sample is rounded to
// float first (1e-3 counts at the top of the range), so within that of a tie
// between two codes it may take the other one; everywhere else it is
// raw_magnitude_nearest exactly.
void raw_quantise(const double* samples, std::size_t n, double saturation, std::int16_t* out);

}  // namespace tofmat
