// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The session matcher's per-element work on the fixed-point path (internal:
// fixed_session_classifier.cpp and its NEON kernel). A row's compared
// elements are held as structure of arrays (the difference query - candidate
// in steps, and each nuisance term's Legendre basis value), so that a pass
// over them is one tight loop, and four int32 lanes a NEON instruction.
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>

#include "tofmat/core/session_classifier.hpp"

namespace tofmat::session_detail {

inline constexpr int kBasisBits = 14;   // the normal equations' basis in Q14: |a| <= 2^14
inline constexpr int kFitBits = 8;      // nuisance coefficients and residuals in Q8 steps
inline constexpr int kWeightBits = 15;  // robust weights in Q15: an inlier's is 2^15
// The coefficients' bound, Q8 steps (2^20 steps, metres): a fit's value
// then stays within 3 x 2^28 and a residual within 2^30 + 2^24 < 2^31.
inline constexpr std::int32_t kMaxCoefficient = std::int32_t{1} << 28;
inline constexpr std::int32_t kNoThreshold = std::numeric_limits<std::int32_t>::max();  // beyond every residual

// Arrays are padded to a multiple of this many elements (a NEON kernel reads
// the last block whole and leaves out its lanes past n).
inline constexpr std::size_t kSessionBlock = 4;
inline std::size_t session_padded(std::size_t n) { return (n + kSessionBlock - 1) / kSessionBlock * kSessionBlock; }

// The compared elements of one candidate's row (each array readable for
// session_padded(n) elements). Term 0 may be the offset
// (Legendre degree 0, the value 1 everywhere): the fit adds its coefficient
// as it is (`constant`); the others' fit basis is Q31 (|P1|, |P2| < 1 at the
// bins' centres), multiplied as NEON's rounding doubling high half does:
// (2 B f + 2^31) >> 32 = round(B f / 2^31).
struct SessionElements {
  const std::int32_t* e = nullptr;               // query - candidate, steps: |e| <= 65534
  const std::int32_t* a[kSessionMaxTerms] = {};  // per term, the Q14 basis of each element's bin
  const std::int32_t* f[kSessionMaxTerms] = {};  // per term, the Q31 basis (unused for a constant term 0)
  bool constant = false;                         // term 0 is the offset
  std::size_t n = 0;                             // at most 65535
};

// B f / 2^31 rounded, as vqrdmulhq_s32 (|B| <= 2^28, |f| < 2^31: no saturation).
inline std::int32_t fit_product(std::int32_t B, std::int32_t f) {
  return static_cast<std::int32_t>((std::int64_t{2} * B * f + (std::int64_t{1} << 31)) >> 32);
}

// The normal equations' sums over a row's elements with their weights W
// (Q15): sum W a_s a_t (lower triangle, Q15 x Q28; |W a| <= 2^29, each term
// within 2^43, over 2^16 elements within 2^59) and sum W e a_s (|W e| < 2^31,
// each term within 2^45, the sum within 2^61). Integers: exact in any order.
struct NormalSums {
  std::int64_t G[kSessionMaxTerms][kSessionMaxTerms] = {};
  std::int64_t h[kSessionMaxTerms] = {};
  bool operator==(const NormalSums& o) const;
};

// What a reweighting pass leaves, over the residuals r_i = e_i 2^8 - fit_i
// (Q8 steps; fit_i = sum_t B_t basis_t,i as SessionElements says) of the
// coefficients B, an inlier when |r_i| <= threshold (T): the data term's
// sums, and (when asked) what the next pass's weights take from the normal
// equations of all elements at weight 1: Huber's weight of an outlier is
// W_i = nearest(T 2^15 / |r_i|) in Q15, computed in binary32 (the quotient of
// the two values rounded to binary32, ties to even), and `shortfall` sums its
// shortfall D_i = 2^15 - W_i (0 for an inlier) as NormalSums does W.
struct SessionPassSums {
  std::uint64_t squares = 0;  // inliers' |r|^2 (Q16 steps^2, each < 2^62), saturating
  std::int64_t beyond = 0;    // outliers' |r|: < 2^31 each, within 2^47
  std::int64_t n_beyond = 0;
  NormalSums shortfall;
};

// a + b, held at UINT64_MAX instead of wrapping: a sum that large only says
// the candidate explains nothing (all terms >= 0: the result is min(max, sum)
// in any order, so lanes may add apart).
inline std::uint64_t add_saturating(std::uint64_t a, std::uint64_t b) {
  return b > std::numeric_limits<std::uint64_t>::max() - a ? std::numeric_limits<std::uint64_t>::max() : a + b;
}

// A pass kernel's instantiation for the run-time number of terms (0..3),
// constant term 0 and next: Kernel::run<K, Constant, Next>(x, B, threshold).
template <class Kernel, int K, bool Constant>
SessionPassSums dispatch_next(const SessionElements& x, const std::int32_t* B, std::int32_t threshold, bool next) {
  if (next) return Kernel::template run<K, Constant, true>(x, B, threshold);
  return Kernel::template run<K, Constant, false>(x, B, threshold);
}

template <class Kernel, int K>
SessionPassSums dispatch_terms(const SessionElements& x, const std::int32_t* B, std::int32_t threshold, bool next) {
  if (x.constant) return dispatch_next<Kernel, K, true>(x, B, threshold, next);
  return dispatch_next<Kernel, K, false>(x, B, threshold, next);
}

template <class Kernel>
SessionPassSums dispatch_pass(const SessionElements& x, int k, const std::int32_t* B, std::int32_t threshold,
                              bool next) {
  switch (k) {
    case 0: return Kernel::template run<0, false, false>(x, B, threshold);  // no terms: nothing to fit or weigh
    case 1: return dispatch_terms<Kernel, 1>(x, B, threshold, next);
    case 2: return dispatch_terms<Kernel, 2>(x, B, threshold, next);
    default: return dispatch_terms<Kernel, 3>(x, B, threshold, next);
  }
}

// Which kernel runs the passes: session_pass_neon is session_pass_scalar to the bit.
using SessionPassFn = SessionPassSums (*)(const SessionElements& x, int k, const std::int32_t* B,
                                          std::int32_t threshold, bool next);

// A pass for k terms (0..3) with the coefficients B (Q8, |B| <= 2^28),
// threshold in [0, 2^31 - 1]; next: also the shortfall's sums (else they stay 0).
SessionPassSums session_pass_scalar(const SessionElements& x, int k, const std::int32_t* B, std::int32_t threshold,
                                    bool next);
// sum_i e_i a_t,i (Q14 basis) for the k terms into h[0..k) (|e a| <= 2^30
// over 2^16 elements: within 2^46): the first pass's right-hand side, all weights 1.
using SessionMomentsFn = void (*)(const SessionElements& x, int k, std::int64_t* h);
void session_moments_scalar(const SessionElements& x, int k, std::int64_t* h);
// The kernels to run: the vector ones where this build has them (NEON on aarch64), or the scalar ones.
SessionPassFn session_pass(bool vector);
SessionMomentsFn session_moments(bool vector);
#if defined(__aarch64__)
void session_moments_neon(const SessionElements& x, int k, std::int64_t* h);
SessionPassSums session_pass_neon(const SessionElements& x, int k, const std::int32_t* B, std::int32_t threshold,
                                  bool next);
#endif

}  // namespace tofmat::session_detail
