// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Fixed-point decode of raw frames (docs/numerics.md): the same outputs as
// decode_frame (frame_decode.hpp), in integers. Per pixel and group the phase
// comes from a CORDIC in Q32 turns (wrapping arithmetic does the mod 2 pi)
// and the amplitude from the CORDIC's magnitude; depths are Q16 mm, the
// combined depth Q8 mm. The phase/amplitude stage has a scalar, a NEON
// (aarch64) and an AVX2 (x86-64) kernel, the finishing stage (unwrapping,
// flags, features) a scalar and an AVX2 kernel: all give the same integers
// bit for bit.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "tofmat/core/fixed_kernel.hpp"
#include "tofmat/core/frame_decode.hpp"

namespace tofmat {

inline constexpr int kPhaseFracBits = 32;                 // phase: uint32 turns
inline constexpr int kDepthFracBits = 16;                 // per-frequency depths and features: int32 Q16 mm
inline constexpr int kCombinedFracBits = 8;               // combined depth: int32 Q8 mm
inline constexpr int kAmplitudeFracBits = 8;              // amplitude: uint32 Q8 counts
inline constexpr std::int32_t kFixedInvalid = INT32_MIN;  // depth, combined, feature of an invalid pixel
// The phase estimator (docs/numerics.md): kCordicSteps CORDIC steps rotate
// the phasor to within atan(2^-5) = 1.8 degrees of the x axis, in integers;
// the residual angle is then atan(t) = t - t^3 / 3 (t^5 / 5 < 6e-9 rad
// dropped), t = y / x, and the magnitude x sqrt(1 + t^2) = x + x t^2 / 2, in
// IEEE-754 binary32: one correctly rounded division and a fixed sequence of
// products and a difference (never fused: the files that compute them build
// with -ffp-contract=off), so scalar, NEON and AVX2 agree bit for bit.
inline constexpr int kCordicSteps = 6;

// p0 per pixel and group in Q32 turns (round(p0 / 2 pi * 2^32) mod 2^32).
struct FixedDecodeTables {
  std::size_t pixels = 0;
  std::array<std::vector<std::uint32_t>, 3> p0_turns;
  // p0_rad: 3 x pixels (empty: no correction). Throws std::invalid_argument on a size mismatch.
  FixedDecodeTables(const std::vector<float>& p0_rad, std::size_t pixels);
};

struct FixedDecodedFrame {
  std::size_t pixels = 0;
  std::array<std::vector<std::uint32_t>, 3> phase_turns;   // group order 80, 16, 120 MHz
  std::array<std::vector<std::uint32_t>, 3> amplitude_q8;  // |a + i b| / 1.5
  std::array<std::vector<std::int32_t>, 3> depth_q16;      // Eq. (1), wrapped; kFixedInvalid where invalid
  std::vector<std::int32_t> combined_q8;                   // unwrapped, frequency-weighted
  std::array<std::vector<std::int32_t>, 2> features_q16;   // d16 - d120, d80 - d120 (wrapped depths)
  std::vector<std::uint8_t> flags;                         // as DecodedFrame::flags
};

FixedDecodedFrame decode_frame_fixed(const std::int16_t* raw, const FixedDecodeTables& tables,
                                     const DecodeOptions& options = {}, FixedKernel kernel = FixedKernel::kBest);
// The same into `out`, whose buffers are reused (no allocation once sized:
// what a stream of frames wants).
void decode_frame_fixed(const std::int16_t* raw, const FixedDecodeTables& tables, FixedDecodedFrame& out,
                        const DecodeOptions& options = {}, FixedKernel kernel = FixedKernel::kBest);
// Only the pixels of `region` (raw and tables are the full frame's).
FixedDecodedFrame decode_region_fixed(const std::int16_t* raw, int width, int height, const FixedDecodeTables& tables,
                                      const PixelRegion& region, const DecodeOptions& options = {},
                                      FixedKernel kernel = FixedKernel::kBest);
// The same into `out`, whose buffers are reused (a handheld ROI decoded every
// frame: its planes are not allocated again).
void decode_region_fixed(const std::int16_t* raw, int width, int height, const FixedDecodeTables& tables,
                         const PixelRegion& region, FixedDecodedFrame& out, const DecodeOptions& options = {},
                         FixedKernel kernel = FixedKernel::kBest);

// The phase/amplitude kernels over n pixels of one group: samples m0, m1, m2
// (the group's three sub-images), p0 in Q32 turns; writes phase (Q32 turns),
// amplitude (Q8 counts) and ORs kDecodeSaturated into flags where a sample is
// 32767. Exposed for the bit-exactness tests.
void phase_amplitude_scalar(const std::int16_t* m0, const std::int16_t* m1, const std::int16_t* m2,
                            const std::uint32_t* p0, std::size_t n, std::uint32_t* phase, std::uint32_t* amp_q8,
                            std::uint8_t* flags);
#if defined(__aarch64__)
void phase_amplitude_neon(const std::int16_t* m0, const std::int16_t* m1, const std::int16_t* m2,
                          const std::uint32_t* p0, std::size_t n, std::uint32_t* phase, std::uint32_t* amp_q8,
                          std::uint8_t* flags);
#endif
#if defined(__x86_64__)
// Only on a CPU with AVX2 (cpu_has_avx2()).
void phase_amplitude_avx2(const std::int16_t* m0, const std::int16_t* m1, const std::int16_t* m2,
                          const std::uint32_t* p0, std::size_t n, std::uint32_t* phase, std::uint32_t* amp_q8,
                          std::uint8_t* flags);
#endif

// The finishing stage (per-frequency depths, unwrapping, flags, combined
// depth, features) of n pixels whose phase and amplitude are done, over
// plane pointers; every output is written (kFixedInvalid where flagged).
// Thresholds are DecodeOptions in the decode's units: amplitudes Q8 counts
// (rounded up), gaps Q16 mm (rounded down; -1: every gap fails).
struct FixedThresholds {
  std::uint32_t amp, mean_sum, unwrap_amp;
  std::int64_t gap_16_80, gap_80_120;
};
FixedThresholds fixed_thresholds(const DecodeOptions& options);
struct FixedPlanes {
  std::uint32_t* phase[3];
  std::uint32_t* amp[3];
  std::uint8_t* flags;  // in: saturation; out: every flag
  std::int32_t* depth[3];
  std::int32_t* combined;
  std::int32_t* features[2];
};
void finish_pixels_scalar(const FixedPlanes& planes, std::size_t n, const FixedThresholds& th);

// Pixels [first, first + n) of a full frame (raw and tables are the whole
// frame's) decoded into caller-owned planes of n values each: the pieces a
// tiled consumer (PixelClassifier::classify_frame) keeps in cache.
void decode_pixels_fixed(const std::int16_t* raw, const FixedDecodeTables& tables, std::size_t first, std::size_t n,
                         const FixedThresholds& th, const FixedPlanes& out, FixedKernel kernel = FixedKernel::kBest);
// Sizes every plane of `out` for `pixels` (a reused frame keeps its buffers),
// and the planes of `frame` from pixel `first` on (throws
// std::invalid_argument beyond the frame): for a consumer that decodes a
// frame in pieces (rows split over threads) with decode_pixels_fixed.
void size_fixed_frame(FixedDecodedFrame& out, std::size_t pixels);
FixedPlanes planes_of(FixedDecodedFrame& frame, std::size_t first);
// The same planes from pixel `first` on (a kernel's scalar tail).
FixedPlanes planes_from(const FixedPlanes& planes, std::size_t first);
#if defined(__x86_64__)
void finish_pixels_avx2(const FixedPlanes& planes, std::size_t n, const FixedThresholds& th);  // AVX2 CPUs only
#endif
#if defined(__aarch64__)
void finish_pixels_neon(const FixedPlanes& planes, std::size_t n, const FixedThresholds& th);
#endif

// The CORDIC's constants, shared by both kernels.
namespace fixed_decode_detail {
// round(atan(2^-i) / (2 pi) * 2^32), i = 0..5 (computed at 50 digits).
inline constexpr std::array<std::uint32_t, kCordicSteps> kAtanTurns = {536870912u, 316933406u, 167458907u,
                                                                       85004756u,  42667331u,  21354465u};
inline constexpr float kThirdF = 1.0f / 3.0f;
// 2^32 / (2 pi) as a float (683565248, 4e-8 relative off): the residual's radians to Q32 turns.
inline constexpr float kTurnsPerRadF = static_cast<float>(4294967296.0 / 6.283185307179586476925);
// sqrt(3) / 2 in Q31 (the imaginary part's factor; vqrdmulh's operand).
inline constexpr std::int32_t kHalfSqrt3Q31 = 1859775393;
// 256 / (3 K) in Q25, K the gain of the 6 CORDIC steps: amplitude_q8 = x' * kAmpScale >> (25 + shift),
// x' the magnitude corrected for the residual angle.
inline constexpr int kAmpScaleBits = 25;
extern const std::uint32_t kAmpScale;
// The unwrap's divisions without a divide (AVX2 has none): floor(m / R) =
// (m * magic) >> shift for every 0 <= m < 2^14 (FixedDecode.UnwrapDivisionMagicIsExact).
struct DivisionMagic {
  std::int32_t range_mm, magic;
  int shift;
};
inline constexpr DivisionMagic kDiv80{1875, 2237, 22}, kDiv120{1250, 6711, 23};
// round(2 a b / 2^32): vqrdmulhq_s32 on one lane (no saturation: b > -2^31).
inline std::int32_t rounding_doubling_mul_high(std::int32_t a, std::int32_t b) {
  return static_cast<std::int32_t>((2 * static_cast<std::int64_t>(a) * b + (std::int64_t{1} << 31)) >> 32);
}
}  // namespace fixed_decode_detail

}  // namespace tofmat
