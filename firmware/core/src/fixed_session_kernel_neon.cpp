// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The session matcher's reweighting pass with NEON, four elements a step in
// int32 lanes (fixed_session_kernel.hpp), the last block's padding lanes
// masked: the same sums as the scalar pass to the bit. Every sum is of integers, or a saturating sum of non-negative
// ones, so the lanes' order of addition does not matter; the fit's products are vqrdmulhq_s32, which fit_product
// defines; the weight's binary32 division and ties-to-even conversion are the scalar's.
#if defined(__aarch64__)
#include <arm_neon.h>

#include "fixed_session_kernel.hpp"

namespace tofmat::session_detail {
namespace {

template <int K, bool Constant, bool Next>
SessionPassSums pass(const SessionElements& x, const std::int32_t* B, std::int32_t threshold) {
  int32x4_t b[kSessionMaxTerms];
  for (int t = 0; t < K; ++t) b[t] = vdupq_n_s32(B[t]);
  const int32x4_t T = vdupq_n_s32(threshold);
  const float32x4_t tw = vdupq_n_f32(static_cast<float>(threshold) * static_cast<float>(1 << kWeightBits));
  const int32x4_t one = vdupq_n_s32(1 << kWeightBits);
  uint64x2_t squares = vdupq_n_u64(0), beyond = vdupq_n_u64(0);
  int32x4_t n_beyond = vdupq_n_s32(0);  // per lane at most 2^14 outliers
  int64x2_t G[kSessionMaxTerms][kSessionMaxTerms], h[kSessionMaxTerms];
  for (int u = 0; u < K; ++u) {
    h[u] = vdupq_n_s64(0);
    for (int t = 0; t <= u; ++t) G[u][t] = vdupq_n_s64(0);
  }
  // Four elements from i; a lane at or past n (the last block's padding) counts for nothing.
  const auto step = [&](std::size_t i, uint32x4_t lanes) {
    const int32x4_t e = vld1q_s32(x.e + i);
    int32x4_t fit = Constant ? b[0] : vdupq_n_s32(0);
    for (int t = Constant ? 1 : 0; t < K; ++t) fit = vaddq_s32(fit, vqrdmulhq_s32(b[t], vld1q_s32(x.f[t] + i)));
    const int32x4_t mag = vabsq_s32(vsubq_s32(vshlq_n_s32(e, kFitBits), fit));
    const uint32x4_t out = vandq_u32(vcgtq_s32(mag, T), lanes);
    const uint32x4_t umag = vreinterpretq_u32_s32(mag);
    beyond = vpadalq_u32(beyond, vandq_u32(umag, out));
    n_beyond = vsubq_s32(n_beyond, vreinterpretq_s32_u32(out));  // out: -1 in an outlier's lane
    const uint32x4_t in = vandq_u32(vbicq_u32(umag, out), lanes);
    squares = vqaddq_u64(squares, vmull_u32(vget_low_u32(in), vget_low_u32(in)));
    squares = vqaddq_u64(squares, vmull_high_u32(in, in));
    if (Next && vmaxvq_u32(out) != 0) {
      // The outliers' weight shortfall 2^15 - nearest(T 2^15 / |r|); 0 in an inlier's lane.
      const int32x4_t w = vcvtnq_s32_f32(vdivq_f32(tw, vcvtq_f32_s32(mag)));
      const int32x4_t d = vandq_s32(vsubq_s32(one, w), vreinterpretq_s32_u32(out));
      const int32x4_t de = vmulq_s32(d, e);
      int32x4_t a[kSessionMaxTerms];
      for (int t = 0; t < K; ++t) a[t] = vld1q_s32(x.a[t] + i);
      for (int u = 0; u < K; ++u) {
        const int32x4_t da = vmulq_s32(d, a[u]);
        h[u] = vmlal_high_s32(vmlal_s32(h[u], vget_low_s32(de), vget_low_s32(a[u])), de, a[u]);
        for (int t = 0; t <= u; ++t)
          G[u][t] = vmlal_high_s32(vmlal_s32(G[u][t], vget_low_s32(da), vget_low_s32(a[t])), da, a[t]);
      }
    }
  };
  std::size_t i = 0;
  for (; i + 4 <= x.n; i += 4) step(i, vdupq_n_u32(0xffffffffu));
  if (i < x.n) {
    static const std::uint32_t kLane[4] = {0, 1, 2, 3};
    step(i, vcltq_u32(vld1q_u32(kLane), vdupq_n_u32(static_cast<std::uint32_t>(x.n - i))));
  }
  SessionPassSums s;
  s.squares = add_saturating(add_saturating(s.squares, vgetq_lane_u64(squares, 0)), vgetq_lane_u64(squares, 1));
  s.beyond += static_cast<std::int64_t>(vaddvq_u64(beyond));
  s.n_beyond += vaddvq_s32(n_beyond);
  if (Next) {
    for (int u = 0; u < K; ++u) {
      s.shortfall.h[u] += vaddvq_s64(h[u]);
      for (int t = 0; t <= u; ++t) s.shortfall.G[u][t] += vaddvq_s64(G[u][t]);
    }
  }
  return s;
}

struct Kernel {
  template <int K, bool Constant, bool Next>
  static SessionPassSums run(const SessionElements& x, const std::int32_t* B, std::int32_t threshold) {
    return pass<K, Constant, Next>(x, B, threshold);
  }
};

}  // namespace

void session_moments_neon(const SessionElements& x, int k, std::int64_t* h) {
  for (int t = 0; t < k; ++t) {
    int64x2_t sum = vdupq_n_s64(0);
    std::size_t i = 0;
    for (; i + 4 <= x.n; i += 4) {
      const int32x4_t e = vld1q_s32(x.e + i), a = vld1q_s32(x.a[t] + i);
      sum = vmlal_high_s32(vmlal_s32(sum, vget_low_s32(e), vget_low_s32(a)), e, a);
    }
    std::int64_t total = vaddvq_s64(sum);
    for (; i < x.n; ++i) total += std::int64_t{x.e[i]} * x.a[t][i];
    h[t] = total;
  }
}

SessionPassSums session_pass_neon(const SessionElements& x, int k, const std::int32_t* B, std::int32_t threshold,
                                  bool next) {
  return dispatch_pass<Kernel>(x, k, B, threshold, next);
}

}  // namespace tofmat::session_detail
#endif
