// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The session-robust matcher (session_classifier.hpp) on the fixed-point
// path: the query quantised to the table's step and the table held as a
// CompactTable (as FixedClassifier's), the per-element work in integers
// (differences in steps, the Legendre basis in Q14, the normal equations'
// sums over the inliers in int64, the residuals in Q16 steps from the
// nuisance fit quantised to Q16, the squared residuals in Q8 and a saturating
// uint64 sum; the rare outliers' weighted terms in double), and per
// candidate and row only the O(1) work in double: the K x K solve (K <= 3),
// the logs and the final scaling. Its
// scores follow the float reference on the same quantised values within the
// budget of docs/numerics.md (tests/cpp/test_fixed_session_classifier.cpp).
// Scalar: no NEON kernel yet.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "tofmat/core/classifier.hpp"
#include "tofmat/core/exemplar_table.hpp"
#include "tofmat/core/fixed_classifier.hpp"
#include "tofmat/core/session_classifier.hpp"

namespace tofmat {

class FixedSessionClassifier {
 public:
  // As SessionClassifier's constructor (the same errors).
  FixedSessionClassifier(const std::shared_ptr<const ExemplarTable>& table, SessionPrior prior,
                         std::vector<double> noise_mm = {}, std::vector<std::uint32_t> candidates = {});

  // As SessionClassifier::classify, with FixedClassifier's query rules (a
  // value beyond +-32767 steps saturates there). Same errors.
  Classification classify(const float* query, std::size_t n) const;

  // The float reference it shares its prior, noise and nuisance terms with.
  const SessionClassifier& reference() const { return reference_; }
  const CompactTable& compact() const { return eq12_.compact(); }
  const std::vector<std::uint32_t>& candidates() const { return reference_.candidates(); }

 private:
  SessionClassifier reference_;
  FixedClassifier eq12_;  // the compact table and the query's quantisation
  // Per bin, the terms' basis values in Q14 (term t: Legendre degree degree(t)).
  std::vector<std::array<std::int32_t, kSessionMaxTerms>> basis_;
};

}  // namespace tofmat
