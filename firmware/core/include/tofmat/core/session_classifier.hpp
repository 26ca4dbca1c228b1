// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The session-robust matcher (docs/evaluation.md), float reference in double
// precision. Eq. (12) counts every difference between a query and a stored
// curve against the material; a new capture session moves the rows by an
// offset and a drift along depth that are not about the material. Per
// candidate and row this matcher models the query's difference from the
// curve as
//   e_j = sum_k beta_k a_k(x_j) + noise_j,
// a_0 = 1 (the row's offset), a_1 = P1(x), a_2 = P2(x) (Legendre drift over
// the table's depth range, x in [-1, 1]), beta_k ~ N(0, s_k^2) (a prior, not
// free), noise_j ~ N(0, v) with v = (noise_scale sigma_m,r)^2 + floor^2 and
// sigma_m,r the candidate's own bin noise; outlier elements weigh less
// (Huber's loss, reweighted). The score is the negative log-likelihood with
// the beta integrated out (Laplace: exact for the Gaussian part):
//   sum_j rho(r_j / sqrt v) + n/2 log(2 pi v) + sum_k beta_k^2 / (2 s_k^2)
//   + log det(S P) / 2,  S = diag(s_k^2), P the posterior precision,
// summed over rows, plus (1/2 + log(2 pi v)/2) for each query element the
// candidate lacks. Lower is better. Match::fit is how well the candidate
// explains the query: Q = 2 (sum_j rho(r_j / sqrt v) + sum_k beta_k^2 / (2 s_k^2))
// over the n compared elements is e' Sigma^-1 e, chi-square with n degrees
// of freedom when the candidate is the truth (exactly so for the Gaussian
// part), and fit = its Wilson-Hilferty normal deviate
//   ((Q/n)^(1/3) - (1 - 2/(9n))) / sqrt(2/(9n)),
// a length-free scale on which a threshold rejects a query that no candidate
// explains (docs/evaluation.md, open set). The NumPy reference it must equal is
// tofmat.evaluation.matchers.SessionMatcher (tests/python/test_session_classifier.py).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include "tofmat/core/classifier.hpp"
#include "tofmat/core/exemplar_table.hpp"

namespace tofmat {

// The nuisance terms of a row at most: its offset and the drift's Legendre degrees 1 and 2.
inline constexpr int kSessionMaxTerms = 3;

struct SessionPrior {
  // Prior sd of each row's offset, mm (one per table row; 0 leaves the term out).
  std::vector<double> offset_sd_mm;
  // Prior sd of the drift's Legendre degree 1 and 2 terms over the table, mm (0: left out).
  double drift1_sd_mm = 5.0;
  double drift2_sd_mm = 3.0;
  // Element noise: noise_scale x the candidate's bin noise, combined with floor_mm.
  double noise_scale = 1.4142135623730951;
  double floor_mm = 0.5;
  // Residuals beyond huber_k noise units count linearly (infinity: Gaussian).
  double huber_k = 3.0;
  int iterations = 3;  // reweighting passes, at least 1

  // The settings docs/evaluation.md tuned on its tuning split, for a table
  // of the Kinect v2 database rows (16-120 and 80-120 MHz): the offset
  // priors are the calibration's spread (2.27 and 0.73 mm). Other rows get
  // 1 mm each. A table that carries its own calibration (format 1.3, tofmat
  // table calibrate) gives its prior instead. Throws std::invalid_argument
  // for n_rows 0.
  static SessionPrior tuned(const ExemplarTable& table);
  // Throws std::invalid_argument naming the bad setting (negative or NaN
  // sd, noise_scale, floor; huber_k <= 0; iterations < 1; the offsets'
  // count not the table's rows; no noise at all: noise_scale and floor 0).
  void validate(std::uint32_t n_rows) const;
};

// The nuisance term of Legendre degree `degree` (0, 1 or 2) at the centre of
// bin `bin` of `bins`: the basis is Legendre over the table's depth range,
// x = 2 ((bin + 1/2) / bins - 1/2) in (-1, 1).
inline double session_basis(std::uint32_t bin, std::uint32_t bins, int degree) {
  const double x = 2.0 * ((bin + 0.5) / bins - 0.5);
  return degree == 0 ? 1.0 : degree == 1 ? x : 0.5 * (3.0 * x * x - 1.0);
}

// The prior with its offsets and drift spreads times `scale` (finite, >= 0;
// std::invalid_argument otherwise); the noise model unchanged: how far a
// session moves, as the session learner weighs it (session_learner.hpp).
SessionPrior scaled(const SessionPrior& prior, double scale);

// Each material's bin noise per row (n_materials x n_rows, mm): 1.4826 x the
// median absolute deviation of its observed elements' second differences,
// over sqrt(6) (white noise of sd s has second differences of sd s sqrt(6);
// a smooth trend almost none). NaN where a row has fewer than 5 elements.
std::vector<double> curve_roughness(const ExemplarTable& table);

// The Wilson-Hilferty normal deviate of a chi-square value q with n degrees of freedom (n >= 1).
double chi_square_deviate(double q, double n);
// The real cube root of x, within 4 ulp (std::cbrt's rules for 0,
// subnormals, infinities and NaN), in a third of std::cbrt's instructions.
double cube_root(double x);

// How vague each material is as a candidate (n_materials values, each >= 1):
// the mean over rows of its element variance, (noise_scale sigma_m,r)^2 +
// floor^2, over the median of every material's in that row; 1 where that is
// less. A candidate k times noisier than the table's typical one explains any
// query k times more easily (a dark or specular material's curve, whose
// frames scatter by millimetres); fit_tempering judges a best match's fit at
// the typical noise with it (confidence.hpp). noise_mm: n_materials x n_rows,
// every value finite and > 0 (SessionClassifier::noise_mm()).
std::vector<double> candidate_vagueness(const std::vector<double>& noise_mm, std::uint32_t n_rows,
                                        const SessionPrior& prior);

class SessionClassifier {
 public:
  // noise_mm: n_materials x n_rows bin noise (empty: the table's noise_mm()
  // where it holds a measured value, curve_roughness(table) elsewhere);
  // a NaN or non-positive entry takes the median of the others. Throws
  // std::invalid_argument on a bad prior, a noise of the wrong size, or a
  // candidate index outside the table.
  SessionClassifier(std::shared_ptr<const ExemplarTable> table, SessionPrior prior, std::vector<double> noise_mm = {},
                    std::vector<std::uint32_t> candidates = {});

  // As FloatClassifier::classify: Match::distance is the score (lower is
  // better), Match::valid the elements compared. Same errors.
  Classification classify(const float* query, std::size_t n) const;

  const ExemplarTable& table() const { return *table_; }
  const SessionPrior& prior() const { return prior_; }
  const std::vector<double>& noise_mm() const { return noise_; }
  const std::vector<std::uint32_t>& candidates() const { return candidates_; }
  // candidate_vagueness() of this matcher's noise and prior, per table material.
  const std::vector<double>& vagueness() const { return vagueness_; }
  // The nuisance terms with a prior, as derived from the prior (the
  // fixed-point path shares them): how many, each one's Legendre degree, per
  // row their prior variances (mm^2) and the log of their product.
  int terms() const { return terms_; }
  int degree(int t) const { return degree_[static_cast<std::size_t>(t)]; }
  const std::array<double, kSessionMaxTerms>& prior_var(std::uint32_t row) const { return prior_var_[row]; }
  double log_det_prior(std::uint32_t row) const { return log_det_prior_[row]; }

 private:
  static constexpr int kMaxTerms = kSessionMaxTerms;

  std::shared_ptr<const ExemplarTable> table_;
  SessionPrior prior_;
  std::vector<double> noise_;  // n_materials x n_rows
  std::vector<std::uint32_t> candidates_;
  std::vector<double> vagueness_;
  // The nuisance terms with a prior (a zero prior leaves its term out): their
  // Legendre degrees, per row their prior variances, and per row the log of
  // their product (log det S).
  int terms_ = 0;
  std::array<int, kMaxTerms> degree_{};
  std::vector<std::array<double, kMaxTerms>> prior_var_;
  std::vector<double> log_det_prior_;
};

}  // namespace tofmat
