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
  // Eq. (10) per pixel in the database's sign: d16 - d120 and d80 - d120 of
  // the wrapped depths (mm); NaN where invalid.
  std::array<std::vector<float>, 2> features;
  std::vector<std::uint8_t> flags;              // kDecodeSaturated | kDecodeDark per pixel, 0 = valid
};

// A pixel rectangle [x0, x1) x [y0, y1) of a width x height frame.
struct PixelRegion {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
};

inline constexpr std::uint8_t kDecodeSaturated = 1;
inline constexpr std::uint8_t kDecodeDark = 2;

// raw: 9 x pixels (sub-image-major, the LUT's 16-bit values, 32767 = saturated);
// p0_rad: 3 x pixels per-pixel phase corrections (empty = none). Throws
// std::invalid_argument on size mismatch.
DecodedFrame decode_frame(const std::int16_t* raw, std::size_t pixels, const std::vector<float>& p0_rad,
                          const DecodeOptions& options = {});

// The P0 corrections as the decode uses them: e^{-i p0} per pixel and group
// (the device's P0 tables do not change while it streams, so a driver builds
// these once; the decode then needs no trigonometry but the phase's atan2).
struct DecodeTables {
  std::size_t pixels = 0;
  std::array<std::vector<float>, 3> cos_p0, sin_p0;
  // p0_rad: 3 x pixels (empty: no correction). Throws std::invalid_argument on a size mismatch.
  DecodeTables(const std::vector<float>& p0_rad, std::size_t pixels);
};
DecodedFrame decode_frame(const std::int16_t* raw, const DecodeTables& tables, const DecodeOptions& options = {});

// Only the pixels of `region` (what a hand-held ROI profile needs): raw and
// p0_rad are the full frame's (as above, width x height pixels); the result
// holds the region's pixels row by row. Throws std::invalid_argument on a
// size mismatch or a region that is empty or outside the frame.
DecodedFrame decode_region(const std::int16_t* raw, int width, int height, const std::vector<float>& p0_rad,
                           const PixelRegion& region, const DecodeOptions& options = {});
DecodedFrame decode_region(const std::int16_t* raw, int width, int height, const DecodeTables& tables,
                           const PixelRegion& region, const DecodeOptions& options = {});

}  // namespace tofmat
