// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The session matcher's small solve, shared by its float reference and its
// fixed-point path (internal: session_classifier.cpp, fixed_session_classifier.cpp).
#pragma once

#include <array>
#include <cmath>

#include "tofmat/core/session_classifier.hpp"

namespace tofmat::session_detail {

constexpr int kMaxTerms = kSessionMaxTerms;

// log det P from the diagonal of P's Cholesky factor (cholesky_factor_solve):
// twice the log of the diagonal's product, one log where there are three
// (a candidate's row costs a few hundred instructions of which the logs were
// half); the logs of each term where the product leaves the normal range.
inline double cholesky_log_det(const std::array<double, kMaxTerms>& diagonal, int k) {
  double product = 1.0;
  for (int i = 0; i < k; ++i) product *= diagonal[i];
  if (std::isnormal(product)) return 2.0 * std::log(product);
  double logdet = 0.0;
  for (int i = 0; i < k; ++i) logdet += 2.0 * std::log(diagonal[i]);
  return logdet;
}

// Solves the K x K symmetric positive definite system P beta = b (K <= 3) by
// Cholesky; writes the factor's diagonal (for cholesky_log_det: a caller
// that solves several times takes the logs of the last solve only).
inline void cholesky_factor_solve(std::array<std::array<double, kMaxTerms>, kMaxTerms> P, int k,
                                  const std::array<double, kMaxTerms>& b, std::array<double, kMaxTerms>& beta,
                                  std::array<double, kMaxTerms>& diagonal) {
  std::array<std::array<double, kMaxTerms>, kMaxTerms> L{};
  for (int i = 0; i < k; ++i) {
    for (int j = 0; j <= i; ++j) {
      double s = P[i][j];
      for (int m = 0; m < j; ++m) s -= L[i][m] * L[j][m];
      if (i == j) {
        // P = (prior precision, > 0) + a Gram matrix: positive definite.
        L[i][i] = std::sqrt(s);
        diagonal[i] = L[i][i];
      } else {
        L[i][j] = s / L[j][j];
      }
    }
  }
  std::array<double, kMaxTerms> y{};
  for (int i = 0; i < k; ++i) {
    double s = b[i];
    for (int m = 0; m < i; ++m) s -= L[i][m] * y[m];
    y[i] = s / L[i][i];
  }
  for (int i = k - 1; i >= 0; --i) {
    double s = y[i];
    for (int m = i + 1; m < k; ++m) s -= L[m][i] * beta[m];
    beta[i] = s / L[i][i];
  }
}

// cholesky_factor_solve, returning log det P.
inline double cholesky_solve(const std::array<std::array<double, kMaxTerms>, kMaxTerms>& P, int k,
                             const std::array<double, kMaxTerms>& b, std::array<double, kMaxTerms>& beta) {
  std::array<double, kMaxTerms> diagonal{};
  cholesky_factor_solve(P, k, b, beta, diagonal);
  return cholesky_log_det(diagonal, k);
}

}  // namespace tofmat::session_detail
