// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// A translation-stage capture, as the paper's database was built (Sec. 5): a
// target moved through a list of depths, a region of interest rendered and
// decoded at each, per-frequency depths averaged over the region and frames.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "tofmat/sim/renderer.hpp"

namespace tofmat::sim {

struct StageCapture {
  std::vector<double> stage_mm;  // commanded target depth (ground truth)
  std::array<std::vector<double>, 3>
      depth_mm;                        // mean unwrapped per-frequency depth (80, 16, 120 MHz); NaN: no valid pixel
  std::vector<double> combined_mm;     // mean combined depth
  std::vector<std::uint32_t> samples;  // valid pixel-frames in each mean
};

// `target` gives material, orientation and fold; its depth is replaced by each
// stage position. Only `roi` is rendered and decoded (P0-corrected), frames
// seeded from `seed`. Throws std::invalid_argument on bad geometry.
StageCapture stage_sweep(const Renderer& renderer, const Target& target, const PixelRect& roi,
                         const std::vector<double>& stage_mm, int frames_per_position, std::uint64_t seed,
                         bool noise = true);

}  // namespace tofmat::sim
