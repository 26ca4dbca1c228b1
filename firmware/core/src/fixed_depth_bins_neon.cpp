// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The NEON kernel of bin_indices (aarch64 only; the scalar one in
// fixed_depth_bins.cpp is its definition): four pixels a step.
#include "tofmat/core/fixed_depth_bins.hpp"

#if defined(__aarch64__)
#include <arm_neon.h>

namespace tofmat {

void bin_indices_neon(const std::int32_t* depth_q8, const std::uint8_t* flags, std::size_t n, const FixedBinning& b,
                      std::int32_t* bin) {
  const int64x2_t start = vdupq_n_s64(b.start_q8);
  const int32x2_t inv = vdup_n_s32(b.inv_width);
  const int64x2_t count = vdupq_n_s64(b.count);
  const int32x4_t invalid = vdupq_n_s32(kFixedInvalid);
  std::size_t i = 0;
  for (; i + 4 <= n; i += 4) {
    const int32x4_t d = vld1q_s32(depth_q8 + i);
    // Offsets in int64 (as the scalar kernel), times the inverse width, >> 32.
    const int64x2_t off_lo = vsubq_s64(vmovl_s32(vget_low_s32(d)), start);
    const int64x2_t off_hi = vsubq_s64(vmovl_high_s32(d), start);
    // off < 2^32 and inv <= 2^30: the product fits; the high half of a 64 x 32
    // product as (off_hi32 * inv << 32 + off_lo32 * inv) >> 32, exactly.
    const auto bins_of = [&](int64x2_t off) {
      const uint32x2_t lo32 = vmovn_u64(vreinterpretq_u64_s64(off));
      const int32x2_t hi32 = vmovn_s64(vshrq_n_s64(off, 32));
      const int64x2_t p_lo = vreinterpretq_s64_u64(vmull_u32(lo32, vreinterpret_u32_s32(inv)));
      const int64x2_t p_hi = vmull_s32(hi32, inv);
      const int64x2_t j = vaddq_s64(p_hi, vshrq_n_s64(p_lo, 32));  // (off * inv) >> 32 (floor)
      // -1 where off < 0 or j >= count.
      const uint64x2_t ok = vandq_u64(vcgezq_s64(off), vcltq_s64(j, count));
      return vmovn_s64(vbslq_s64(ok, j, vdupq_n_s64(-1)));
    };
    int32x4_t j = vcombine_s32(bins_of(off_lo), bins_of(off_hi));
    // Flags (uint8) widened to 32-bit lanes; invalid depths.
    const std::uint32_t fl[4] = {flags[i], flags[i + 1], flags[i + 2], flags[i + 3]};
    const uint32x4_t bad = vorrq_u32(vtstq_u32(vld1q_u32(fl), vld1q_u32(fl)), vceqq_s32(d, invalid));
    j = vbslq_s32(bad, vdupq_n_s32(-1), j);
    vst1q_s32(bin + i, j);
  }
  if (i < n) bin_indices_scalar(depth_q8 + i, flags + i, n - i, b, bin + i);
}

}  // namespace tofmat
#endif
