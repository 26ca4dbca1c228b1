// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Depth-bin accumulation in fixed point (docs/numerics.md): a region's
// surface adds its pixels' Eq. (10) features, Q16 mm, to the bin of its mean
// combined depth, Q8 mm (add_surface: what the profiles use), or each pixel
// to the bin of its own depth (add_frame), in integer sums. The bin
// index of every pixel comes from a kernel with a scalar, a NEON and an AVX2
// version (bit for bit the same); the sums are shared scalar code. The result is the
// partial query the classifier matches as a hand-held sweep grows.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "tofmat/core/bin_spec.hpp"
#include "tofmat/core/fixed_decode.hpp"

namespace tofmat {

// A BinSpec in the decode's units: bin = ((depth_q8 - start_q8) * inv_width) >> 32.
struct FixedBinning {
  std::int32_t start_q8 = 0;
  std::int32_t inv_width = 0;  // round(2^32 / (width_mm * 256)) <= 2^30
  std::uint32_t count = 0;
  // Throws std::invalid_argument unless the bins lie within +-2^22 mm and are
  // at least 1/64 mm wide (inv_width <= 2^30: products stay below 2^62).
  static FixedBinning from(const BinSpec& bins);
};

// Bin of every pixel: -1 where flags != 0, the depth is invalid, or it lies
// outside the bins. Exposed for the bit-exactness test.
void bin_indices_scalar(const std::int32_t* depth_q8, const std::uint8_t* flags, std::size_t n, const FixedBinning& b,
                        std::int32_t* bin);
#if defined(__aarch64__)
void bin_indices_neon(const std::int32_t* depth_q8, const std::uint8_t* flags, std::size_t n, const FixedBinning& b,
                      std::int32_t* bin);
#endif
#if defined(__x86_64__)
void bin_indices_avx2(const std::int32_t* depth_q8, const std::uint8_t* flags, std::size_t n, const FixedBinning& b,
                      std::int32_t* bin);  // AVX2 CPUs only
#endif
// The build's best kernel for this CPU, or the scalar one.
void bin_indices(FixedKernel kernel, const std::int32_t* depth_q8, const std::uint8_t* flags, std::size_t n,
                 const FixedBinning& b, std::int32_t* bin);

// The surface a region shows in one frame: its valid pixels within band_q8 of
// centre_q8 (the region's median depth; a background behind the target falls
// outside), their mean combined depth and their features' sums.
//
// Why a region is binned by its mean depth and not pixel by pixel: a pixel's
// combined depth and its Eq. (10) features come from the same nine phase
// samples, so their noise is correlated (the 120 MHz phase's error moves the
// combined depth one way and both rows the other). Binning each pixel by its
// own noisy depth sorts pixels by their noise: the bins a still target
// covers lean with depth (-6.7 to +7.3 mm across three bins in
// FixedDepthBins.AStillTargetsSurfaceIsOneBinAtItsValueWherePixelBinsLean),
// while the mean over the region is right. The
// tables are recorded the same way (the region's mean features at its mean
// depth, sdk/tofmat/sim/table.py), and so were the real database's curves.
//
// The features are differences of wrapped depths (Eq. (10) as the database
// has them), so a surface that crosses a frequency's wrap (120 MHz every
// 1250 mm: a tilted target's far corners at 1.2 m) holds pixels whose features
// are 1250, 1875 or 9375 mm apart. Only the pixels within kSurfaceSameWrapMm
// of the features of the pixel nearest the centre's depth count: those on its
// side of every wrap (the smallest jump is 1250 mm; a material's features
// vary by tens of mm across a surface).
inline constexpr std::int32_t kSurfaceSameWrapMm = 625;
// A region's surface: its valid pixels within this far of the region's median
// depth. A target tilted 30 degrees across the handheld ROI at 1200 mm spans
// about +-46 mm; a background behind it lies further away.
inline constexpr std::int32_t kSurfaceBandMm = 64;
struct FixedSurfaceMean {
  std::int32_t depth_q8 = kFixedInvalid;  // floor of the mean; kFixedInvalid when no pixel counts
  std::int64_t sum_q16[2] = {0, 0};       // features of the pixels counted
  std::uint64_t pixels = 0;
};
FixedSurfaceMean surface_mean(const FixedDecodedFrame& frame, std::int32_t centre_q8, std::int32_t band_q8);

class FixedDepthBinAccumulator {
 public:
  // Observations one row and bin holds at most: beyond it a bin takes no more
  // (the Q16 sum then stays below 2^62). A test may ask for fewer.
  static constexpr std::uint64_t kMaxCount = std::uint64_t{1} << 32;

  // n_rows: 1 or 2 (the decode's two features, d16 - d120 and d80 - d120).
  FixedDepthBinAccumulator(BinSpec bins, std::uint32_t n_rows = 2, std::uint64_t max_count = kMaxCount);

  // Adds every valid pixel of a decoded frame or region to the bin of its own
  // depth; returns how many. (Biased for a still target: see FixedSurfaceMean.)
  std::size_t add_frame(const FixedDecodedFrame& frame, FixedKernel kernel = FixedKernel::kBest);
  // Adds a region's surface as one observation at its mean depth: its pixels'
  // sums and count go to that bin, so the bin's mean is the pixel-weighted mean
  // of the surfaces it holds. Returns the pixels added: 0 when the surface is
  // empty, its depth outside the bins, or the bin would pass max_count.
  std::size_t add_surface(const FixedSurfaceMean& surface);
  // n_rows x n_bins means in mm, NaN where a bin holds fewer than min_count
  // observations: the query for Classifier / FixedClassifier.
  std::vector<float> query(std::uint64_t min_count = 1) const;
  std::uint64_t count(std::uint32_t row, std::uint32_t bin) const;
  std::uint32_t bins_covered(std::uint64_t min_count = 1) const;
  // Observations refused because their bin was full.
  std::uint64_t refused() const { return refused_; }
  void reset();
  const BinSpec& bins() const { return bins_; }

 private:
  BinSpec bins_;
  FixedBinning fixed_;
  std::uint32_t n_rows_;
  std::uint64_t max_count_;
  std::vector<std::int64_t> sum_;  // Q16 mm
  std::vector<std::uint64_t> count_;
  std::vector<std::int32_t> bin_;  // per-frame scratch
  std::uint64_t refused_ = 0;
};

}  // namespace tofmat
