// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Accumulation of per-frame feature observations into depth bins. A hand-held
// sweep adds one observation per frame; the current query (mean per bin, NaN
// where a bin has too few observations) is a partial feature vector that the
// classifier matches as it grows (Eq. (12) partial matching).
#pragma once

#include <cstdint>
#include <vector>

#include "tofmat/core/bin_spec.hpp"
#include "tofmat/core/frame_decode.hpp"

namespace tofmat {

// A region's surface in one frame on the float path: the valid pixels within
// band_mm of centre_mm, their mean combined depth (NaN if none) and the sums of
// their two features (see FixedSurfaceMean for why a region is binned so).
struct SurfaceMean {
  double depth_mm = 0.0;
  double sum_mm[2] = {0.0, 0.0};
  std::uint64_t pixels = 0;
};
SurfaceMean surface_mean(const DecodedFrame& frame, double centre_mm, double band_mm);

class DepthBinAccumulator {
 public:
  DepthBinAccumulator(BinSpec bins, std::uint32_t n_rows);

  // Adds row_values[0..n_rows) at the bin holding depth_mm (the combined,
  // unwrapped depth). NaN row values are skipped; an Inf value throws
  // std::invalid_argument. Returns the bin index, or -1 when the depth is
  // outside the bins (nothing is added).
  std::int32_t add(double depth_mm, const float* row_values);
  // Adds `count` observations whose values sum to row_sums[0..n_rows) at the
  // bin holding depth_mm (a region's surface at its mean depth, as
  // FixedDepthBinAccumulator::add_surface). A non-finite sum throws
  // std::invalid_argument; returns the bin index, or -1 (nothing added) when
  // the depth is outside the bins or count is 0.
  std::int32_t add_sums(double depth_mm, const double* row_sums, std::uint64_t count);

  // n_rows x n_bins means, NaN where a bin holds fewer than min_count observations.
  std::vector<float> query(std::uint64_t min_count = 1) const;

  // Observations in one row and bin; throws std::out_of_range outside the table.
  std::uint64_t count(std::uint32_t row, std::uint32_t bin) const;
  // Bins where at least one row has min_count observations.
  std::uint32_t bins_covered(std::uint64_t min_count = 1) const;
  void reset();

  const BinSpec& bins() const { return bins_; }
  std::uint32_t n_rows() const { return n_rows_; }

 private:
  std::size_t index(std::uint32_t row, std::uint32_t bin) const {
    return static_cast<std::size_t>(row) * bins_.count + bin;
  }

  BinSpec bins_;
  std::uint32_t n_rows_;
  std::vector<double> sum_;
  std::vector<std::uint64_t> count_;
};

}  // namespace tofmat
