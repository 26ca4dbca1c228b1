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
// The work that does not depend on the candidate is done once a query: the
// bins the query holds, their basis values and their Gram matrix per row
// (exact integer sums: a candidate missing some of those bins subtracts
// them, and a pass subtracts its outliers). Each reweighting pass is one
// loop over the compared elements, which also sums the data term; the logs
// are taken of the last pass's factor only.
//
// The session learner (session_learner.hpp) scores a query under the prior
// with its offsets and drift scaled by each of several scales. Only the
// nuisance fit depends on the scale: the query's quantisation, each
// candidate's differences from it and their first moments are shared, so
// classify_scaled costs one matcher's shared work and each scale's passes
// (the scales' scores are those of a FixedSessionClassifier of each scaled
// prior, to the bit).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "tofmat/core/classifier.hpp"
#include "tofmat/core/exemplar_table.hpp"
#include "tofmat/core/fixed_classifier.hpp"
#include "tofmat/core/fixed_kernel.hpp"
#include "tofmat/core/session_classifier.hpp"

namespace tofmat {

class FixedSessionClassifier {
 public:
  // As SessionClassifier's constructor (the same errors). kernel: the
  // reweighting passes' (NEON on aarch64 with kBest; the same scores to the bit).
  // scales: those classify_scaled scores under (each finite and >= 0; none:
  // classify only); std::invalid_argument for another.
  FixedSessionClassifier(const std::shared_ptr<const ExemplarTable>& table, SessionPrior prior,
                         std::vector<double> noise_mm = {}, std::vector<std::uint32_t> candidates = {},
                         FixedKernel kernel = FixedKernel::kBest, const std::vector<double>& scales = {});

  // As SessionClassifier::classify, with FixedClassifier's query rules (a
  // value beyond +-32767 steps saturates there). Same errors.
  Classification classify(const float* query, std::size_t n) const;

  // The query under the prior scaled (scaled(), session_classifier.hpp) by
  // each of scales() whose `wanted` is set (one flag per scale): what a
  // FixedSessionClassifier of that scaled prior's classify gives, to the
  // bit; an empty ranking for a scale not wanted. The same errors as
  // classify, and std::invalid_argument for another count of flags.
  // ranked false: each scale's candidates in candidates() order, not sorted
  // (for a caller that ranks a mixture of the scales itself: SessionLearner).
  std::vector<Classification> classify_scaled(const float* query, std::size_t n, const std::vector<bool>& wanted,
                                              bool ranked = true) const;
  // The same into `out` (resized to the scales), whose rankings' storage is
  // kept from call to call: a caller that keeps `out` allocates nothing once
  // it has grown (SessionLearner: a frame's label). deviates false: each
  // Match::fit holds the chi-square statistic Q instead of its deviate, and
  // chi_square_deviate(Q, valid) gives the deviate (for a caller that keeps
  // one scale's fit of each candidate: SessionLearner, which then takes one
  // cube root a candidate instead of one a candidate and scale).
  void classify_scaled(const float* query, std::size_t n, const std::vector<bool>& wanted,
                       std::vector<Classification>& out, bool ranked = true, bool deviates = true) const;
  const std::vector<double>& scales() const { return scales_; }

  // The float reference it shares its prior, noise and nuisance terms with.
  const SessionClassifier& reference() const { return reference_; }
  const CompactTable& compact() const { return eq12_.compact(); }
  const std::vector<std::uint32_t>& candidates() const { return reference_.candidates(); }

 private:
  SessionClassifier reference_;
  FixedClassifier eq12_;  // the compact table and the query's quantisation
  FixedKernel kernel_;
  // Per term, each bin's basis value in Q14 (term t: Legendre degree degree(t)).
  std::array<std::vector<std::int32_t>, kSessionMaxTerms> basis_;
  // The same in Q31 for the fit (a constant term's is unused: it is 1).
  std::array<std::vector<std::int32_t>, kSessionMaxTerms> fit_basis_;
  // Per candidate (in candidates() order) and row: the noise variance (steps^2)
  // and sd (steps), the Gaussian's log normaliser (mm), the outlier threshold (Q8 steps).
  struct RowNoise {
    double v = 0.0, sd = 0.0, log_norm = 0.0;
    std::int32_t threshold = 0;
  };
  std::vector<RowNoise> noise_;
  // A prior's nuisance terms in steps: how many (the prior's, or none for a
  // prior of zero spreads), per row their prior variances (steps^2) and the
  // log of their product.
  struct PriorSteps {
    int terms = 0;
    std::vector<std::array<double, kSessionMaxTerms>> var;
    std::vector<double> log_det;
  };
  PriorSteps prior_steps(const SessionClassifier& reference) const;
  // Scores the query under each prior of `priors` (null: not scored) into `out`, one Classification each
  // (ranked false: in candidates() order; deviates: as classify_scaled's).
  void score(const float* query, std::size_t n, const std::vector<const PriorSteps*>& priors,
             std::vector<Classification>& out, bool ranked = true, bool deviates = true) const;

  PriorSteps prior_;                // the prior's own
  std::vector<double> scales_;      // classify_scaled's
  std::vector<PriorSteps> scaled_;  // one per scale
};

}  // namespace tofmat
