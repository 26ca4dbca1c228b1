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

inline constexpr int kWeightBits = 15;  // robust weights in Q15: an inlier's is 2^15

// The normal equations' sums over a row's elements with their weights W
// (Q15): sum W a_s a_t (lower triangle, Q15 x Q28; |W a| <= 2^29, each term
// within 2^43, over 2^16 elements within 2^59) and sum W e a_s (|W e| < 2^31,
// each term within 2^45, the sum within 2^61). Integers: exact in any order.
struct NormalSums {
  std::int64_t G[kSessionMaxTerms][kSessionMaxTerms] = {};
  std::int64_t h[kSessionMaxTerms] = {};
  bool operator==(const NormalSums& o) const;
};

// What a reweighting pass leaves, over the residuals
// r_i = e_i 2^16 - round(sum_s B_s a_s,i / 2^14) (Q16 steps) of the fit B, an
// inlier when |r_i| <= threshold (T): the data term's sums, and (when asked)
// what the next pass's weights take from the normal equations of all
// elements at weight 1: Huber's weight of an outlier is
// W_i = nearest(T 2^15 / |r_i|) (in double) in Q15, and `shortfall` sums its
// shortfall D_i = 2^15 - W_i (0 for an inlier) as NormalSums does W.
struct SessionPassSums {
  std::uint64_t squares = 0;  // inliers' round(|r| / 2^8)^2 (Q16 steps -> Q8, squared), saturating
  std::int64_t beyond = 0;    // outliers' |r|: <= 2^43 each, within 2^59
  std::int64_t n_beyond = 0;
  NormalSums shortfall;
};

// a + b, held at UINT64_MAX instead of wrapping: a sum that large only says
// the candidate explains nothing (all terms >= 0: the result is min(max, sum)
// in any order, so lanes may add apart).
inline std::uint64_t add_saturating(std::uint64_t a, std::uint64_t b) {
  return b > std::numeric_limits<std::uint64_t>::max() - a ? std::numeric_limits<std::uint64_t>::max() : a + b;
}

// Which kernel runs the passes: session_pass_neon is session_pass_scalar to the bit.
using SessionPassFn = SessionPassSums (*)(const SessionElements& x, int k, const std::int64_t* B,
                                          std::int64_t threshold, bool next);

// A pass for k terms (0..3) with the coefficients B (Q16, |B| <= 2^40),
// threshold in [0, 2^60]; next: also the shortfall's sums (else they stay 0).
SessionPassSums session_pass_scalar(const SessionElements& x, int k, const std::int64_t* B, std::int64_t threshold,
                                    bool next);
// sum_i e_i a_t,i for the k terms into h[0..k) (|e a| <= 2^30 over 2^16
// elements: within 2^46): the first pass's right-hand side, all weights 1.
using SessionMomentsFn = void (*)(const SessionElements& x, int k, std::int64_t* h);
void session_moments_scalar(const SessionElements& x, int k, std::int64_t* h);
#if defined(__aarch64__)
void session_moments_neon(const SessionElements& x, int k, std::int64_t* h);
SessionPassSums session_pass_neon(const SessionElements& x, int k, const std::int64_t* B, std::int64_t threshold,
                                  bool next);
#endif

}  // namespace tofmat::session_detail
