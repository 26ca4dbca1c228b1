// The NEON kernel of the fixed-point phase and amplitude (aarch64 only; the
// scalar kernel in fixed_decode.cpp is its definition): four pixels a step,
// the CORDIC's branch replaced by selects, the same integers bit for bit.
#include "tofmat/core/fixed_decode.hpp"

#if defined(__aarch64__)
#include <arm_neon.h>

#include <utility>

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
    const int32x4_t a0 = vmovl_s16(vld1_s16(m0 + i));
    const int32x4_t a1 = vmovl_s16(vld1_s16(m1 + i));
    const int32x4_t a2 = vmovl_s16(vld1_s16(m2 + i));
    const uint32x4_t saturated = vorrq_u32(vorrq_u32(vceqq_s32(a0, sat), vceqq_s32(a1, sat)), vceqq_s32(a2, sat));
    if (vmaxvq_u32(saturated)) {  // rare: flag the lanes one by one
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

}  // namespace tofmat
#endif
