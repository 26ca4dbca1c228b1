// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The NEON kernel of the fixed-point phase and amplitude (aarch64 only; the
// scalar kernel in fixed_decode.cpp is its definition): four pixels a step,
// the CORDIC's branch replaced by selects, the same integers bit for bit.
#include "tofmat/core/fixed_decode.hpp"

#if defined(__aarch64__)
#include <arm_neon.h>

#include <algorithm>
#include <cstring>
#include <utility>

#include "tofmat/core/decode.hpp"
#include "tofmat/core/raw_lut.hpp"

namespace tofmat {
namespace {

// One CORDIC step with the shift as an immediate: the steps are unrolled
// (no loop counter, no shift or angle registers to rebuild each step).
template <int K>
inline void cordic_step(int32x4_t& x, int32x4_t& y, uint32x4_t& angle) {
  int32x4_t xs = x, ys = y;
  if constexpr (K > 0) {
    xs = vshrq_n_s32(x, K);
    ys = vshrq_n_s32(y, K);
  }
  const uint32x4_t up = vcgezq_s32(y);
  const uint32x4_t turn = vdupq_n_u32(fixed_decode_detail::kAtanTurns[K]);
  x = vaddq_s32(x, vbslq_s32(up, ys, vnegq_s32(ys)));
  y = vaddq_s32(y, vbslq_s32(up, vnegq_s32(xs), xs));
  angle = vbslq_u32(up, vaddq_u32(angle, turn), vsubq_u32(angle, turn));
}

template <int... K>
inline void cordic(int32x4_t& x, int32x4_t& y, uint32x4_t& angle, std::integer_sequence<int, K...>) {
  (cordic_step<K>(x, y, angle), ...);
}

}  // namespace

void phase_amplitude_neon(const std::int16_t* m0, const std::int16_t* m1, const std::int16_t* m2,
                          const std::uint32_t* p0, std::size_t n, std::uint32_t* phase, std::uint32_t* amp_q8,
                          std::uint8_t* flags) {
  using namespace fixed_decode_detail;
  const int32x4_t sat = vdupq_n_s32(kRawSaturated);
  std::size_t i = 0;
  for (; i + 4 <= n; i += 4) {
    const int16x4_t l0 = vld1_s16(m0 + i), l1 = vld1_s16(m1 + i), l2 = vld1_s16(m2 + i);
    const int32x4_t a0 = vmovl_s16(l0), a1 = vmovl_s16(l1), a2 = vmovl_s16(l2);
    // (kRawSaturated is the largest int16: a saturated sample is the maximum)
    static_assert(kRawSaturated == INT16_MAX, "saturation is found by the samples' maximum");
    if (vmaxv_s16(vmax_s16(vmax_s16(l0, l1), l2)) == kRawSaturated) {  // rare: flag the lanes one by one
      const uint32x4_t saturated = vorrq_u32(vorrq_u32(vceqq_s32(a0, sat), vceqq_s32(a1, sat)), vceqq_s32(a2, sat));
      std::uint32_t s[4];
      vst1q_u32(s, saturated);
      for (int l = 0; l < 4; ++l) {
        if (s[l]) flags[i + static_cast<std::size_t>(l)] |= kDecodeSaturated;
      }
    }
    const int32x4_t X = vsubq_s32(vsubq_s32(vshlq_n_s32(a0, 1), a1), a2);
    const int32x4_t W = vsubq_s32(a2, a1);
    const uint32x4_t none = vandq_u32(vceqzq_s32(X), vceqzq_s32(W));
    const uint32x4_t mx =
        vorrq_u32(vmaxq_u32(vreinterpretq_u32_s32(vabsq_s32(X)), vreinterpretq_u32_s32(vabsq_s32(W))), vdupq_n_u32(1));
    const int32x4_t sh = vmaxq_s32(vsubq_s32(vreinterpretq_s32_u32(vclzq_u32(mx)), vdupq_n_s32(4)), vdupq_n_s32(0));
    int32x4_t x = vshlq_s32(X, sh);
    int32x4_t y = vshlq_n_s32(vqrdmulhq_n_s32(vshlq_s32(W, sh), kHalfSqrt3Q31), 1);
    const uint32x4_t left = vcltzq_s32(x);
    x = vbslq_s32(left, vnegq_s32(x), x);
    y = vbslq_s32(left, vnegq_s32(y), y);
    uint32x4_t angle = vandq_u32(left, vdupq_n_u32(0x80000000u));
    cordic(x, y, angle, std::make_integer_sequence<int, kCordicSteps>{});
    // The residual angle and the magnitude as the scalar kernel: FDIV is
    // correctly rounded, FCVTNS rounds to nearest even, and this file builds
    // with -ffp-contract=off (no FMLS in place of the product and difference).
    const float32x4_t xf = vcvtq_f32_s32(x);
    const float32x4_t t = vdivq_f32(vcvtq_f32_s32(y), xf);
    const float32x4_t t2 = vmulq_f32(t, t);
    const float32x4_t r = vsubq_f32(t, vmulq_n_f32(vmulq_f32(t, t2), kThirdF));
    angle = vaddq_u32(angle, vreinterpretq_u32_s32(vcvtnq_s32_f32(vmulq_n_f32(r, kTurnsPerRadF))));
    x = vaddq_s32(x, vcvtnq_s32_f32(vmulq_n_f32(vmulq_f32(xf, t2), 0.5f)));
    const uint32x4_t ph = vsubq_u32(angle, vld1q_u32(p0 + i));
    vst1q_u32(phase + i, vbicq_u32(ph, none));
    // amplitude_q8 = x * kAmpScale >> (25 + sh), in 64-bit lanes.
    const uint32x4_t xu = vreinterpretq_u32_s32(x);
    const int32x4_t rshift = vnegq_s32(vaddq_s32(sh, vdupq_n_s32(kAmpScaleBits)));
    const uint64x2_t lo = vshlq_u64(vmull_n_u32(vget_low_u32(xu), kAmpScale), vmovl_s32(vget_low_s32(rshift)));
    const uint64x2_t hi = vshlq_u64(vmull_high_n_u32(xu, kAmpScale), vmovl_high_s32(rshift));
    vst1q_u32(amp_q8 + i, vbicq_u32(vcombine_u32(vmovn_u64(lo), vmovn_u64(hi)), none));
  }
  if (i < n) phase_amplitude_scalar(m0 + i, m1 + i, m2 + i, p0 + i, n - i, phase + i, amp_q8 + i, flags + i);
}

// The finishing stage, four pixels a step, as finish_pixels_scalar (and the
// AVX2 kernel): the same integers bit for bit.
void finish_pixels_neon(const FixedPlanes& p, std::size_t n, const FixedThresholds& th) {
  using fixed_decode_detail::kDiv120;
  using fixed_decode_detail::kDiv80;
  static_assert(kDiv80.shift == 22 && kDiv120.shift == 23, "the shifts below are immediates");
  const int32x4_t invalid = vdupq_n_s32(kFixedInvalid);
  const uint32x4_t th_amp = vdupq_n_u32(th.amp), th_mean = vdupq_n_u32(th.mean_sum),
                   th_unwrap = vdupq_n_u32(th.unwrap_amp);
  // Gaps are < 2^31: a threshold beyond is never exceeded; -1 always is.
  const int32x4_t th_gap1 = vdupq_n_s32(static_cast<std::int32_t>(std::min<std::int64_t>(th.gap_16_80, 0x7FFFFFFF)));
  const int32x4_t th_gap2 = vdupq_n_s32(static_cast<std::int32_t>(std::min<std::int64_t>(th.gap_80_120, 0x7FFFFFFF)));
  constexpr std::uint32_t kRange[3] = {1875, 9375, 1250};
  constexpr std::int32_t R80 = 1875 << 16, R120 = 1250 << 16;
  std::size_t i = 0;
  for (; i + 4 <= n; i += 4) {
    int32x4_t d[3];
    uint32x4_t a[3], dark = vdupq_n_u32(0);
    for (std::size_t g = 0; g < 3; ++g) {
      // (phase * R) >> 16 < 2^30: the 64-bit products, shifted and narrowed.
      const uint32x4_t ph = vld1q_u32(p.phase[g] + i);
      const uint32x4_t dg = vcombine_u32(vshrn_n_u64(vmull_n_u32(vget_low_u32(ph), kRange[g]), 16),
                                         vshrn_n_u64(vmull_high_n_u32(ph, kRange[g]), 16));
      d[g] = vreinterpretq_s32_u32(dg);
      a[g] = vld1q_u32(p.amp[g] + i);
      dark = vorrq_u32(dark, vcltq_u32(a[g], th_amp));
    }
    // (amplitudes are below 2^23, docs/numerics.md: their sum fits 32 bits)
    dark = vorrq_u32(dark, vcltq_u32(vaddq_u32(vaddq_u32(a[0], a[1]), a[2]), th_mean));
    std::uint32_t f4;
    std::memcpy(&f4, p.flags + i, sizeof f4);
    uint32x4_t flags = vmovl_u16(vget_low_u16(vmovl_u8(vreinterpret_u8_u32(vdup_n_u32(f4)))));
    flags = vorrq_u32(flags, vandq_u32(dark, vdupq_n_u32(kDecodeDark)));
    const uint32x4_t bad = vtstq_u32(flags, flags);
    // Unwrap (as the scalar code; k80 + 1 and k120 + 2 are the quotients of
    // positive dividends, by the exact multiply-and-shift of DivisionMagic).
    const int32x4_t D16 = d[kGroup16];
    const uint32x4_t n1 = vreinterpretq_u32_s32(vaddq_s32(vsubq_s32(D16, d[kGroup80]), vdupq_n_s32(R80 / 2 + R80)));
    const int32x4_t k80 =
        vsubq_s32(vreinterpretq_s32_u32(
                      vshrq_n_u32(vmulq_n_u32(vshrq_n_u32(n1, 16), static_cast<std::uint32_t>(kDiv80.magic)), 22)),
                  vdupq_n_s32(1));
    const int32x4_t D80 = vmlaq_n_s32(d[kGroup80], k80, R80);
    const uint32x4_t n2 =
        vreinterpretq_u32_s32(vaddq_s32(vsubq_s32(D80, d[kGroup120]), vdupq_n_s32(R120 / 2 + 2 * R120)));
    const int32x4_t k120 =
        vsubq_s32(vreinterpretq_s32_u32(
                      vshrq_n_u32(vmulq_n_u32(vshrq_n_u32(n2, 16), static_cast<std::uint32_t>(kDiv120.magic)), 23)),
                  vdupq_n_s32(2));
    const int32x4_t D120 = vmlaq_n_s32(d[kGroup120], k120, R120);
    const int32x4_t gap1 = vabsq_s32(vsubq_s32(D80, D16)), gap2 = vabsq_s32(vsubq_s32(D120, D80));
    const uint32x4_t unwrap_bad = vbicq_u32(
        vorrq_u32(vcltq_u32(a[kGroup16], th_unwrap), vorrq_u32(vcgtq_s32(gap1, th_gap1), vcgtq_s32(gap2, th_gap2))),
        bad);
    flags = vbslq_u32(unwrap_bad, vdupq_n_u32(kDecodeUnwrap), flags);
    const uint32x4_t off = vorrq_u32(bad, unwrap_bad);
    for (std::size_t g = 0; g < 3; ++g) vst1q_s32(p.depth[g] + i, vbslq_s32(off, invalid, d[g]));
    // num8 = (10 D80 + 2 D16 + 15 D120) >> 8 in 64-bit lanes, then
    // (num8 * ceil(2^32 / 27)) >> 32: the high half of a signed product.
    const auto num8 = [&](int32x2_t d80, int32x2_t d16, int32x2_t d120) {
      int64x2_t s = vmull_n_s32(d80, 10);
      s = vmlal_n_s32(s, d16, 2);
      s = vmlal_n_s32(s, d120, 15);
      return vshrq_n_s64(s, kDepthFracBits - kCombinedFracBits);
    };
    const int64x2_t lo = num8(vget_low_s32(D80), vget_low_s32(D16), vget_low_s32(D120));
    const int64x2_t hi = num8(vget_high_s32(D80), vget_high_s32(D16), vget_high_s32(D120));
    // (|num8| < 2^31 as in the scalar code's int32 result)
    const int32x4_t n8 = vcombine_s32(vmovn_s64(lo), vmovn_s64(hi));
    const int32x4_t combined = vcombine_s32(vshrn_n_s64(vmull_n_s32(vget_low_s32(n8), 159072863), 32),
                                            vshrn_n_s64(vmull_high_n_s32(n8, 159072863), 32));
    vst1q_s32(p.combined + i, vbslq_s32(off, invalid, combined));
    vst1q_s32(p.features[0] + i, vbslq_s32(off, invalid, vsubq_s32(d[kGroup16], d[kGroup120])));
    vst1q_s32(p.features[1] + i, vbslq_s32(off, invalid, vsubq_s32(d[kGroup80], d[kGroup120])));
    const uint8x8_t fb = vmovn_u16(vcombine_u16(vmovn_u32(flags), vdup_n_u16(0)));
    f4 = vget_lane_u32(vreinterpret_u32_u8(fb), 0);
    std::memcpy(p.flags + i, &f4, sizeof f4);
  }
  if (i < n) finish_pixels_scalar(planes_from(p, i), n - i, th);  // the tail
}

}  // namespace tofmat
#endif
