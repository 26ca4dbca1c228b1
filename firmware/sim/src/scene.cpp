// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Scene::centred_target: a scene of one square target at the centre of the image.
#include "tofmat/sim/scene.hpp"

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

}  // namespace tofmat::sim
