// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The simulated sorting line (issue 17): a conveyor belt carrying items of
// the scene's materials past a light barrier and under the simulated
// camera. `--source sim:belt,...` renders the items where they are on the
// belt when each frame is taken; with `--gpio sim` the same belt drives the
// simulated chip's barrier line (edges at the moments items cross it, with
// those moments as their timestamps), so tofmatd's sorting line runs end to
// end on the one clock (CLOCK_MONOTONIC) without hardware.
//
// Geometry: the camera looks straight down at the belt from `depth` mm; the
// image's x axis runs along the belt, items move towards +x; the camera's
// optical axis meets the belt `camera` mm past the barrier. Items are
// `item` mm long and `width` mm wide, arrive `60 / rate` s apart on average
// (each gap varied by up to +-jitter/2 of it), and their materials are drawn
// from the scene's list with the seed.
#pragma once
#include <atomic>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "tofmat/gpio/sim_gpio.hpp"
#include "tofmat/sim/scene.hpp"

namespace tofmat::daemon {

struct BeltSpec {
  // (sim:belt sets these four from the keys every scene has.)
  std::vector<std::string> materials;
  double speed_mm_s = 500, rate_per_min = 60, item_mm = 160, width_mm = 140, depth_mm = 900, camera_mm = 300;
  double jitter = 0.3;
  // The items' surface turned this far from facing the camera (about the
  // image's vertical axis): a camera mounted askew, as the tables are
  // recorded (sim table: 10 degrees); straight on, glossy surfaces return
  // their specular glint and read differently.
  double yaw_deg = 10;
  std::uint64_t seed = 1;
  std::string barrier_line = "barrier";  // on the simulated chip
  bool barrier_active_low = true;        // the pin is low while an item interrupts the beam
};

class BeltSim {
 public:
  struct Item {
    std::uint64_t number = 0;      // from 1, in the order they reach the barrier
    std::uint64_t arrival_ns = 0;  // its leading edge at the barrier, since the belt started
    std::string material;
  };
  // Throws std::invalid_argument for values that make no belt.
  BeltSim(BeltSpec spec, std::shared_ptr<gpio::SimGpio> gpio);

  // The belt starts moving (its time 0) at `t0_ns` (CLOCK_MONOTONIC).
  void start(std::uint64_t t0_ns);
  // What the camera sees at `now_ns` (a frame being taken), remembered under
  // `frame` for its truth.
  sim::Scene scene(std::uint64_t frame, std::uint64_t now_ns);
  // The materials of the targets of the scene rendered for `frame` (target
  // index -> material), or empty if it is no longer remembered.
  std::vector<std::string> truth_materials(std::uint64_t frame) const;
  // Drives the barrier line until `stop`: each item's edges at their moments.
  void run(const std::atomic<bool>& stop);
  // The items that have reached the barrier by `now_ns`, oldest first (bounded).
  std::vector<Item> items_until(std::uint64_t now_ns);
  // The material of the item whose leading edge reached the barrier at
  // `edge_ns` (within 20 ms), if it is still remembered.
  std::optional<std::string> item_at(std::uint64_t edge_ns) const;
  const BeltSpec& spec() const { return spec_; }

 private:
  const Item& item(std::uint64_t number);  // generated on demand (mutex held)
  BeltSpec spec_;
  std::shared_ptr<gpio::SimGpio> gpio_;
  std::atomic<std::uint64_t> t0_ns_{0};
  mutable std::mutex mutex_;
  std::mt19937_64 rng_;
  std::deque<Item> items_;  // generated so far (the oldest dropped past the view)
  std::uint64_t next_arrival_ns_ = 0;
  std::map<std::uint64_t, std::vector<std::string>> truth_;  // recent frames
};

}  // namespace tofmat::daemon
