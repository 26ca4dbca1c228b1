// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Per-pixel classification (the segmentation's feature, m = 1): every pixel's
// two Eq. (10) features at the bin of its own combined depth, against every
// candidate's two table values at that bin, by Eq. (12) in integers. The
// table is rearranged bin-major at construction (each bin's candidates side
// by side, value pairs packed in 32 bits) so that a vector kernel takes eight
// candidates an instruction; the scalar kernel is the definition and the AVX2
// (x86-64 CPUs that have it) and NEON (aarch64) kernels give the same labels
// bit for bit.
//
// The definition (docs/numerics.md): q_r = clamp((clamp(feature_r, +-2^30) +
// half a step) >> shift, -32767, 32767) in table steps (the inner clamp,
// 16384 mm, is far beyond any feature the decode gives: 9375 mm); for candidate k with at least one
// valid element at the bin, d_r = clamp(q_r - e_r, -32767, 32767) and
// s_k = (d_0^2 + d_1^2) if both elements are valid, 2 d_r^2 if one is (Eq. (12)'s
// sum / count, times 2); the label is the k with the least s_k, ties to the
// lower k. s_k < 2^31 always. The differences' clamp only matters where a
// candidate is 32767 steps (256 mm at the .tmx step) or more from the pixel.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "tofmat/core/bin_spec.hpp"
#include "tofmat/core/compact_table.hpp"
#include "tofmat/core/fixed_decode.hpp"
#include "tofmat/core/fixed_depth_bins.hpp"
#include "tofmat/core/fixed_kernel.hpp"

namespace tofmat {

class PixelClassifier {
 public:
  static constexpr std::uint8_t kUnclassified = 255;
  static constexpr std::size_t kSlotBlock = 8;  // candidates per vector

  // The table must have the two Kinect v2 rows, at most 254 candidates and a
  // power-of-two step; bins are the table's (the combined depth's binning).
  // Throws std::invalid_argument otherwise.
  PixelClassifier(const CompactTable& table, const BinSpec& bins);

  // Labels (candidate index, kUnclassified where the pixel is flagged or
  // outside the bins, or no candidate has a value at its bin) of a decoded
  // frame; returns how many pixels got a label.
  std::size_t classify(const FixedDecodedFrame& frame, std::uint8_t* labels,
                       FixedKernel kernel = FixedKernel::kBest) const;
  // The same from a bin index per pixel (-1: none) and the two features (Q16 mm).
  std::size_t classify(const std::int32_t* bin, const std::int32_t* f0_q16, const std::int32_t* f1_q16, std::size_t n,
                       std::uint8_t* labels, FixedKernel kernel = FixedKernel::kBest) const;

  // The same from planes of n pixels (a piece of a decoded frame: its
  // combined depth, flags and two features, or features smoothed beforehand).
  std::size_t classify_range(const std::int32_t* combined_q8, const std::uint8_t* flags, const std::int32_t* f0_q16,
                             const std::int32_t* f1_q16, std::size_t n, std::uint8_t* labels,
                             FixedKernel kernel = FixedKernel::kBest) const;
  // Decode, features and classification of a whole raw frame (9 x
  // tables.pixels samples) in one pass over tiles that stay in cache: only the
  // labels reach memory (the segmentation's hot path). The same labels as
  // classify(decode_frame_fixed(raw, tables, options)).
  std::size_t classify_frame(const std::int16_t* raw, const FixedDecodeTables& tables, std::uint8_t* labels,
                             const DecodeOptions& options = {}, FixedKernel kernel = FixedKernel::kBest) const;

  std::size_t n_candidates() const { return n_candidates_; }
  const FixedBinning& binning() const { return binning_; }

  // The rearranged table, for the kernels: per bin, `slots` entries.
  struct Layout {
    std::size_t slots = 0;  // candidates rounded up to kSlotBlock
    std::uint32_t bins = 0;
    int shift = 0;                           // Q16 mm -> table steps
    bool one_valid = false;                  // some slot has exactly one valid element
    std::vector<std::uint8_t> slot_of;       // candidate (rank) -> slot within a bin (a permutation)
    std::vector<std::int32_t> pairs;         // e0 | e1 << 16 (int16 each)
    std::vector<std::int32_t> elem_mask;     // 0xFFFF per valid element (low: row 0, high: row 1)
    std::vector<std::int32_t> doubled;       // 1 where exactly one element is valid (s = 2 d^2)
    std::vector<std::int32_t> absent;        // 0x7FFFFFFF where no element is valid (or padding), else 0
    std::vector<std::uint8_t> needs_absent;  // per bin: 1 if some slot is absent (else every slot holds
                                             // values: padding copies a lower candidate, which wins a tie)
  };
  const Layout& layout() const { return layout_; }

 private:
  static constexpr std::size_t kChunk = 1024;  // pixels per pass: the scratch stays in L1
  std::size_t classify_chunk(const std::int32_t* depth_q8, const std::uint8_t* flags, const std::int32_t* bin,
                             const std::int32_t* f0, const std::int32_t* f1, std::size_t n, std::uint8_t* labels,
                             FixedKernel kernel) const;

  std::size_t n_candidates_ = 0;
  FixedBinning binning_;
  Layout layout_;
};

// The features (Q16 mm) in table steps, packed q0 | q1 << 16.
void quantise_features_scalar(const std::int32_t* f0, const std::int32_t* f1, std::size_t n, int shift,
                              std::int32_t* q);
#if defined(__aarch64__)
void quantise_features_neon(const std::int32_t* f0, const std::int32_t* f1, std::size_t n, int shift, std::int32_t* q);
#endif
#if defined(__x86_64__)
void quantise_features_avx2(const std::int32_t* f0, const std::int32_t* f1, std::size_t n, int shift,
                            std::int32_t* q);  // AVX2 CPUs only
#endif

// The kernels over n pixels: q packs the pixel's quantised features (q0 | q1
// << 16), bin its bin (-1: none). Exposed for the bit-exactness tests.
std::size_t classify_pixels_scalar(const PixelClassifier::Layout& t, const std::int32_t* bin, const std::int32_t* q,
                                   std::size_t n, std::uint8_t* labels);
#if defined(__aarch64__)
std::size_t classify_pixels_neon(const PixelClassifier::Layout& t, const std::int32_t* bin, const std::int32_t* q,
                                 std::size_t n, std::uint8_t* labels);
#endif
#if defined(__x86_64__)
// Only on a CPU with AVX2 (cpu_has_avx2()).
std::size_t classify_pixels_avx2(const PixelClassifier::Layout& t, const std::int32_t* bin, const std::int32_t* q,
                                 std::size_t n, std::uint8_t* labels);
#endif

}  // namespace tofmat
