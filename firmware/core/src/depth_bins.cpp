// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// DepthBinAccumulator: per-bin sums and counts of observations, and the partial query of their means.
#include "tofmat/core/depth_bins.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "tofmat/core/exemplar_table.hpp"

namespace tofmat {

DepthBinAccumulator::DepthBinAccumulator(BinSpec bins, std::uint32_t n_rows) : bins_(bins), n_rows_(n_rows) {
  bins_.validate();
  if (n_rows_ < 1 || n_rows_ > kMaxRows) throw std::invalid_argument("accumulator needs 1..16 rows");
  sum_.assign(static_cast<std::size_t>(n_rows_) * bins_.count, 0.0);
  count_.assign(sum_.size(), 0);
}

std::int32_t DepthBinAccumulator::add(double depth_mm, const float* row_values) {
  for (std::uint32_t r = 0; r < n_rows_; ++r) {
    if (std::isinf(row_values[r])) throw std::invalid_argument("feature value is infinite");
  }
  const std::int32_t bin = bins_.index_of(depth_mm);
  if (bin < 0) return -1;
  for (std::uint32_t r = 0; r < n_rows_; ++r) {
    if (std::isnan(row_values[r])) continue;
    const std::size_t i = index(r, static_cast<std::uint32_t>(bin));
    sum_[i] += row_values[r];
    ++count_[i];
  }
  return bin;
}

std::uint64_t DepthBinAccumulator::count(std::uint32_t row, std::uint32_t bin) const {
  if (row >= n_rows_ || bin >= bins_.count) throw std::out_of_range("row or bin outside the accumulator");
  return count_[index(row, bin)];
}

std::vector<float> DepthBinAccumulator::query(std::uint64_t min_count) const {
  min_count = std::max<std::uint64_t>(min_count, 1);
  std::vector<float> out(sum_.size());
  for (std::size_t i = 0; i < sum_.size(); ++i) {
    out[i] = count_[i] >= min_count ? static_cast<float>(sum_[i] / static_cast<double>(count_[i])) : NAN;
  }
  return out;
}

std::uint32_t DepthBinAccumulator::bins_covered(std::uint64_t min_count) const {
  min_count = std::max<std::uint64_t>(min_count, 1);
  std::uint32_t n = 0;
  for (std::uint32_t b = 0; b < bins_.count; ++b) {
    for (std::uint32_t r = 0; r < n_rows_; ++r) {
      if (count_[index(r, b)] >= min_count) {
        ++n;
        break;
      }
    }
  }
  return n;
}

void DepthBinAccumulator::reset() {
  std::fill(sum_.begin(), sum_.end(), 0.0);
  std::fill(count_.begin(), count_.end(), 0);
}

}  // namespace tofmat
