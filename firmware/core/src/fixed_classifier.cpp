// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// FixedClassifier: the query quantised, integer squared sums by the build's kernel, exact ranking of the means.
#include "tofmat/core/fixed_classifier.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "tofmat/core/fixed_distance.hpp"

namespace tofmat {
namespace {

__extension__ typedef unsigned __int128 Wide;  // sum (< 2^52) x count (< 2^21)

struct Scored {
  std::uint32_t index;  // into the source table
  SquaredSum s;
};

// a.sum / a.count < b.sum / b.count, exactly; ties to the lower table index.
bool ranks_before(const Scored& a, const Scored& b) {
  const Wide l = static_cast<Wide>(a.s.sum) * b.s.count, r = static_cast<Wide>(b.s.sum) * a.s.count;
  return l != r ? l < r : a.index < b.index;
}

}  // namespace

FixedClassifier::FixedClassifier(std::shared_ptr<const ExemplarTable> table, std::vector<std::uint32_t> candidates,
                                 FixedKernel kernel)
    : table_(table ? std::move(table) : throw std::invalid_argument("classifier needs a table")),
      compact_(*table_, std::move(candidates)),
      kernel_(kernel) {
#if defined(__aarch64__)
  if (kernel_ == FixedKernel::kBest) elements_ = std::make_unique<const ElementMajorTable>(compact_);
#endif
}

FixedClassifier::Prepared FixedClassifier::prepare(const float* query, std::size_t n) const {
  const std::size_t len = table_->elements_per_material();
  if (n != len) {
    throw std::invalid_argument("query has " + std::to_string(n) + " elements, the table needs " +
                                std::to_string(table_->n_rows()) + " x " + std::to_string(table_->n_bins()) + " = " +
                                std::to_string(len));
  }
  const std::uint32_t rows = compact_.n_rows(), bins = compact_.n_bins();
  const std::size_t pb = compact_.padded_bins(), row_blocks = pb / kCompactBlock;
  Prepared p;
  p.q.assign(compact_.padded_elements(), 0);
  p.mask.assign(compact_.padded_elements() / kCompactBlock, 0);
  // Per row, the blocks holding valid elements: a partial query (a few bins
  // of a sweep) touches only those.
  p.first.assign(rows, row_blocks);
  p.last.assign(rows, 0);
  const double inv = 1.0 / compact_.step_mm();
  bool any = false;
  for (std::uint32_t r = 0; r < rows; ++r) {
    for (std::uint32_t b = 0; b < bins; ++b) {
      const std::size_t k = static_cast<std::size_t>(r) * bins + b;
      if (std::isinf(query[k])) {
        throw std::invalid_argument("query element " + std::to_string(k) + " is infinite (use NaN for missing)");
      }
      if (std::isnan(query[k])) continue;
      const std::size_t i = static_cast<std::size_t>(r) * pb + b;
      p.q[i] = quantise_to_step(query[k], inv);
      p.mask[i / kCompactBlock] = static_cast<std::uint8_t>(p.mask[i / kCompactBlock] | (1u << (i % kCompactBlock)));
      p.first[r] = std::min(p.first[r], b / kCompactBlock);
      p.last[r] = b / kCompactBlock + 1;
      any = true;
    }
  }
  if (!any) throw std::invalid_argument("query has no valid element (all NaN): nothing to classify");
  return p;
}

void FixedClassifier::squared_sums(const Prepared& p, SquaredSum* out) const {
  std::fill(out, out + compact_.n_candidates(), SquaredSum{});
  const std::size_t row_blocks = compact_.padded_bins() / kCompactBlock;
#if defined(__aarch64__)
  if (elements_) {  // every row in one pass over the query's valid elements
    BlockRange ranges[kMaxRows];
    std::size_t n = 0;
    for (std::uint32_t r = 0; r < compact_.n_rows() && n < kMaxRows; ++r) {
      if (p.first[r] < p.last[r]) ranges[n++] = {r * row_blocks + p.first[r], p.last[r] - p.first[r]};
    }
    squared_sums_elements_neon(*elements_, compact_, ranges, n, p.q.data(), p.mask.data(), out);
    return;
  }
#endif
  for (std::uint32_t r = 0; r < compact_.n_rows(); ++r) {
    if (p.first[r] >= p.last[r]) continue;
    const std::size_t block0 = r * row_blocks + p.first[r];
    tofmat::squared_sums(kernel_, compact_, block0, p.last[r] - p.first[r], p.q.data() + block0 * kCompactBlock,
                         p.mask.data() + block0, out);
  }
}

std::vector<SquaredSum> FixedClassifier::squared_sums(const Prepared& p) const {
  std::vector<SquaredSum> sums(compact_.n_candidates());
  squared_sums(p, sums.data());
  return sums;
}

Classification FixedClassifier::classify(const float* query, std::size_t n) const {
  const std::vector<SquaredSum> sums = squared_sums(prepare(query, n));
  std::vector<Scored> scored;
  scored.reserve(sums.size());
  for (std::size_t c = 0; c < sums.size(); ++c) {
    if (sums[c].count == 0) continue;  // nothing in common: this candidate cannot be judged
    scored.push_back({compact_.candidates()[c], sums[c]});
  }
  if (scored.empty()) throw std::invalid_argument("query shares no valid element with any candidate material");
  std::sort(scored.begin(), scored.end(), ranks_before);
  Classification out;
  out.ranking.reserve(scored.size());
  const double step2 = compact_.step_mm() * compact_.step_mm();
  for (const auto& s : scored) {
    out.ranking.push_back(Match{s.index, static_cast<double>(s.s.sum) * step2 / s.s.count, s.s.count});
  }
  return out;
}

}  // namespace tofmat
