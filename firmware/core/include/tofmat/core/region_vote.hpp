// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Region-level voting on a label map: a surface of one material is a set of
// neighbouring pixels whose depths change little from one to the next, and a
// one-position label (the segmentation's m = 1) is right on most of its pixels
// but not all. The valid pixels are joined into regions by 4-neighbour steps
// of at most `max_step_q8` in combined depth; a region of at least
// `min_pixels` whose most frequent label holds at least half of its labelled
// pixels gives that label to every valid pixel of it, those without a label
// too (a depth outside the table's bins, say); other regions keep their
// labels. Integers only: one scan of the frame that counts each id's labels
// with a union-find over the ids it starts, then one pass to relabel.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace tofmat {

class RegionVote {
 public:
  // classes: labels are values below it (others: no label), at most 255.
  // Throws std::invalid_argument on a frame size below 1, a negative step,
  // min_pixels 0 or classes outside 1..255.
  RegionVote(int width, int height, std::int32_t max_step_q8, std::size_t min_pixels, int classes);

  // combined_q8: the combined depth (Q8 mm); flags: 0 where the pixel is
  // valid; labels: the map, changed in place (width x height, row-major).
  void apply(const std::int32_t* combined_q8, const std::uint8_t* flags, std::uint8_t* labels);

  // Regions that voted in the last apply().
  std::size_t regions_voted() const { return voted_; }

 private:
  std::uint32_t find(std::uint32_t i);
  void join(std::uint32_t a, std::uint32_t b);

  int width_, height_;
  std::int32_t max_step_q8_;
  std::size_t min_pixels_;
  int classes_;
  std::vector<std::uint32_t> id_;      // per pixel: its id (0: not valid)
  std::vector<std::uint32_t> parent_;  // per id: the union-find's parent (an older id, or itself)
  std::vector<std::uint32_t> counts_;  // per id, per class and one more (no label): its pixels
  std::vector<std::uint8_t> winner_;   // per id: its region's label, or classes_ (no vote)
  std::size_t voted_ = 0;
};

}  // namespace tofmat
