// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Scene::centred_target: a scene of one square target at the centre of the image;
// target_mask: the pixels an outlined target covers.
#include "tofmat/sim/scene.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace tofmat::sim {

Scene Scene::centred_target(const std::string& material, double depth_mm, double yaw_deg, int size) {
  Scene s;
  Target t;
  t.material = material;
  t.depth_mm = depth_mm;
  t.yaw_deg = yaw_deg;
  t.x0 = 256 - size / 2;
  t.x1 = t.x0 + size;
  t.y0 = 212 - size / 2;
  t.y1 = t.y0 + size;
  s.targets.push_back(t);
  return s;
}

std::vector<std::uint8_t> target_mask(const Target& t) {
  const int w = std::max(0, t.x1 - t.x0), h = std::max(0, t.y1 - t.y0);
  const auto& poly = t.outline;
  std::vector<std::uint8_t> mask(static_cast<std::size_t>(w) * static_cast<std::size_t>(h), poly.empty() ? 1 : 0);
  if (poly.empty()) return mask;
  if (poly.size() < 3 || poly.size() > Target::kMaxOutline)
    throw std::invalid_argument("target '" + t.material + "': an outline needs 3 to " +
                                std::to_string(Target::kMaxOutline) + " vertices");
  for (const auto& v : poly)
    if (!std::isfinite(v[0]) || !std::isfinite(v[1]))
      throw std::invalid_argument("target '" + t.material + "': an outline vertex is not finite");
  // Scan lines through the pixel centres: the edges' crossings, sorted, bound
  // the covered spans (even-odd), so a row costs its edges, not its pixels.
  std::vector<double> cross;
  for (int row = 0; row < h; ++row) {
    const double yc = t.y0 + row + 0.5;
    cross.clear();
    for (std::size_t k = 0; k < poly.size(); ++k) {
      const auto& a = poly[k];
      const auto& b = poly[(k + 1) % poly.size()];
      if ((a[1] <= yc) == (b[1] <= yc)) continue;  // (half-open: a vertex on the line counts once)
      cross.push_back(a[0] + (yc - a[1]) * (b[0] - a[0]) / (b[1] - a[1]));
    }
    std::sort(cross.begin(), cross.end());
    for (std::size_t k = 0; k + 1 < cross.size(); k += 2) {
      // Pixels whose centres x + 0.5 lie in [cross[k], cross[k + 1]).
      const double lo = std::ceil(cross[k] - 0.5) - t.x0, hi = std::ceil(cross[k + 1] - 0.5) - t.x0;
      const int c0 = static_cast<int>(std::clamp(lo, 0.0, static_cast<double>(w)));
      const int c1 = static_cast<int>(std::clamp(hi, 0.0, static_cast<double>(w)));
      std::fill(mask.begin() + static_cast<std::ptrdiff_t>(row) * w + c0,
                mask.begin() + static_cast<std::ptrdiff_t>(row) * w + std::max(c0, c1), std::uint8_t{1});
    }
  }
  return mask;
}

}  // namespace tofmat::sim
