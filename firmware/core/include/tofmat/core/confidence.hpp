// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Calibrated confidence and open-set rejection of a classification
// (docs/evaluation.md). A label's confidence is a probability over the
// candidates, softmax(-score / T): a score sums over the sweep's elements, so
// its scale grows with the sweep, and T depends on the sweep's length in bins
// (fitted on the evaluation's tuning split by the Brier score, then raised
// until no label is wrong at 0.9 at any session size tried), times the
// best match's reduced chi-square at the table's typical noise when it
// exceeds 1 (fit_tempering: a query the best candidate explains worse than
// the noise allows is one the scores' differences say less about). A best match
// whose fit (Match::fit, the session matcher's chi-square deviate) exceeds a
// threshold explains the query worse than the noise model allows: the label
// is "unknown", not the nearest material.
#pragma once

#include <cstdint>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "tofmat/core/classifier.hpp"

namespace tofmat {

// The label an open-set rejection gives; a table may not name a material so.
inline constexpr const char* kUnknownLabel = "unknown";

struct Calibration {
  // (sweep length in bins, temperature) knots, lengths strictly increasing;
  // between knots T is interpolated linearly in log length, beyond the ends
  // held at the end's value.
  std::vector<std::pair<double, double>> temperatures;
  // (sweep length in bins, fit) knots of the open-set threshold, interpolated
  // as the temperatures: a best match whose fit exceeds it is unknown. Empty:
  // never unknown. (A fit's spread under the truth grows with the sweep,
  // where the session model explains less of a long sweep, so one threshold
  // for all lengths would reject most long sweeps or accept all short ones.)
  std::vector<std::pair<double, double>> unknown_fits;

  // What docs/evaluation.md fitted on its tuning split for each method
  // ("eq12", "session"): the temperatures at 1, 3, 10, 30 and 100 bins, and
  // for the session matcher the open-set thresholds (Eq. (12) has no noise
  // model: never unknown). Throws std::invalid_argument for another name.
  static Calibration tuned(const std::string& method);
  // The table's own calibration of the method when it carries one (format
  // 1.3, tofmat table calibrate), else tuned(method).
  static Calibration tuned(const std::string& method, const ExemplarTable& table);
  // Throws std::invalid_argument naming the bad setting: no temperature, a
  // length not increasing or not > 0, a temperature not finite and > 0, a
  // threshold NaN.
  void validate() const;
  double temperature(double bins) const;
  double unknown_fit(double bins) const;  // +infinity without thresholds
};

struct Verdict {
  std::vector<double> probability;  // one per ranking entry, summing to 1
  bool unknown = false;             // the best match fits worse than Calibration::unknown_fit
  double confidence() const { return probability.empty() ? 0.0 : probability.front(); }
};

// The factor judge() multiplies the temperature by: the best match's reduced
// chi-square Q/n, recovered from Match::fit (the Wilson-Hilferty deviate of Q
// with n = Match::valid degrees of freedom), judged at the table's typical
// noise (times `vagueness`, candidate_vagueness() of the best match: a
// candidate that fits only because its own noise is wide does not make a
// confident label), when that exceeds 1, else 1; 1 for a fit of NaN (Eq.
// (12): no noise model). At most 1e6. A vagueness below 1 or NaN counts as 1.
double fit_tempering(const Match& best, double vagueness = 1.0);

// The probabilities of a classification's ranking and whether it is unknown;
// the sweep's length is the best match's compared elements over the table's
// rows. A fit of NaN (Eq. (12)) is never unknown. vagueness: per table
// material (SessionClassifier::vagueness()), or empty (1 for all).
Verdict judge(const Classification& c, std::uint32_t n_rows, const Calibration& calibration,
              const std::vector<double>& vagueness = {});
// judge()'s unknown alone, without the probabilities.
bool rejected(const Classification& c, std::uint32_t n_rows, const Calibration& calibration);

// One material's place in a classification, for tables that hold several
// exemplars of a material (ExemplarTable::materials()): the ranking position
// of its best exemplar and the sum of its exemplars' probabilities (the
// posterior of a mixture of its exemplars, equally likely). The label is the
// best exemplar's material, the paper's nearest neighbour over orientations;
// not the material of the largest sum, which under the flat softmax of a
// short sweep is the material nearest on average over its exemplars, not the
// one at the query's angle (docs/evaluation.md).
struct MaterialRank {
  std::string material;
  std::size_t position = 0;  // into Classification::ranking
  double probability = 0.0;
};

// The ranking's materials, each once, in the order of their best exemplars
// (a table of one entry per material: the ranking itself, its probabilities
// unchanged). `verdict` is judge()'s for `c`.
std::vector<MaterialRank> rank_materials(const Classification& c, const Verdict& verdict, const ExemplarTable& table);

}  // namespace tofmat
