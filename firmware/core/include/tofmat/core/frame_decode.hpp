// Float reference decode of a raw frame (nine phase-step images) into
// per-frequency phase, amplitude and depth, the combined depth, and validity.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace tofmat {

struct DecodeOptions {
  // A group whose phasor magnitude |a + i b| / 1.5 (the fundamental's
  // amplitude in raw counts) is below this is too dark to trust.
  double min_amplitude = 3.0;
};

struct DecodedFrame {
  std::size_t pixels = 0;
  std::array<std::vector<float>, 3> phase_rad;  // group order 80, 16, 120 MHz, [0, 2 pi)
  std::array<std::vector<float>, 3> amplitude;  // |a + i b| / 1.5, raw counts
  std::array<std::vector<float>, 3> depth_mm;   // Eq. (1), wrapped; NaN where invalid
  std::vector<float> combined_mm;               // unwrapped, frequency-weighted; NaN where invalid
  std::vector<std::uint8_t> flags;              // kDecodeSaturated | kDecodeDark per pixel, 0 = valid
};

inline constexpr std::uint8_t kDecodeSaturated = 1;
inline constexpr std::uint8_t kDecodeDark = 2;

// raw: 9 x pixels (sub-image-major, the LUT's 16-bit values, 32767 = saturated);
// p0_rad: 3 x pixels per-pixel phase corrections (empty = none). Throws
// std::invalid_argument on size mismatch.
DecodedFrame decode_frame(const std::int16_t* raw, std::size_t pixels, const std::vector<float>& p0_rad,
                          const DecodeOptions& options = {});

}  // namespace tofmat
