// The NEON kernel of squared_sum (aarch64 only; see fixed_distance.hpp).
// Per block of 8: a validity byte becomes a lane mask (vtst against the bit
// of each lane), absolute differences widen to uint32 (vabdl), square in
// uint32 (no wrap: < 2^32), are masked, and pairwise-add into uint64 lanes.
#include "tofmat/core/fixed_distance.hpp"

#if defined(__aarch64__)
#include <arm_neon.h>

namespace tofmat {

SquaredSum squared_sum_neon(const std::int16_t* q, const std::uint8_t* qmask, const std::int16_t* e,
                            const std::uint8_t* emask, std::size_t blocks) {
  static const std::uint16_t kLaneBits[8] = {1, 2, 4, 8, 16, 32, 64, 128};
  const uint16x8_t lane_bits = vld1q_u16(kLaneBits);
  uint64x2_t acc = vdupq_n_u64(0);
  std::uint32_t count = 0;
  for (std::size_t b = 0; b < blocks; ++b) {
    const unsigned m = emask ? (qmask[b] & emask[b]) : qmask[b];
    if (m == 0) continue;
    count += static_cast<std::uint32_t>(__builtin_popcount(m));
    const uint16x8_t lanes = vtstq_u16(vdupq_n_u16(static_cast<std::uint16_t>(m)), lane_bits);
    const int16x8_t qv = vld1q_s16(q + b * 8);
    const int16x8_t ev = vld1q_s16(e + b * 8);
    uint32x4_t lo = vreinterpretq_u32_s32(vabdl_s16(vget_low_s16(qv), vget_low_s16(ev)));
    uint32x4_t hi = vreinterpretq_u32_s32(vabdl_high_s16(qv, ev));
    lo = vmulq_u32(lo, lo);
    hi = vmulq_u32(hi, hi);
    // 0xFFFF lanes widen (as signed) to 0xFFFFFFFF.
    lo = vandq_u32(lo, vreinterpretq_u32_s32(vmovl_s16(vreinterpret_s16_u16(vget_low_u16(lanes)))));
    hi = vandq_u32(hi, vreinterpretq_u32_s32(vmovl_high_s16(vreinterpretq_s16_u16(lanes))));
    acc = vpadalq_u32(acc, lo);
    acc = vpadalq_u32(acc, hi);
  }
  SquaredSum out;
  out.sum = vgetq_lane_u64(acc, 0) + vgetq_lane_u64(acc, 1);
  out.count = count;
  return out;
}

}  // namespace tofmat
#endif
