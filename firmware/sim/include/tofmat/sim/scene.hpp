// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// What the simulated camera looks at: planar (or folded) targets of library
// materials in front of a background, in the camera's pixel grid.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace tofmat::sim {

// A planar target through the point where the ray of pixel (centre_x,
// centre_y) meets z = depth_mm, turned by yaw (about the vertical axis) and
// pitch (about the horizontal axis) away from facing the camera. A fold
// splits it at centre_x into two halves turned by +fold/2 and -fold/2 more
// (a target folded along a vertical line, the paper's Fig. 7).
struct Target {
  std::string material;
  double depth_mm = 1000.0;
  double yaw_deg = 0.0;
  double pitch_deg = 0.0;
  double fold_deg = 0.0;
  // Pixel rectangle it covers, [x0, x1) x [y0, y1); centre is its middle.
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  // An outline within the rectangle: a closed polygon (vertices in pixel
  // coordinates, pixel (x, y)'s centre at (x + 0.5, y + 0.5)); the target
  // covers the rectangle's pixels whose centres lie inside it (even-odd
  // rule). Empty: the whole rectangle. At most kMaxOutline vertices.
  std::vector<std::array<double, 2>> outline;
  static constexpr std::size_t kMaxOutline = 4096;
};

// Which pixels of t's rectangle the target covers, row-major over the
// rectangle (1: covered); every pixel without an outline. Throws
// std::invalid_argument for an outline of fewer than 3 or more than
// kMaxOutline vertices, or a vertex that is not finite.
std::vector<std::uint8_t> target_mask(const Target& t);

struct Scene {
  std::vector<Target> targets;  // later ones cover earlier ones
  // A wall behind everything; an empty material means no return (read noise only).
  std::string background_material;
  double background_depth_mm = 3000.0;

  // A centred square target of `size` pixels: the hand-held / stage setup.
  static Scene centred_target(const std::string& material, double depth_mm, double yaw_deg, int size = 120);
};

}  // namespace tofmat::sim
