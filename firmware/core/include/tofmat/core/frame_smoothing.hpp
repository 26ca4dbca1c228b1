// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Spatial smoothing of the segmentation's per-pixel data, in integers (no
// float conversion of a full frame): the features' mean over a window of
// valid pixels before classification, and a majority filter of the label map
// after it. Both compute a band of output rows [y0, y1) and read side / 2 rows
// beyond it on each side, so a frame can be split over threads; every band
// gives the same values as the whole frame at once. Each object holds its
// running sums: one per thread.
#pragma once
#include <cstddef>
#include <cstdint>
#include <vector>

#include "tofmat/core/fixed_kernel.hpp"

namespace tofmat {

// The mean of a pixel's two Eq. (10) features over the valid pixels (flag 0)
// of the side x side window centred on it, clipped at the frame's edges.
// Definition (docs/numerics.md): each valid feature is first rounded to Q8 mm,
// v8 = (v16 + 128) >> 8 (|v8| <= 2^23, so a 15 x 15 window's sum S fits
// int32 whatever the input); for a valid pixel with S over n valid pixels,
// the mean is floor((256 S + floor(n / 2)) / n) in Q16 mm (round half up),
// clamped to [INT32_MIN + 1, INT32_MAX] (only inputs beyond the decode's
// range reach the clamp). Pixels whose flag is not 0 get kFixedInvalid. A
// scalar and a NEON kernel (aarch64) give the same integers bit for bit.
class BoxMeanFilter {
 public:
  // side: odd, in [1, 15]. Throws std::invalid_argument otherwise or on a
  // frame size below 1.
  BoxMeanFilter(int width, int height, int side);
  // f0, f1, flags: the whole frame; out0, out1: the whole frame too (only
  // rows [y0, y1) are written). Throws std::invalid_argument on a band
  // outside the frame.
  void apply(const std::int32_t* f0, const std::int32_t* f1, const std::uint8_t* flags, int y0, int y1,
             std::int32_t* out0, std::int32_t* out1, FixedKernel kernel = FixedKernel::kBest);

 private:
  int width_, height_, radius_;
  std::vector<std::int32_t> col0_, col1_, coln_;   // per column: the window's rows summed
  std::vector<std::uint32_t> pre0_, pre1_, pren_;  // their prefix sums along the row, padded
};

// The majority filter of a label map. A label is a value below `classes`;
// every other value (PixelClassifier::kUnclassified) is "no label". Over the
// side x side window centred on a pixel (clipped at the frame's edges):
// - a labelled pixel takes the label most frequent among the window's
//   labelled pixels; on a tie its own label if it is among the most frequent,
//   else the lowest of them;
// - a pixel without a label takes the most frequent label (ties: the lowest)
//   only when labelled pixels are more than half of the window (a dead pixel
//   inside a region is filled; the background beside a region stays empty),
//   and keeps its value otherwise.
// Counting, not ordering: a median of category indices would prefer whatever
// lies between two materials' indices, and erase a region's corners.
class MajorityFilter {
 public:
  // side: odd, in [1, 15]; classes in [1, 255]. Throws std::invalid_argument otherwise.
  MajorityFilter(int width, int height, int side, int classes);
  // labels and out: whole frames, distinct; only rows [y0, y1) of out are written.
  void apply(const std::uint8_t* labels, int y0, int y1, std::uint8_t* out);

 private:
  void slide(const std::uint8_t* labels, int y_in, int y_out);
  template <std::size_t C>
  void apply_chunks(const std::uint8_t* labels, int y0, int y1, std::uint8_t* out);
  int width_, height_, radius_, classes_;
  std::size_t lanes_;                  // classes + 1 rounded up to 16; the last lane counts non-labels
  std::vector<std::uint8_t> columns_;  // per column, lanes_ counts of its window's rows
  std::vector<std::uint8_t> keep_;     // 0xFF in the lanes of real classes, 0 in the others
  std::vector<int> cols_;              // per column x: the columns its window holds (clipped)
};

}  // namespace tofmat
