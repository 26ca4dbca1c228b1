// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// FloatClassifier: Eq. (12) partial matching of a query against the candidate materials in double precision.
#include "tofmat/core/classifier.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace tofmat {

FloatClassifier::FloatClassifier(std::shared_ptr<const ExemplarTable> table, std::vector<std::uint32_t> candidates)
    : table_(std::move(table)) {
  if (!table_) throw std::invalid_argument("classifier needs a table");
  candidates_ = candidate_indices(table_->n_materials(), std::move(candidates));
}

QueryElements gather_query(const ExemplarTable& table, const float* query, std::size_t n) {
  const std::size_t len = table.elements_per_material();
  if (n != len) {
    throw std::invalid_argument("query has " + std::to_string(n) + " elements, the table needs " +
                                std::to_string(table.n_rows()) + " x " + std::to_string(table.n_bins()) + " = " +
                                std::to_string(len));
  }
  QueryElements q;
  q.index.reserve(len);
  q.value.reserve(len);
  for (std::size_t k = 0; k < len; ++k) {
    if (std::isinf(query[k])) {
      throw std::invalid_argument("query element " + std::to_string(k) + " is infinite (use NaN for missing)");
    }
    if (std::isnan(query[k])) continue;
    q.index.push_back(static_cast<std::uint32_t>(k));
    q.value.push_back(query[k]);
  }
  if (q.index.empty()) throw std::invalid_argument("query has no valid element (all NaN): nothing to classify");
  return q;
}

void rank(Classification& c) {
  if (c.ranking.empty()) throw std::invalid_argument("query shares no valid element with any candidate material");
  std::sort(c.ranking.begin(), c.ranking.end(), [](const Match& a, const Match& b) {
    return a.distance != b.distance ? a.distance < b.distance : a.index < b.index;
  });
}

Classification FloatClassifier::classify(const float* query, std::size_t n) const {
  // The query's valid elements, gathered once: a partial query (a few bins
  // of a sweep) then costs O(valid) per candidate instead of O(n_rows * n_bins).
  const QueryElements q = gather_query(*table_, query, n);
  const std::vector<std::uint32_t>& idx = q.index;
  const std::vector<double>& qv = q.value;
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
  rank(out);
  return out;
}

}  // namespace tofmat
