// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The session matcher's small solve, shared by its float reference and its
// fixed-point path (internal: session_classifier.cpp, fixed_session_classifier.cpp).
#pragma once

#include <array>
#include <cmath>

#include "tofmat/core/session_classifier.hpp"

namespace tofmat::session_detail {

constexpr int kMaxTerms = kSessionMaxTerms;

// Solves the K x K symmetric positive definite system P beta = b (K <= 3) by
// Cholesky; returns log det P.
inline double cholesky_solve(std::array<std::array<double, kMaxTerms>, kMaxTerms> P, int k,
                             const std::array<double, kMaxTerms>& b, std::array<double, kMaxTerms>& beta) {
  std::array<std::array<double, kMaxTerms>, kMaxTerms> L{};
  double logdet = 0.0;
  for (int i = 0; i < k; ++i) {
    for (int j = 0; j <= i; ++j) {
      double s = P[i][j];
      for (int m = 0; m < j; ++m) s -= L[i][m] * L[j][m];
      if (i == j) {
        // P = (prior precision, > 0) + a Gram matrix: positive definite.
        L[i][i] = std::sqrt(s);
        logdet += 2.0 * std::log(L[i][i]);
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
  return logdet;
}

}  // namespace tofmat::session_detail
