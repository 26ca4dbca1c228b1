// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// stage_sweep: a translation-stage capture rendered and decoded over a list of depths.
#include "tofmat/sim/stage.hpp"

#include <cmath>
#include <stdexcept>

#include "tofmat/core/decode.hpp"
#include "tofmat/core/frame_decode.hpp"

namespace tofmat::sim {

StageCapture stage_sweep(const Renderer& renderer, const Target& target, const PixelRect& roi,
                         const std::vector<double>& stage_mm, int frames_per_position, std::uint64_t seed, bool noise) {
  if (frames_per_position < 1 || frames_per_position > 10000) {
    throw std::invalid_argument("frames_per_position must be 1..10000");
  }
  const int width = renderer.device().camera.width;
  // The P0 correction of the region's pixels, as the device reports it.
  const std::size_t n = static_cast<std::size_t>(roi.x1 - roi.x0) * static_cast<std::size_t>(roi.y1 - roi.y0);
  std::vector<float> p0(3 * n);
  for (std::size_t g = 0; g < 3; ++g) {
    const auto pat = renderer.p0_table(static_cast<int>(g));
    std::size_t k = 0;
    for (int y = roi.y0; y < roi.y1; ++y) {
      for (int x = roi.x0; x < roi.x1; ++x) p0[g * n + k++] = pat[static_cast<std::size_t>(y * width + x)];
    }
  }

  StageCapture out;
  Scene scene;
  scene.targets.push_back(target);
  std::uint64_t frame_seed = seed;
  for (double pos : stage_mm) {
    scene.targets[0].depth_mm = pos;
    std::array<double, 3> sum{0.0, 0.0, 0.0};
    double sum_comb = 0.0;
    std::uint32_t count = 0;
    for (int k = 0; k < frames_per_position; ++k) {
      const Frame f = renderer.render_region(scene, frame_seed++, noise, roi);
      const DecodedFrame d = decode_frame(f.raw.data(), n, p0);
      for (std::size_t i = 0; i < n; ++i) {
        if (d.flags[i] || f.target[i] != 0) continue;  // invalid, or a pixel the target does not cover
        const auto u = unwrap_depths({d.depth_mm[0][i], d.depth_mm[1][i], d.depth_mm[2][i]});
        for (std::size_t g = 0; g < 3; ++g) sum[g] += u.depth_mm[g];
        sum_comb += u.combined_mm;
        ++count;
      }
    }
    out.stage_mm.push_back(pos);
    for (std::size_t g = 0; g < 3; ++g) out.depth_mm[g].push_back(count ? sum[g] / count : NAN);
    out.combined_mm.push_back(count ? sum_comb / count : NAN);
    out.samples.push_back(count);
  }
  return out;
}

}  // namespace tofmat::sim
