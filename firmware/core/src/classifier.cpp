// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// FloatClassifier: Eq. (12) partial matching of a query against the candidate materials in double precision.
#include "tofmat/core/classifier.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace tofmat {

FloatClassifier::FloatClassifier(std::shared_ptr<const ExemplarTable> table, std::vector<std::uint32_t> candidates)
    : table_(std::move(table)), candidates_(std::move(candidates)) {
  if (!table_) throw std::invalid_argument("classifier needs a table");
  if (candidates_.empty()) {
    candidates_.resize(table_->n_materials());
    for (std::uint32_t i = 0; i < candidates_.size(); ++i) candidates_[i] = i;
  }
  std::sort(candidates_.begin(), candidates_.end());
  candidates_.erase(std::unique(candidates_.begin(), candidates_.end()), candidates_.end());
  for (std::uint32_t c : candidates_) {
    if (c >= table_->n_materials()) {
      throw std::invalid_argument("candidate index " + std::to_string(c) + " is outside the table's " +
                                  std::to_string(table_->n_materials()) + " materials");
    }
  }
}

Classification FloatClassifier::classify(const float* query, std::size_t n) const {
  const std::size_t len = table_->elements_per_material();
  if (n != len) {
    throw std::invalid_argument("query has " + std::to_string(n) + " elements, the table needs " +
                                std::to_string(table_->n_rows()) + " x " + std::to_string(table_->n_bins()) + " = " +
                                std::to_string(len));
  }
  // Gather the query's valid elements once: a partial query (a few bins of a
  // sweep) then costs O(valid) per candidate instead of O(n_rows * n_bins).
  std::vector<std::uint32_t> idx;
  std::vector<double> qv;
  idx.reserve(len);
  qv.reserve(len);
  for (std::size_t k = 0; k < len; ++k) {
    if (std::isinf(query[k])) {
      throw std::invalid_argument("query element " + std::to_string(k) + " is infinite (use NaN for missing)");
    }
    if (std::isnan(query[k])) continue;
    idx.push_back(static_cast<std::uint32_t>(k));
    qv.push_back(query[k]);
  }
  if (idx.empty()) throw std::invalid_argument("query has no valid element (all NaN): nothing to classify");

  Classification out;
  out.ranking.reserve(candidates_.size());
  for (std::uint32_t p : candidates_) {
    const float* ex = table_->material_values(p);
    double sum = 0.0;
    std::uint32_t valid = 0;
    for (std::size_t i = 0; i < idx.size(); ++i) {
      const float e = ex[idx[i]];
      if (std::isnan(e)) continue;  // missing in the exemplar: Eq. (12) "N/A"
      const double d = qv[i] - static_cast<double>(e);
      sum += d * d;
      ++valid;
    }
    if (valid == 0) continue;  // nothing in common: this candidate cannot be judged
    out.ranking.push_back(Match{p, sum / valid, valid});
  }
  if (out.ranking.empty()) {
    throw std::invalid_argument("query shares no valid element with any candidate material");
  }
  std::sort(out.ranking.begin(), out.ranking.end(), [](const Match& a, const Match& b) {
    return a.distance != b.distance ? a.distance < b.distance : a.index < b.index;
  });
  return out;
}

}  // namespace tofmat
