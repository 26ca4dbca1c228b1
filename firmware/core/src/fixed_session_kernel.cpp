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

template <int K, bool Next>
SessionPassSums pass(const SessionElements& x, const std::int64_t* B, std::int64_t threshold) {
  SessionPassSums s;
  const double tw = static_cast<double>(threshold) * (1 << kWeightBits);  // T 2^15
  for (std::size_t i = 0; i < x.n; ++i) {
    // The fit in Q16 steps from the coefficients in Q16 (|B a| <= 2^54): residuals within 2^43.
    std::int64_t fit = 0;
    for (int t = 0; t < K; ++t) fit += B[t] * x.a[t][i];
    const std::int64_t rounded = (fit + (std::int64_t{1} << (kBasisBits - 1))) >> kBasisBits;
    const std::int64_t mag = std::llabs(std::int64_t{x.e[i]} * (std::int64_t{1} << kFitBits) - rounded);
    if (mag > threshold) {
      s.beyond += mag;
      ++s.n_beyond;
      if (Next) {
        // The weight's shortfall from an inlier's: 2^15 - nearest(T 2^15 / |r|) (ties to
        // even, as the NEON conversion), in (0, 2^15] as |r| > T.
        const std::int32_t d =
            (1 << kWeightBits) - static_cast<std::int32_t>(std::nearbyint(tw / static_cast<double>(mag)));
        const std::int32_t de = d * x.e[i];
        for (int u = 0; u < K; ++u) {
          const std::int32_t da = d * x.a[u][i];
          s.shortfall.h[u] += std::int64_t{de} * x.a[u][i];
          for (int t = 0; t <= u; ++t) s.shortfall.G[u][t] += std::int64_t{da} * x.a[t][i];
        }
      }
      continue;
    }
    const auto q8 = static_cast<std::uint64_t>((mag + 128) >> 8);  // <= 2^35
    s.squares = add_saturating(s.squares, q8 > 0xffffffffu ? std::numeric_limits<std::uint64_t>::max() : q8 * q8);
  }
  return s;
}

template <int K>
SessionPassSums pass(const SessionElements& x, const std::int64_t* B, std::int64_t threshold, bool next) {
  return next ? pass<K, true>(x, B, threshold) : pass<K, false>(x, B, threshold);
}

}  // namespace

void session_moments_scalar(const SessionElements& x, int k, std::int64_t* h) {
  for (int t = 0; t < k; ++t) {
    std::int64_t sum = 0;
    for (std::size_t i = 0; i < x.n; ++i) sum += std::int64_t{x.e[i]} * x.a[t][i];
    h[t] = sum;
  }
}

SessionPassSums session_pass_scalar(const SessionElements& x, int k, const std::int64_t* B, std::int64_t threshold,
                                    bool next) {
  switch (k) {
    case 0: return pass<0, false>(x, B, threshold);
    case 1: return pass<1>(x, B, threshold, next);
    case 2: return pass<2>(x, B, threshold, next);
    default: return pass<3>(x, B, threshold, next);
  }
}

}  // namespace tofmat::session_detail
