// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Per-pixel accumulation over frames, for a static or slowly moving scene: each
// pixel's two Eq. (10) features and combined depth are averaged over its last
// frames, so that one-position labels (the segmentation's m = 1) see less of
// the pixels' noise. A pixel starts over where its depth jumps (something
// moved in front of it) or it is not valid; past `frames` frames the mean
// forgets old frames at the rate 1/frames a frame (sum -= sum / frames before
// a frame adds), so a slow drift is followed. Integers only (Q16 mm features,
// Q8 mm depth, as the fixed-point decode gives them); the same values on any
// build, whatever the split into row ranges.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace tofmat {

class FrameAccumulator {
 public:
  // pixels: the frame's; frames: how many frames a mean holds at most
  // (1..256; 1: no accumulation, the frame's own values); max_jump_q8: a
  // depth that far from the pixel's mean starts it over (>= 0). Throws
  // std::invalid_argument otherwise.
  FrameAccumulator(std::size_t pixels, int frames, std::int32_t max_jump_q8);

  // Adds pixels [begin, end) of a frame (flags 0: valid) and writes their
  // means (depth Q8, features Q16) for the same pixels; an invalid pixel
  // starts over and its outputs are its inputs. Different ranges may run on
  // different threads at once.
  void add(const std::int32_t* depth_q8, const std::uint8_t* flags, const std::int32_t* f0_q16,
           const std::int32_t* f1_q16, std::size_t begin, std::size_t end, std::int32_t* mean_depth_q8,
           std::int32_t* mean_f0_q16, std::int32_t* mean_f1_q16);
  // Forgets every pixel's frames (a reset command).
  void reset();

  int frames() const { return frames_; }
  // How many frames pixel i's mean holds now (0 after a start over).
  int count(std::size_t i) const { return count_[i]; }

 private:
  int frames_;
  std::int32_t max_jump_q8_;
  std::vector<std::int64_t> sum_depth_, sum_f0_, sum_f1_;
  std::vector<std::uint16_t> count_;
};

}  // namespace tofmat
