// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The AVX2 kernel of the depth-bin index (fixed_depth_bins.hpp; the scalar
// kernel is its definition): eight pixels a step, the same indices. Compiled
// with a target attribute; called only when the CPU reports AVX2.
#include "tofmat/core/fixed_depth_bins.hpp"

#if defined(__x86_64__)
#include <immintrin.h>

namespace tofmat {

__attribute__((target("avx2"))) void bin_indices_avx2(const std::int32_t* depth_q8, const std::uint8_t* flags,
                                                      std::size_t n, const FixedBinning& b, std::int32_t* bin) {
  const __m256i start = _mm256_set1_epi32(b.start_q8);
  const __m256i inv = _mm256_set1_epi32(b.inv_width);
  const __m256i count = _mm256_set1_epi32(static_cast<std::int32_t>(b.count));
  const __m256i invalid = _mm256_set1_epi32(kFixedInvalid);
  const __m256i none = _mm256_set1_epi32(-1);
  const __m256i zero = _mm256_setzero_si256();
  std::size_t i = 0;
  for (; i + 8 <= n; i += 8) {
    const __m256i d = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(depth_q8 + i));
    const __m256i f = _mm256_cvtepu8_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(flags + i)));
    // depth - start >= 0 as a 33-bit quantity is depth >= start; then the
    // difference is exact as an unsigned 32-bit value (< 2^32).
    const __m256i below = _mm256_cmpgt_epi32(start, d);
    const __m256i off = _mm256_sub_epi32(d, start);
    // j = (off * inv_width) >> 32 (unsigned off < 2^32, inv_width < 2^30): the high halves.
    const __m256i even = _mm256_srli_epi64(_mm256_mul_epu32(off, inv), 32);
    const __m256i odd = _mm256_mul_epu32(_mm256_srli_epi64(off, 32), inv);
    const __m256i j = _mm256_blend_epi32(even, odd, 0xAA);  // < 2^30
    const __m256i bad = _mm256_or_si256(_mm256_or_si256(below, _mm256_cmpeq_epi32(d, invalid)),
                                        _mm256_or_si256(_mm256_xor_si256(_mm256_cmpeq_epi32(f, zero), none),
                                                        _mm256_xor_si256(_mm256_cmpgt_epi32(count, j), none)));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(bin + i), _mm256_blendv_epi8(j, none, bad));
  }
  if (i < n) bin_indices_scalar(depth_q8 + i, flags + i, n - i, b, bin + i);
}

}  // namespace tofmat
#endif
