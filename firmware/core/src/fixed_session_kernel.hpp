// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The session matcher's per-element work on the fixed-point path (internal:
// fixed_session_classifier.cpp and its NEON kernel). A row's compared
// elements are held as structure of arrays (the difference query - candidate
// in steps, and each nuisance term's Legendre basis value in Q14), so that a
// pass over them is one tight loop (and two int64 lanes a NEON instruction).
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include "tofmat/core/session_classifier.hpp"

namespace tofmat::session_detail {

inline constexpr int kBasisBits = 14;  // basis values in Q14: |a| <= 2^14
inline constexpr int kFitBits = 16;    // nuisance coefficients and residuals in Q16 steps

// The compared elements of one candidate's row.
struct SessionElements {
  const std::int32_t* e = nullptr;               // query - candidate, steps: |e| <= 65534
  const std::int32_t* a[kSessionMaxTerms] = {};  // per term, the basis value of each element's bin
  std::size_t n = 0;                             // at most 65535
};

// What a reweighting pass leaves: the data term's sums over the residuals
// r_i = e_i 2^16 - round(sum_s B_s a_s,i / 2^14) (Q16 steps), an inlier when
// |r_i| <= threshold, and the outliers (increasing i) with their |r_i|.
struct SessionPassSums {
  std::uint64_t squares = 0;  // inliers' round(|r| / 2^8)^2 (Q16 steps -> Q8, squared), saturating
  std::int64_t beyond = 0;    // outliers' |r|: <= 2^43 each, within 2^59
  std::int64_t n_beyond = 0;
};

// a + b, held at UINT64_MAX instead of wrapping: a sum that large only says
// the candidate explains nothing (all terms >= 0: the result is min(max, sum)
// in any order, so lanes may add apart).
inline std::uint64_t add_saturating(std::uint64_t a, std::uint64_t b) {
  return b > std::numeric_limits<std::uint64_t>::max() - a ? std::numeric_limits<std::uint64_t>::max() : a + b;
}

// A pass of the residuals for k terms with the coefficients B (Q16, |B| <=
// 2^40): the sums, and the outliers' indices and magnitudes (cleared first).
// Scalar; session_pass_neon is the same to the bit.
SessionPassSums session_pass_scalar(const SessionElements& x, int k, const std::int64_t* B, std::int64_t threshold,
                                    std::vector<std::uint32_t>& outliers, std::vector<std::int64_t>& magnitudes);
#if defined(__aarch64__)
SessionPassSums session_pass_neon(const SessionElements& x, int k, const std::int64_t* B, std::int64_t threshold,
                                  std::vector<std::uint32_t>& outliers, std::vector<std::int64_t>& magnitudes);
#endif

}  // namespace tofmat::session_detail
