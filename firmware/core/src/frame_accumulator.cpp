// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// FrameAccumulator (frame_accumulator.hpp): per-pixel means over frames in integers.
#include "tofmat/core/frame_accumulator.hpp"

#include <cstdlib>
#include <stdexcept>

namespace tofmat {
namespace {

// sum / n rounded half away from zero (n > 0): the mean of n values, as a
// value of their own type (|sum| <= n * 2^31: the quotient fits 32 bits).
std::int32_t mean_of(std::int64_t sum, std::int64_t n) {
  const std::int64_t half = n / 2;
  return static_cast<std::int32_t>(sum >= 0 ? (sum + half) / n : -((-sum + half) / n));
}

}  // namespace

FrameAccumulator::FrameAccumulator(std::size_t pixels, int frames, std::int32_t max_jump_q8)
    : frames_(frames),
      max_jump_q8_(max_jump_q8),
      sum_depth_(pixels, 0),
      sum_f0_(pixels, 0),
      sum_f1_(pixels, 0),
      count_(pixels, 0) {
  if (frames < 1 || frames > 256) throw std::invalid_argument("frame accumulation: frames must be 1..256");
  if (max_jump_q8 < 0) throw std::invalid_argument("frame accumulation: the depth jump must not be negative");
}

void FrameAccumulator::add(const std::int32_t* depth_q8, const std::uint8_t* flags, const std::int32_t* f0_q16,
                           const std::int32_t* f1_q16, std::size_t begin, std::size_t end, std::int32_t* mean_depth_q8,
                           std::int32_t* mean_f0_q16, std::int32_t* mean_f1_q16) {
  const auto full = static_cast<std::int64_t>(frames_);
  for (std::size_t i = begin; i < end; ++i) {
    if (flags[i] != 0) {  // no value: it starts over, and its outputs are its inputs
      count_[i] = 0;
      mean_depth_q8[i] = depth_q8[i];
      mean_f0_q16[i] = f0_q16[i];
      mean_f1_q16[i] = f1_q16[i];
      continue;
    }
    std::int64_t n = count_[i];
    if (n == 0 || frames_ == 1 ||
        std::llabs(static_cast<long long>(depth_q8[i]) - mean_of(sum_depth_[i], n)) > max_jump_q8_) {
      // Start over: nothing yet (a start, a reset, an invalid frame before), or
      // a jump in depth (something else is in front of it now).
      n = 0;
      sum_depth_[i] = sum_f0_[i] = sum_f1_[i] = 0;
    }
    if (n == full) {  // forget 1/frames of the old mean to make room for this frame
      sum_depth_[i] -= mean_of(sum_depth_[i], full);
      sum_f0_[i] -= mean_of(sum_f0_[i], full);
      sum_f1_[i] -= mean_of(sum_f1_[i], full);
      --n;
    }
    sum_depth_[i] += depth_q8[i];
    sum_f0_[i] += f0_q16[i];
    sum_f1_[i] += f1_q16[i];
    ++n;
    count_[i] = static_cast<std::uint16_t>(n);
    mean_depth_q8[i] = mean_of(sum_depth_[i], n);
    mean_f0_q16[i] = mean_of(sum_f0_[i], n);
    mean_f1_q16[i] = mean_of(sum_f1_[i], n);
  }
}

void FrameAccumulator::reset() {
  for (auto& c : count_) c = 0;
}

}  // namespace tofmat
