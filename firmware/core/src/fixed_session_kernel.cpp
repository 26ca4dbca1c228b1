// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The session matcher's reweighting pass, scalar (fixed_session_kernel.hpp).
#include <cmath>
#include <cstdlib>

#include "fixed_session_kernel.hpp"

namespace tofmat::session_detail {

bool NormalSums::operator==(const NormalSums& o) const {
  for (int s = 0; s < kSessionMaxTerms; ++s) {
    if (h[s] != o.h[s]) return false;
    for (int t = 0; t < kSessionMaxTerms; ++t)
      if (G[s][t] != o.G[s][t]) return false;
  }
  return true;
}

namespace {

template <int K, bool Constant, bool Next>
SessionPassSums pass(const SessionElements& x, const std::int32_t* B, std::int32_t threshold) {
  SessionPassSums s;
  const float tw = static_cast<float>(threshold) * static_cast<float>(1 << kWeightBits);  // T 2^15
  for (std::size_t i = 0; i < x.n; ++i) {
    std::int32_t fit = 0;
    for (int t = 0; t < K; ++t) fit += Constant && t == 0 ? B[0] : fit_product(B[t], x.f[t][i]);
    const std::int32_t mag = std::abs(x.e[i] * (1 << kFitBits) - fit);  // < 2^31
    if (mag > threshold) {
      s.beyond += mag;
      ++s.n_beyond;
      if (Next) {
        // 2^15 - nearest(T 2^15 / |r|) in binary32 (nearbyint: ties to even, as NEON's
        // conversion), in [0, 2^15] as |r| > T.
        const float w = std::nearbyint(tw / static_cast<float>(mag));
        const std::int32_t d = (1 << kWeightBits) - static_cast<std::int32_t>(w);
        const std::int32_t de = d * x.e[i];
        for (int u = 0; u < K; ++u) {
          const std::int32_t da = d * x.a[u][i];
          s.shortfall.h[u] += std::int64_t{de} * x.a[u][i];
          for (int t = 0; t <= u; ++t) s.shortfall.G[u][t] += std::int64_t{da} * x.a[t][i];
        }
      }
      continue;
    }
    s.squares = add_saturating(s.squares, static_cast<std::uint64_t>(std::int64_t{mag} * mag));
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

void session_moments_scalar(const SessionElements& x, int k, std::int64_t* h) {
  for (int t = 0; t < k; ++t) {
    std::int64_t sum = 0;
    for (std::size_t i = 0; i < x.n; ++i) sum += std::int64_t{x.e[i]} * x.a[t][i];
    h[t] = sum;
  }
}

#if defined(__aarch64__)
SessionPassFn session_pass(bool vector) { return vector ? session_pass_neon : session_pass_scalar; }
SessionMomentsFn session_moments(bool vector) { return vector ? session_moments_neon : session_moments_scalar; }
#else
SessionPassFn session_pass(bool) { return session_pass_scalar; }
SessionMomentsFn session_moments(bool) { return session_moments_scalar; }
#endif

SessionPassSums session_pass_scalar(const SessionElements& x, int k, const std::int32_t* B, std::int32_t threshold,
                                    bool next) {
  return dispatch_pass<Kernel>(x, k, B, threshold, next);
}

}  // namespace tofmat::session_detail
