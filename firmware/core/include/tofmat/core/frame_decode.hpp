// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Float reference decode of a raw frame (nine phase-step images) into
// per-frequency phase, amplitude and depth, the combined depth, and validity.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace tofmat {

// Validity of a decoded pixel (flags below). The defaults were checked on
// synthetic samples with 3 counts of Gaussian read noise per sample (the
// shipped simulator profiles' read noise), true amplitude A in all groups, at
// 700, 1000, 2500 and 6000 mm (tests/cpp/test_decode.cpp, DecodeNoise): noise
// alone gives no valid pixel (0 of 500000), and of the valid pixels far fewer
// than 0.5 % are more than 300 mm off: A = 3: no pixel valid; A = 5: 675 of
// 8e6 valid, 1 off (0.15 %; such errors are the 7500 mm ones near the ends of
// the range); A = 10: 17 % valid, 0.001 % off; A = 30: 99.85 % valid, none off.
struct DecodeOptions {
  // Dark (kDecodeDark), as the camera's own decoder: every group's amplitude
  // |a + i b| / 1.5 (the fundamental's amplitude in raw counts) at least
  // min_amplitude, and the mean of the three groups' amplitudes at least
  // min_mean_amplitude. 3 and 10 counts are the Kinect v2 reference
  // decoder's individual and combined amplitude thresholds.
  double min_amplitude = 3.0;
  double min_mean_amplitude = 10.0;
  // Unwrapping (kDecodeUnwrap): the 16 MHz phase alone chooses between depth
  // hypotheses 1875 mm apart (decode.hpp, unwrap_consistent), so its group
  // must be bright enough that its phase noise (~2.46 / A rad with 3 counts
  // of read noise, 306 mm of D16 at A = 12) stays well inside that: at
  // least min_unwrap_amplitude counts. Without it a pixel of true amplitude
  // 5 that the noise lifts over the dark rule is wrong ~1 % of the time near
  // the ends of the range (with it, ~0.2 %). Real targets are at hundreds of
  // counts, and the 16 MHz group is the brightest of the calibrated profile.
  double min_unwrap_amplitude = 12.0;
  // ... and the unwrapped depths must agree: |D80 - D16| <= max_gap_16_80_mm
  // and |D120 - D80| <= max_gap_80_120_mm. A material's own distortion
  // moves the frequencies' depths apart, and must stay valid: the real
  // database's largest d16 - d120 differences are about 130 mm, which
  // leaves 270 mm (400 - 130) and 170 mm (300 - 130) for noise, i.e. about
  // 7 sigma of D16 and 25 sigma of D80 - D120 at an amplitude of 100 counts.
  // Wrong multiples leave gaps near 625 mm (D80 - D120) or 1875 mm (D16,
  // modulo its wrap): 400 and 300 mm keep margins of 1475 and 325 mm to them.
  double max_gap_16_80_mm = 400.0;
  double max_gap_80_120_mm = 300.0;
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
  std::vector<std::uint8_t> flags;  // kDecodeSaturated | kDecodeDark | kDecodeUnwrap, 0 = valid
};

// A pixel rectangle [x0, x1) x [y0, y1) of a width x height frame.
struct PixelRegion {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
};

// Flags of a pixel; any flag makes the depths, combined depth and features
// NaN (phase and amplitude are always filled in).
inline constexpr std::uint8_t kDecodeSaturated = 1;  // a sample is 32767
inline constexpr std::uint8_t kDecodeDark = 2;       // amplitude rule (DecodeOptions)
// The unwrapping is not trustworthy: the 16 MHz amplitude is below
// min_unwrap_amplitude or the unwrapped depths disagree (unwrap_consistent).
// Only tested on pixels that are neither saturated nor dark.
inline constexpr std::uint8_t kDecodeUnwrap = 4;

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
// holds the region's pixels row by row, identical to decode_frame's for those
// pixels. The p0_rad overload computes the corrections of the region's pixels
// only (not DecodeTables of the whole frame). Throws std::invalid_argument on
// a size mismatch or a region that is empty or outside the frame.
DecodedFrame decode_region(const std::int16_t* raw, int width, int height, const std::vector<float>& p0_rad,
                           const PixelRegion& region, const DecodeOptions& options = {});
DecodedFrame decode_region(const std::int16_t* raw, int width, int height, const DecodeTables& tables,
                           const PixelRegion& region, const DecodeOptions& options = {});

}  // namespace tofmat
