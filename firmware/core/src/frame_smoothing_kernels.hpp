// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The box mean's three steps per output row (frame_smoothing.cpp): internal
// to the core. The scalar kernels are the definition; the NEON ones
// (frame_smoothing_neon.cpp, aarch64) give the same integers bit for bit.
#pragma once
#include <cstddef>
#include <cstdint>

namespace tofmat::smoothing_detail {

// One row of the frame entering the columns' sums and one leaving them
// (either may be absent: nullptr planes): per column x, with
// q8(v) = (v + 128) >> 8 (|q8| <= 2^23, so 225 of them sum within int32) of
// each valid (flag 0) pixel, col += q8(in) - q8(out), coln += valid(in) - valid(out).
struct BoxRows {
  const std::int32_t* in0 = nullptr;
  const std::int32_t* in1 = nullptr;
  const std::uint8_t* in_flags = nullptr;
  const std::int32_t* out0 = nullptr;
  const std::int32_t* out1 = nullptr;
  const std::uint8_t* out_flags = nullptr;
};
struct BoxColumns {
  std::int32_t* col0;
  std::int32_t* col1;
  std::int32_t* coln;
  std::uint32_t* pre0;  // w + 2r + 1 each
  std::uint32_t* pre1;
  std::uint32_t* pren;
};

void box_slide_scalar(const BoxRows& rows, std::size_t w, const BoxColumns& c);
// The columns' prefix sums modulo 2^32, padded: pre[k] = sum of col[x] for
// x < clamp(k - r, 0, w), k in [0, w + 2r + 1).
void box_prefix_scalar(std::size_t w, std::size_t r, const BoxColumns& c);
// Per pixel x of a row: S = pre[x + 2r + 1] - pre[x] (window sum), n likewise
// (at least 1); mean = floor((256 S + floor(n / 2)) / n) computed as
// trunc((256 S + floor(n / 2) + 1/2 + n 2^31) x (1 / n)) - 2^31 in binary64
// (each step exact or rounded once, none fused), clamped to
// [INT32_MIN + 1, INT32_MAX]; kFixedInvalid where the pixel's flag is not 0.
void box_means_scalar(std::size_t w, std::size_t r, const BoxColumns& c, const std::uint8_t* flags, std::int32_t* out0,
                      std::int32_t* out1);

#if defined(__aarch64__)
void box_slide_neon(const BoxRows& rows, std::size_t w, const BoxColumns& c);
void box_prefix_neon(std::size_t w, std::size_t r, const BoxColumns& c);
void box_means_neon(std::size_t w, std::size_t r, const BoxColumns& c, const std::uint8_t* flags, std::int32_t* out0,
                    std::int32_t* out1);
#endif

// The mean's bias (2^31 per pixel of the window: above any |256 S| / n, so
// that the numerator is positive and truncation is floor).
inline constexpr std::int64_t kMeanBias = std::int64_t{1} << 31;
inline constexpr double kMeanBiasF = 2147483648.0;

}  // namespace tofmat::smoothing_detail
