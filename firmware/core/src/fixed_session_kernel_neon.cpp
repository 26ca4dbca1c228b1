// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The session matcher's reweighting pass with NEON, two elements a step in
// int64 lanes (fixed_session_kernel.hpp): the same sums as the scalar pass
// to the bit (every sum is of integers, or saturating sums of non-negative
// ones, so the lanes' order of addition does not matter; the weight's double
// division and ties-to-even conversion are the scalar's).
#if defined(__aarch64__)
#include <arm_neon.h>

#include "fixed_session_kernel.hpp"

namespace tofmat::session_detail {
namespace {

// B_t a_t summed over the terms, exactly: B (|B| <= 2^40) split as
// hi 2^21 + lo with lo in [0, 2^21), so that both halves multiply the Q14
// basis in 32 x 32 -> 64-bit lanes (each sum within 2^36; hi 2^21 within 2^56).
template <int K>
inline int64x2_t fit_of(const int32x2_t (&a)[kSessionMaxTerms], const std::int32_t (&hi)[kSessionMaxTerms],
                        const std::int32_t (&lo)[kSessionMaxTerms]) {
  int64x2_t h = vdupq_n_s64(0), l = vdupq_n_s64(0);
  for (int t = 0; t < K; ++t) {
    h = vmlal_s32(h, a[t], vdup_n_s32(hi[t]));
    l = vmlal_s32(l, a[t], vdup_n_s32(lo[t]));
  }
  return vaddq_s64(vshlq_n_s64(h, 21), l);
}

template <int K, bool Next>
SessionPassSums pass(const SessionElements& x, const std::int64_t* B, std::int64_t threshold) {
  std::int32_t hi[kSessionMaxTerms] = {}, lo[kSessionMaxTerms] = {};
  for (int t = 0; t < K; ++t) {
    hi[t] = static_cast<std::int32_t>(B[t] >> 21);  // floor: |B| <= 2^40 -> |hi| <= 2^19
    lo[t] = static_cast<std::int32_t>(B[t] - (std::int64_t{hi[t]} * (std::int64_t{1} << 21)));
  }
  const int64x2_t T = vdupq_n_s64(threshold);
  const float64x2_t tw = vdupq_n_f64(static_cast<double>(threshold) * (1 << kWeightBits));
  const int64x2_t one = vdupq_n_s64(std::int64_t{1} << kWeightBits);
  const uint64x2_t u32max = vdupq_n_u64(0xffffffffu);
  uint64x2_t squares = vdupq_n_u64(0);
  int64x2_t beyond = vdupq_n_s64(0), n_beyond = vdupq_n_s64(0);
  int64x2_t G[kSessionMaxTerms][kSessionMaxTerms], h[kSessionMaxTerms];
  for (int u = 0; u < K; ++u) {
    h[u] = vdupq_n_s64(0);
    for (int t = 0; t <= u; ++t) G[u][t] = vdupq_n_s64(0);
  }
  std::size_t i = 0;
  for (; i + 2 <= x.n; i += 2) {
    const int32x2_t e = vld1_s32(x.e + i);
    int32x2_t a[kSessionMaxTerms];
    for (int t = 0; t < K; ++t) a[t] = vld1_s32(x.a[t] + i);
    const int64x2_t rounded = vrshrq_n_s64(fit_of<K>(a, hi, lo), kBasisBits);  // (fit + 2^13) >> 14
    const int64x2_t mag = vabsq_s64(vsubq_s64(vshll_n_s32(e, kFitBits), rounded));
    const uint64x2_t out = vcgtq_s64(mag, T);
    beyond = vaddq_s64(beyond, vandq_s64(mag, vreinterpretq_s64_u64(out)));
    n_beyond = vsubq_s64(n_beyond, vreinterpretq_s64_u64(out));  // out: -1 in an outlier's lane
    // Inliers: round(|r| / 2^8)^2, all ones (saturated) past 2^32 - 1.
    const uint64x2_t q8 = vrshrq_n_u64(vreinterpretq_u64_s64(mag), 8);  // (|r| + 128) >> 8
    const uint32x2_t q8_lo = vmovn_u64(q8);
    const uint64x2_t sq = vorrq_u64(vmull_u32(q8_lo, q8_lo), vcgtq_u64(q8, u32max));
    squares = vqaddq_u64(squares, vbicq_u64(sq, out));
    if (Next && vmaxvq_u32(vreinterpretq_u32_u64(out)) != 0) {
      // The outliers' weight shortfall 2^15 - nearest(T 2^15 / |r|); 0 in an inlier's lane.
      const int64x2_t w = vcvtnq_s64_f64(vdivq_f64(tw, vcvtq_f64_s64(mag)));
      const int32x2_t d = vmovn_s64(vandq_s64(vsubq_s64(one, w), vreinterpretq_s64_u64(out)));
      const int32x2_t de = vmul_s32(d, e);
      for (int u = 0; u < K; ++u) {
        const int32x2_t da = vmul_s32(d, a[u]);
        h[u] = vmlal_s32(h[u], de, a[u]);
        for (int t = 0; t <= u; ++t) G[u][t] = vmlal_s32(G[u][t], da, a[t]);
      }
    }
  }
  SessionPassSums s;
  if (i < x.n) {  // the odd element: the scalar pass over it alone
    SessionElements tail = x;
    tail.e = x.e + i;
    for (int t = 0; t < K; ++t) tail.a[t] = x.a[t] + i;
    tail.n = x.n - i;
    s = session_pass_scalar(tail, K, B, threshold, Next);
  }
  s.squares = add_saturating(add_saturating(s.squares, vgetq_lane_u64(squares, 0)), vgetq_lane_u64(squares, 1));
  s.beyond += vaddvq_s64(beyond);
  s.n_beyond += vaddvq_s64(n_beyond);
  if (Next) {
    for (int u = 0; u < K; ++u) {
      s.shortfall.h[u] += vaddvq_s64(h[u]);
      for (int t = 0; t <= u; ++t) s.shortfall.G[u][t] += vaddvq_s64(G[u][t]);
    }
  }
  return s;
}

template <int K>
SessionPassSums pass(const SessionElements& x, const std::int64_t* B, std::int64_t threshold, bool next) {
  return next ? pass<K, true>(x, B, threshold) : pass<K, false>(x, B, threshold);
}

}  // namespace

void session_moments_neon(const SessionElements& x, int k, std::int64_t* h) {
  for (int t = 0; t < k; ++t) {
    int64x2_t sum = vdupq_n_s64(0);
    std::size_t i = 0;
    for (; i + 4 <= x.n; i += 4) {
      const int32x4_t e = vld1q_s32(x.e + i), a = vld1q_s32(x.a[t] + i);
      sum = vmlal_s32(sum, vget_low_s32(e), vget_low_s32(a));
      sum = vmlal_high_s32(sum, e, a);
    }
    std::int64_t total = vaddvq_s64(sum);
    for (; i < x.n; ++i) total += std::int64_t{x.e[i]} * x.a[t][i];
    h[t] = total;
  }
}

SessionPassSums session_pass_neon(const SessionElements& x, int k, const std::int64_t* B, std::int64_t threshold,
                                  bool next) {
  switch (k) {
    case 0: return pass<0, false>(x, B, threshold);
    case 1: return pass<1>(x, B, threshold, next);
    case 2: return pass<2>(x, B, threshold, next);
    default: return pass<3>(x, B, threshold, next);
  }
}

}  // namespace tofmat::session_detail
#endif
