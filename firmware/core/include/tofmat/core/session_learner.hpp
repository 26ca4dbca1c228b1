// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The session matcher that learns how far this session moved from the sweeps
// it has labelled (docs/evaluation.md, "Sessions of many sweeps").
//
// How far a box's session departs from its table's (the row offsets and the
// waveform's drift the session matcher integrates out) is not known: one
// short sweep cannot tell a small session change from a material difference,
// and a prior that expects the calibration's spread explains real material
// differences away when the session barely moved, while Eq. (12) fails when
// it moved a lot. A box labels many sweeps in one session, and the session's
// size is common to them. So the matcher scores a query under the session
// prior scaled by each of a few scales s_k (0: the table's own session) and
// mixes them with weights w_k learned from the sweeps labelled since the
// session began:
//   D(m) = -log sum_k w_k exp(-D_k(m)),
// D_k(m) the session matcher's score (a negative log-likelihood) of candidate
// m under scale s_k. After each finished sweep, with
//   E_k = log sum_m exp(-D_k(m))
// (the sweep's evidence for scale k, candidates equally likely a priori),
//   log w_k <- forget * log w_k + min(E_k - max_j E_j, ...) ,
// the evidence capped at `evidence_cap` nats below the best scale, so that
// no one sweep (a material outside the table, a bad region) settles the
// session, and `forget` lets the weights follow a session that drifts
// (the last 1 / (1 - forget) sweeps count). The weights start equal and
// start again at reset (a new session).
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <vector>

#include "tofmat/core/classifier.hpp"
#include "tofmat/core/exemplar_table.hpp"
#include "tofmat/core/session_classifier.hpp"

namespace tofmat {

struct SessionLearning {
  // The scales of the session prior's spreads (offsets and drift) the
  // mixture holds; 0 is a session that did not move. Increasing, >= 0.
  std::vector<double> scales{0.0, 0.25, 0.5, 1.0, 2.0, 4.0};
  double forget = 0.9;         // in (0, 1]: each sweep's weight in the next one's, 1: never forgets
  double evidence_cap = 10.0;  // > 0, nats: a sweep moves a scale's weight by at most this

  // Throws std::invalid_argument naming the bad setting.
  void validate() const;
};

// The prior with its offsets and drift spreads times `scale` (>= 0); the noise model unchanged.
SessionPrior scaled(const SessionPrior& prior, double scale);

class SessionLearner {
 public:
  // Scores a query under one scale's prior (SessionClassifier::classify or
  // FixedSessionClassifier::classify): every scorer must rank the same
  // candidates.
  using Scorer = std::function<Classification(const float*, std::size_t)>;

  // One scorer per scale of `settings`. Throws std::invalid_argument on bad
  // settings or a count that is not the scales'.
  SessionLearner(SessionLearning settings, std::vector<Scorer> scorers);

  // Session classifiers of the table under prior x each scale, on the float
  // or the fixed-point path, with noise_mm and candidates as
  // SessionClassifier's (the same errors as their constructors).
  static std::shared_ptr<SessionLearner> make(const std::shared_ptr<const ExemplarTable>& table,
                                              const SessionPrior& prior, bool fixed_point,
                                              const std::vector<double>& noise_mm = {},
                                              const std::vector<std::uint32_t>& candidates = {},
                                              SessionLearning settings = {});

  struct Scored {
    Classification mixture;        // the ranking by the mixture's score D(m), fit from m's likeliest scale
    std::vector<double> evidence;  // E_k per scale
  };
  // The query under the weights learned so far. A scale whose weight is
  // under e^-kNegligibleNats of the largest adds nothing to D(m) and is not
  // scored (its evidence is -infinity) unless every_scale: a handheld frame
  // then costs about one session matcher once the session is learned. Throws
  // std::invalid_argument as the scorers do (no candidate shares an element
  // with the query).
  Scored classify(const float* query, std::size_t n, bool every_scale = false) const;
  // A finished sweep (classify(..., true) of its whole query) moves the
  // weights. Throws std::invalid_argument for another count of scales, or
  // for a sweep not scored at every scale.
  void learn(const Scored& sweep);
  // A weight this many nats under the largest is not scored by classify.
  static constexpr double kNegligibleNats = 30.0;
  // A new session: equal weights, no sweep learned.
  void reset();

  struct State {
    std::vector<double> scales;
    std::vector<double> weights;  // summing to 1
    double scale = 0.0;           // the weights' mean scale
    std::uint64_t sweeps = 0;     // learned since the session began
  };
  State state() const;
  const SessionLearning& settings() const { return settings_; }

 private:
  SessionLearning settings_;
  std::vector<Scorer> scorers_;
  mutable std::mutex mutex_;        // guards what follows: one learner serves every region of a session
  std::vector<double> log_weight_;  // up to a constant
  std::uint64_t sweeps_ = 0;
};

}  // namespace tofmat
