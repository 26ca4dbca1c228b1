// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The box mean's NEON kernels (aarch64 only; the scalar ones in
// frame_smoothing.cpp are their definition): four columns or pixels a step,
// the same integers bit for bit.
#include "frame_smoothing_kernels.hpp"

#if defined(__aarch64__)
#include <arm_neon.h>

#include <cstdint>

#include "tofmat/core/fixed_decode.hpp"

namespace tofmat::smoothing_detail {
namespace {

// 0xFFFFFFFF where the pixel's flag is 0 (valid), for four flags.
uint32x4_t valid_mask(const std::uint8_t* flags) {
  std::uint32_t f;
  __builtin_memcpy(&f, flags, sizeof f);
  const uint8x8_t b = vreinterpret_u8_u32(vdup_n_u32(f));
  return vceqzq_u32(vmovl_u16(vget_low_u16(vmovl_u8(b))));
}

// (v + 128) >> 8 of the valid lanes, 0 elsewhere (vrshrq: the rounding shift
// has the headroom the scalar's int64 has).
int32x4_t q8_where(const std::int32_t* v, uint32x4_t valid) {
  return vreinterpretq_s32_u32(vandq_u32(vreinterpretq_u32_s32(vrshrq_n_s32(vld1q_s32(v), 8)), valid));
}

template <bool In, bool Out>
void slide(const BoxRows& rows, std::size_t w, const BoxColumns& c) {
  std::size_t x = 0;
  for (; x + 4 <= w; x += 4) {
    int32x4_t c0 = vld1q_s32(c.col0 + x), c1 = vld1q_s32(c.col1 + x), cn = vld1q_s32(c.coln + x);
    if (In) {
      const uint32x4_t ok = valid_mask(rows.in_flags + x);
      c0 = vaddq_s32(c0, q8_where(rows.in0 + x, ok));
      c1 = vaddq_s32(c1, q8_where(rows.in1 + x, ok));
      cn = vsubq_s32(cn, vreinterpretq_s32_u32(ok));  // (-1 where valid)
    }
    if (Out) {
      const uint32x4_t ok = valid_mask(rows.out_flags + x);
      c0 = vsubq_s32(c0, q8_where(rows.out0 + x, ok));
      c1 = vsubq_s32(c1, q8_where(rows.out1 + x, ok));
      cn = vaddq_s32(cn, vreinterpretq_s32_u32(ok));
    }
    vst1q_s32(c.col0 + x, c0);
    vst1q_s32(c.col1 + x, c1);
    vst1q_s32(c.coln + x, cn);
  }
  if (x < w) {  // the last columns: the scalar kernel over what is left
    BoxRows rest;
    if (In) rest.in0 = rows.in0 + x, rest.in1 = rows.in1 + x, rest.in_flags = rows.in_flags + x;
    if (Out) rest.out0 = rows.out0 + x, rest.out1 = rows.out1 + x, rest.out_flags = rows.out_flags + x;
    const BoxColumns tail{c.col0 + x, c.col1 + x, c.coln + x, nullptr, nullptr, nullptr};
    box_slide_scalar(rest, w - x, tail);
  }
}

// Inclusive prefix sum of four lanes plus the running total before them.
uint32x4_t scan4(uint32x4_t v, uint32x4_t carry) {
  const uint32x4_t zero = vdupq_n_u32(0);
  v = vaddq_u32(v, vextq_u32(zero, v, 3));  // + the lane before
  v = vaddq_u32(v, vextq_u32(zero, v, 2));  // + the two before
  return vaddq_u32(v, carry);
}

}  // namespace

void box_slide_neon(const BoxRows& rows, std::size_t w, const BoxColumns& c) {
  const bool in = rows.in0 != nullptr, out = rows.out0 != nullptr;
  if (in && out) return slide<true, true>(rows, w, c);
  if (in) return slide<true, false>(rows, w, c);
  if (out) return slide<false, true>(rows, w, c);
}

void box_prefix_neon(std::size_t w, std::size_t r, const BoxColumns& c) {
  std::size_t k = 0;
  for (; k <= r; ++k) c.pre0[k] = c.pre1[k] = c.pren[k] = 0;
  uint32x4_t a0 = vdupq_n_u32(0), a1 = a0, an = a0;  // the totals so far, in every lane
  std::size_t x = 0;
  for (; x + 4 <= w; x += 4, k += 4) {
    const uint32x4_t p0 = scan4(vreinterpretq_u32_s32(vld1q_s32(c.col0 + x)), a0);
    const uint32x4_t p1 = scan4(vreinterpretq_u32_s32(vld1q_s32(c.col1 + x)), a1);
    const uint32x4_t pn = scan4(vreinterpretq_u32_s32(vld1q_s32(c.coln + x)), an);
    vst1q_u32(c.pre0 + k, p0);
    vst1q_u32(c.pre1 + k, p1);
    vst1q_u32(c.pren + k, pn);
    a0 = vdupq_laneq_u32(p0, 3);
    a1 = vdupq_laneq_u32(p1, 3);
    an = vdupq_laneq_u32(pn, 3);
  }
  std::uint32_t s0 = vgetq_lane_u32(a0, 0), s1 = vgetq_lane_u32(a1, 0), sn = vgetq_lane_u32(an, 0);
  for (; x < w; ++x, ++k) {
    c.pre0[k] = s0 += static_cast<std::uint32_t>(c.col0[x]);
    c.pre1[k] = s1 += static_cast<std::uint32_t>(c.col1[x]);
    c.pren[k] = sn += static_cast<std::uint32_t>(c.coln[x]);
  }
  for (; k < w + 2 * r + 1; ++k) c.pre0[k] = s0, c.pre1[k] = s1, c.pren[k] = sn;
}

void box_means_neon(std::size_t w, std::size_t r, const BoxColumns& c, const std::uint8_t* flags, std::int32_t* out0,
                    std::int32_t* out1) {
  const std::size_t span = 2 * r + 1;
  const float64x2_t one = vdupq_n_f64(1.0), half = vdupq_n_f64(0.5), bias = vdupq_n_f64(kMeanBiasF),
                    k256 = vdupq_n_f64(256.0);
  const int64x2_t bias_int = vdupq_n_s64(kMeanBias);
  const int32x4_t lowest = vdupq_n_s32(INT32_MIN + 1), invalid = vdupq_n_s32(kFixedInvalid);
  const auto to_f64 = [](int32x2_t v) { return vcvtq_f64_s64(vmovl_s32(v)); };
  int32x4_t last_n = vdupq_n_s32(0);  // (no count is 0: the first step computes them)
  float64x2_t inv[2] = {one, one}, half_n[2] = {one, one};
  std::size_t x = 0;
  for (; x + 4 <= w; x += 4) {
    const auto window = [&](const std::uint32_t* pre) {
      return vreinterpretq_s32_u32(vsubq_u32(vld1q_u32(pre + x + span), vld1q_u32(pre + x)));
    };
    const int32x4_t n = vmaxq_s32(window(c.pren), vdupq_n_s32(1));
    // The counts' reciprocals and offsets, again only where the counts
    // changed (inside a valid region every window is full: they rarely do).
    if (vmaxvq_u32(vreinterpretq_u32_s32(veorq_s32(n, last_n))) != 0) {
      last_n = n;
      const int32x4_t halves = vshrq_n_s32(n, 1);
      const float64x2_t nd[2] = {to_f64(vget_low_s32(n)), to_f64(vget_high_s32(n))};
      for (int j = 0; j < 2; ++j) {
        inv[j] = vdivq_f64(one, nd[j]);
        const float64x2_t h = to_f64(j == 0 ? vget_low_s32(halves) : vget_high_s32(halves));
        half_n[j] = vaddq_f64(vaddq_f64(h, half), vmulq_f64(nd[j], bias));
      }
    }
    const auto means = [&](int32x4_t s) {
      int64x2_t q[2];
      for (int j = 0; j < 2; ++j) {
        const float64x2_t sd = to_f64(j == 0 ? vget_low_s32(s) : vget_high_s32(s));
        const float64x2_t num = vaddq_f64(vmulq_f64(k256, sd), half_n[j]);
        q[j] = vsubq_s64(vcvtq_s64_f64(vmulq_f64(num, inv[j])), bias_int);
      }
      return vmaxq_s32(vcombine_s32(vqmovn_s64(q[0]), vqmovn_s64(q[1])), lowest);
    };
    const uint32x4_t ok = valid_mask(flags + x);
    vst1q_s32(out0 + x, vbslq_s32(ok, means(window(c.pre0)), invalid));
    vst1q_s32(out1 + x, vbslq_s32(ok, means(window(c.pre1)), invalid));
  }
  if (x < w) {
    // The last pixels: the scalar kernel, on prefix arrays offset to them.
    const BoxColumns tail{nullptr, nullptr, nullptr, c.pre0 + x, c.pre1 + x, c.pren + x};
    box_means_scalar(w - x, r, tail, flags + x, out0 + x, out1 + x);
  }
}

}  // namespace tofmat::smoothing_detail

#endif
