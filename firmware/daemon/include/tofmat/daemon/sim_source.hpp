// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// `--source sim[:SCENE[,key=value...]]`: the simulated Kinect v2 (firmware/sim)
// behind the driver, looking at a scripted scene, with its ground truth.
//
// Scenes:
//   sweep    (default) targets of `materials` one after another, each moved by
//            hand from `near` to `far` mm over `frames` frames, then `gap`
//            frames with nothing in front of the camera (a hand-held sweep)
//   static   one target of the first material at `depth` mm
//   regions  up to six materials side by side at depths from `near` to
//            `far` (a scene for the segmentation profile)
//   belt     a conveyor carrying items of `materials` under the camera
//            (belt_sim.hpp): speed=MM/S, rate=ITEMS/MIN, item=MM, width=MM,
//            camera=MM (barrier to the optical axis), jitter=0..1, depth=MM
//            (camera to the items), yaw=DEG (the items' surface askew to the
//            camera, as tables are recorded); with tofmatd --gpio sim it
//            drives the simulated light barrier
// Keys: materials=a+b+c (or material=a), frames=N, gap=N, near=MM, far=MM, depth=MM, yaw=DEG,
// size=PIXELS, realtime=0|1 (30 frames/s, default 1), seed=N,
// device=NAME, library=NAME, unplug_at=FRAME, replug_ms=MS (the simulated
// device is unplugged in the middle of that frame and plugged back after MS).
#pragma once
#include <string>
#include <vector>

#include "tofmat/daemon/belt_sim.hpp"
#include "tofmat/daemon/source.hpp"
#include "tofmat/sim/scene.hpp"

namespace tofmat::daemon {

struct SimSpec {
  std::string scene = "sweep";
  std::vector<std::string> materials = {"cork", "pvc", "wood", "paper", "acryl"};
  int frames = 90;
  int gap = 15;
  double near_mm = 600.0, far_mm = 1200.0, depth_mm = 900.0;
  double yaw_deg = 10.0;
  double pitch_deg = 20.0;  // objects: the plane's tilt about the horizontal axis
  int size = 160;
  bool realtime = true;
  std::uint64_t seed = 1;
  std::string device = "kinect2_tanaka2017";
  std::string library = "tanaka2017";
  std::int64_t unplug_at = -1;
  int replug_ms = 500;
  // Frames at which the simulated front-panel button (line "button" of the
  // simulated GPIO chip, low while pressed) is pressed, for 100 ms each.
  std::vector<std::uint64_t> presses;
  // belt: its own keys (materials, depth, yaw and seed are the ones above)
  BeltSpec belt;
};

// The simulated GPIO chip's line that sim's presses= drives.
inline constexpr const char* kSimButtonLine = "button";

// The text after "sim:" (may be empty). Throws std::invalid_argument.
SimSpec parse_sim_spec(const std::string& text);
// The scene at a frame index.
sim::Scene sim_scene_at(const SimSpec& spec, std::uint64_t frame);

std::unique_ptr<Source> make_sim_source(const SimSpec& spec, const SourceOptions& options);

}  // namespace tofmat::daemon
