// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// What this session did to the curves, learned from the sweeps labelled since
// it began: the mean of each row's nuisance terms (the offset and the drift's
// Legendre degrees 1 and 2 of session_classifier.hpp), for the session
// learner to take out of every query before it scores it (session_learner.hpp;
// docs/evaluation.md, "Sessions of many sweeps").
//
// The session matcher integrates each sweep's terms beta out under a prior
// N(0, S) centred on the table's own session. But the terms are the
// session's, common to every sweep in it: a row offset, a camera warmer than
// at recording, move every material's curve alike. Each labelled sweep is
// evidence on them. For a candidate m and a row, with the query's differences
// e_j = q_j - c_mj from m's curve, the basis a_j and the element variance v_m
// (the session matcher's noise model), the sweep adds to the information
//   Lambda += A' A / v_m,   eta += A' e / v_m,
// weighted by m's posterior share p_m under the learner's mixture (a sweep
// the learner is unsure of teaches about every likely candidate, none much).
// The learned mean is the posterior mean under the calibration's prior:
//   mu = (Lambda + S^-1)^-1 eta,
// so one short sweep barely moves it, and Lambda, eta decay by `forget` a
// sweep (a session that drifts is followed). Each element counts with the
// weight the session matcher's robust fit of the sweep gives it (Huber's, at
// huber_k element sds from the fit about the learned mean): one bad element
// does not move the session.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include "tofmat/core/session_classifier.hpp"

namespace tofmat {

class SessionOffsets {
 public:
  // reference: the session matcher at the calibration's prior (its noise
  // model, terms and prior variances; its table); forget in (0, 1]. Throws
  // std::invalid_argument for a null reference or a forget outside (0, 1].
  SessionOffsets(std::shared_ptr<const SessionClassifier> reference, double forget);

  // One sweep's information on the session's terms, per row.
  struct Evidence {
    std::vector<std::array<std::array<double, kSessionMaxTerms>, kSessionMaxTerms>> lambda;
    std::vector<std::array<double, kSessionMaxTerms>> eta;
    bool empty() const { return lambda.empty(); }
  };
  // The sweep's unshifted query (n: the table's elements a material) and its
  // candidates' posterior shares (table index, share; shares under
  // kNegligibleShare are left out, the others renormalised). Empty evidence
  // for no share left. Throws std::invalid_argument for another n or an index
  // outside the table.
  Evidence evidence(const float* query, std::size_t n,
                    const std::vector<std::pair<std::uint32_t, double>>& shares) const;
  static constexpr double kNegligibleShare = 1e-3;

  // A sweep's evidence moves the learned mean. Throws std::invalid_argument
  // for evidence of another count of rows.
  void learn(const Evidence& sweep);
  // A new session: nothing learned, the mean 0.
  void reset();

  // The learned mean at every element (n_rows x n_bins, mm): what to take out
  // of a query; all 0 before anything is learned.
  const std::vector<float>& shift() const { return shift_; }
  // The learned mean's terms per row (offset, drift degree 1, degree 2; 0
  // where the prior leaves a term out), mm.
  std::vector<std::array<double, kSessionMaxTerms>> terms_mm() const;

 private:
  std::shared_ptr<const SessionClassifier> reference_;
  double forget_;
  std::uint32_t rows_, bins_;
  int k_;
  std::vector<std::array<double, kSessionMaxTerms>> basis_;  // per bin, the terms' values
  std::vector<std::array<double, kSessionMaxTerms>> mean_;   // per row, in the reference's term order
  Evidence learned_;                                         // Lambda, eta so far (decayed)
  std::vector<float> shift_;
};

}  // namespace tofmat
