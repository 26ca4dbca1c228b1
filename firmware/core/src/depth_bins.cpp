// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// DepthBinAccumulator: per-bin sums and counts of observations, and the partial query of their means.
#include "tofmat/core/depth_bins.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "tofmat/core/exemplar_table.hpp"
#include "tofmat/core/fixed_depth_bins.hpp"

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

std::int32_t DepthBinAccumulator::add_sums(double depth_mm, const double* row_sums, std::uint64_t count) {
  for (std::uint32_t r = 0; r < n_rows_; ++r) {
    if (!std::isfinite(row_sums[r])) throw std::invalid_argument("feature sum is not finite");
  }
  const std::int32_t bin = count == 0 ? -1 : bins_.index_of(depth_mm);
  if (bin < 0) return -1;
  for (std::uint32_t r = 0; r < n_rows_; ++r) {
    const std::size_t i = index(r, static_cast<std::uint32_t>(bin));
    sum_[i] += row_sums[r];
    count_[i] += count;
  }
  return bin;
}

SurfaceMean surface_mean(const DecodedFrame& f, double centre_mm, double band_mm) {
  const std::size_t n = f.pixels;
  if (f.combined_mm.size() != n || f.flags.size() != n || f.features[0].size() != n || f.features[1].size() != n) {
    throw std::invalid_argument("decoded frame's arrays do not match its pixel count");
  }
  if (!(band_mm >= 0.0)) throw std::invalid_argument("the surface's band must not be negative");
  SurfaceMean s;
  s.depth_mm = std::nan("");
  const auto counts = [&](std::size_t i) {
    return f.flags[i] == 0 && std::fabs(static_cast<double>(f.combined_mm[i]) - centre_mm) <= band_mm;
  };
  // As surface_mean's fixed-point twin: the features of the pixel nearest the centre are the reference.
  std::size_t ref = n;
  double nearest = INFINITY;
  for (std::size_t i = 0; i < n; ++i) {
    const double gap = std::fabs(static_cast<double>(f.combined_mm[i]) - centre_mm);
    if (counts(i) && gap < nearest) {
      nearest = gap;
      ref = i;
    }
  }
  if (ref == n) return s;
  double depth_sum = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    if (!counts(i) || std::fabs(f.features[0][i] - f.features[0][ref]) > kSurfaceSameWrapMm ||
        std::fabs(f.features[1][i] - f.features[1][ref]) > kSurfaceSameWrapMm)
      continue;
    depth_sum += f.combined_mm[i];
    s.sum_mm[0] += f.features[0][i];
    s.sum_mm[1] += f.features[1][i];
    ++s.pixels;
  }
  s.depth_mm = depth_sum / static_cast<double>(s.pixels);
  return s;
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
