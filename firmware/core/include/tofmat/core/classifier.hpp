// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Nearest-neighbour classification with partial matching, Eq. (12):
//   xi_p = (1/N) * sum over elements valid in both the query and exemplar p of (v_k - v_k^p)^2,
// N the number of such elements, and the label is argmin_p xi_p.
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include "tofmat/core/exemplar_table.hpp"

namespace tofmat {

struct Match {
  std::uint32_t index = 0;  // into ExemplarTable::materials()
  double distance = 0.0;    // Eq. (12), mm^2
  std::uint32_t valid = 0;  // N: elements valid in both query and exemplar
  // How well the candidate explains the query under a noise model, as a
  // standard normal deviate (0: as expected, large: fits worse than noise
  // allows); NaN for a method without a noise model (Eq. (12)). The session
  // matcher's (session_classifier.hpp) decides open-set rejection.
  double fit = std::numeric_limits<double>::quiet_NaN();
};

// Candidates that share at least one valid element with the query, best
// first. Ties in distance are broken by the lower table index so the order is
// deterministic (and the same on every backend).
struct Classification {
  std::vector<Match> ranking;
  const Match& best() const { return ranking.front(); }
};

// A query's valid elements: their indices into n_rows x n_bins and values.
struct QueryElements {
  std::vector<std::uint32_t> index;
  std::vector<double> value;
};
// Throws std::invalid_argument if the size is not the table's, an element is
// infinite, or no element is valid.
QueryElements gather_query(const ExemplarTable& table, const float* query, std::size_t n);
// Sorts a ranking best first (ties: the lower table index, so the order is the
// same on every backend). Throws std::invalid_argument when it is empty (the
// query shares no valid element with any candidate).
void rank(Classification& c);

class FloatClassifier {
 public:
  // `candidates`: indices into the table to search; empty means all. Throws
  // std::invalid_argument on an index out of range.
  explicit FloatClassifier(std::shared_ptr<const ExemplarTable> table, std::vector<std::uint32_t> candidates = {});

  // query: n_rows x n_bins of the table, C order; NaN = missing. Throws
  // std::invalid_argument if the size is wrong, if any element is infinite,
  // if no element is valid, or if no candidate shares a valid element with it.
  Classification classify(const float* query, std::size_t n) const;

  const ExemplarTable& table() const { return *table_; }
  const std::vector<std::uint32_t>& candidates() const { return candidates_; }

 private:
  std::shared_ptr<const ExemplarTable> table_;
  std::vector<std::uint32_t> candidates_;
};

}  // namespace tofmat
