// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The session matcher's reweighting pass, scalar (fixed_session_kernel.hpp).
#include <cstdlib>

#include "fixed_session_kernel.hpp"

namespace tofmat::session_detail {
namespace {

template <int K>
SessionPassSums pass(const SessionElements& x, const std::int64_t* B, std::int64_t threshold,
                     std::vector<std::uint32_t>& outliers, std::vector<std::int64_t>& magnitudes) {
  SessionPassSums s;
  for (std::size_t i = 0; i < x.n; ++i) {
    // The fit in Q16 steps from the coefficients in Q16 (|B a| <= 2^54): residuals within 2^43.
    std::int64_t fit = 0;
    for (int t = 0; t < K; ++t) fit += B[t] * x.a[t][i];
    const std::int64_t rounded = (fit + (std::int64_t{1} << (kBasisBits - 1))) >> kBasisBits;
    const std::int64_t mag = std::llabs(std::int64_t{x.e[i]} * (std::int64_t{1} << kFitBits) - rounded);
    if (mag > threshold) {
      s.beyond += mag;
      ++s.n_beyond;
      outliers.push_back(static_cast<std::uint32_t>(i));
      magnitudes.push_back(mag);
      continue;
    }
    const auto q8 = static_cast<std::uint64_t>((mag + 128) >> 8);  // <= 2^35
    s.squares = add_saturating(s.squares, q8 > 0xffffffffu ? std::numeric_limits<std::uint64_t>::max() : q8 * q8);
  }
  return s;
}

}  // namespace

SessionPassSums session_pass_scalar(const SessionElements& x, int k, const std::int64_t* B, std::int64_t threshold,
                                    std::vector<std::uint32_t>& outliers, std::vector<std::int64_t>& magnitudes) {
  outliers.clear();
  magnitudes.clear();
  switch (k) {
    case 0: return pass<0>(x, B, threshold, outliers, magnitudes);
    case 1: return pass<1>(x, B, threshold, outliers, magnitudes);
    case 2: return pass<2>(x, B, threshold, outliers, magnitudes);
    default: return pass<3>(x, B, threshold, outliers, magnitudes);
  }
}

}  // namespace tofmat::session_detail
