// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The `sim` source: parsing its scene spec, the scripted scenes, and the simulated Kinect v2 or belt behind the driver.
#include "tofmat/daemon/sim_source.hpp"

#include <pthread.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <set>
#include <stdexcept>
#include <thread>

#include "spec_text.hpp"
#include "tofmat/core/decode.hpp"
#include "tofmat/daemon/belt_sim.hpp"
#include "tofmat/daemon/device_source.hpp"
#include "tofmat/protocol/socket.hpp"
#include "tofmat/sim/kinect_device.hpp"
#include "tofmat/sim/profile_io.hpp"
#include "tofmat/sim/renderer.hpp"

namespace tofmat::daemon {
namespace {

double to_number(const std::string& key, const std::string& value) {
  if (const auto v = whole_number(value)) return *v;
  throw std::invalid_argument("sim: " + key + "=" + value + " is not a number");
}

int to_int(const std::string& key, const std::string& value, int lo, int hi) {
  const double v = to_number(key, value);
  if (v != std::floor(v) || v < lo || v > hi)
    throw std::invalid_argument("sim: " + key + " must be an integer in [" + std::to_string(lo) + ", " +
                                std::to_string(hi) + "], got " + value);
  return static_cast<int>(v);
}

// The simulated camera over a simulated belt: the belt starts with the
// source and drives the simulated light barrier on a thread of its own for
// as long as the source runs.
class BeltSource : public Source {
 public:
  BeltSource(std::unique_ptr<Source> camera, std::shared_ptr<BeltSim> belt)
      : camera_(std::move(camera)), belt_(std::move(belt)) {}
  std::string describe() const override { return camera_->describe(); }
  bool simulated() const override { return true; }
  nlohmann::json counters() const override { return camera_->counters(); }
  std::optional<std::string> item_truth(std::uint64_t edge_ns) const override { return belt_->item_at(edge_ns); }
  void run(const SourceCallbacks& callbacks, const std::atomic<bool>& stop) override {
    belt_->start(protocol::monotonic_ns());
    std::atomic<bool> belt_stop{false};
    std::thread barrier([&] {
      ::pthread_setname_np(::pthread_self(), "tofmatd-belt");
      try {
        belt_->run(belt_stop);
      } catch (const std::exception& e) {
        callbacks.state(DeviceState::kFailed, std::string("the simulated belt stopped: ") + e.what());
      }
    });
    try {
      camera_->run(callbacks, stop);
    } catch (...) {
      belt_stop = true;
      barrier.join();
      throw;
    }
    belt_stop = true;
    barrier.join();
  }

 private:
  std::unique_ptr<Source> camera_;
  std::shared_ptr<BeltSim> belt_;
};

}  // namespace

namespace {

// The objects scene: a plane of the last material filling the frame, tilted
// by yaw and pitch, at `far` through the centre; in front of it the other
// materials as flat objects of irregular (non-convex) outlines, each turned
// its own way, at depths from `near` to halfway to `far`.
sim::Scene objects_scene(const SimSpec& spec) {
  constexpr int kVertices = 72;
  constexpr double kRadius = 54.0;  // pixels; the lobes reach 1.37 times it
  sim::Scene scene;
  const std::size_t n_objects = spec.materials.size() - 1;
  sim::Target plane;
  plane.material = spec.materials.back();
  plane.x0 = 0;
  plane.y0 = 0;
  plane.x1 = kWidth;
  plane.y1 = kHeight;
  plane.depth_mm = spec.far_mm;
  plane.yaw_deg = spec.yaw_deg;
  plane.pitch_deg = spec.pitch_deg;
  scene.targets.push_back(plane);
  for (std::size_t i = 0; i < n_objects; ++i) {
    const int col = static_cast<int>(i % 3), row = static_cast<int>(i / 3);
    const double cx = 96.0 + 160.0 * col + (row == 1 ? 80.0 : 0.0), cy = 120.0 + 190.0 * row;
    const double k = static_cast<double>(i);
    sim::Target t;
    t.material = spec.materials[i];
    double x_lo = 1e9, x_hi = -1e9, y_lo = 1e9, y_hi = -1e9;
    for (int v = 0; v < kVertices; ++v) {
      const double a = 2.0 * tofmat::kPi * v / kVertices;
      const double r = kRadius * (1.0 + 0.25 * std::sin(3.0 * a + 1.7 * k) + 0.12 * std::sin(5.0 * a + 0.9 + 2.3 * k));
      const double x = cx + r * std::cos(a), y = cy + r * std::sin(a);
      t.outline.push_back({x, y});
      x_lo = std::min(x_lo, x);
      x_hi = std::max(x_hi, x);
      y_lo = std::min(y_lo, y);
      y_hi = std::max(y_hi, y);
    }
    t.x0 = std::max(0, static_cast<int>(std::floor(x_lo)));
    t.x1 = std::min(kWidth, static_cast<int>(std::ceil(x_hi)) + 1);
    t.y0 = std::max(0, static_cast<int>(std::floor(y_lo)));
    t.y1 = std::min(kHeight, static_cast<int>(std::ceil(y_hi)) + 1);
    t.depth_mm = n_objects > 1
                     ? spec.near_mm + 0.5 * (spec.far_mm - spec.near_mm) * k / static_cast<double>(n_objects - 1)
                     : spec.near_mm;
    t.yaw_deg = (i % 2 == 0 ? 15.0 : -15.0);
    t.pitch_deg = (i % 3 == 0 ? -10.0 : 10.0);
    scene.targets.push_back(t);
  }
  return scene;
}

}  // namespace

SimSpec parse_sim_spec(const std::string& text) {
  SimSpec s;
  auto parts = split(text, ',');
  std::size_t first = 0;
  if (!parts.empty() && parts[0].find('=') == std::string::npos) {
    if (!parts[0].empty()) s.scene = parts[0];
    first = 1;
  }
  if (s.scene != "sweep" && s.scene != "static" && s.scene != "regions" && s.scene != "objects" && s.scene != "belt")
    throw std::invalid_argument("sim: unknown scene \"" + s.scene + "\" (sweep, static, regions, objects, belt)");
  for (std::size_t i = first; i < parts.size(); ++i) {
    const auto eq = parts[i].find('=');
    if (eq == std::string::npos) throw std::invalid_argument("sim: \"" + parts[i] + "\" is not key=value");
    const std::string key = parts[i].substr(0, eq), value = parts[i].substr(eq + 1);
    if (key == "material") {
      s.materials = {value};
    } else if (key == "materials") {
      s.materials = split(value, '+');
      if (s.materials.empty() || s.materials.size() > 64)
        throw std::invalid_argument("sim: materials= needs 1 to 64 names joined by +");
    } else if (key == "frames") {
      s.frames = to_int(key, value, 2, 100000);
    } else if (key == "gap") {
      s.gap = to_int(key, value, 0, 100000);
    } else if (key == "near") {
      s.near_mm = to_number(key, value);
    } else if (key == "far") {
      s.far_mm = to_number(key, value);
    } else if (key == "depth") {
      s.depth_mm = to_number(key, value);
    } else if (key == "yaw") {
      s.yaw_deg = to_number(key, value);
    } else if (key == "pitch") {
      s.pitch_deg = to_number(key, value);
    } else if (key == "size") {
      s.size = to_int(key, value, 4, 424);
    } else if (key == "realtime") {
      s.realtime = to_int(key, value, 0, 1) == 1;
    } else if (key == "seed") {
      s.seed = static_cast<std::uint64_t>(to_int(key, value, 0, 1 << 30));
    } else if (key == "device") {
      s.device = value;
    } else if (key == "library") {
      s.library = value;
    } else if (key == "unplug_at") {
      s.unplug_at = to_int(key, value, 0, 1 << 30);
    } else if (key == "replug_ms") {
      s.replug_ms = to_int(key, value, 0, 3600000);
    } else if (key == "presses") {
      for (const auto& f : split(value, '+'))
        s.presses.push_back(static_cast<std::uint64_t>(to_int(key, f, 0, 1 << 30)));
      if (s.presses.empty() || s.presses.size() > 64)
        throw std::invalid_argument("sim: presses= needs 1 to 64 frame numbers joined by +");
    } else if (key == "speed") {
      s.belt.speed_mm_s = to_number(key, value);
    } else if (key == "rate") {
      s.belt.rate_per_min = to_number(key, value);
    } else if (key == "item") {
      s.belt.item_mm = to_number(key, value);
    } else if (key == "width") {
      s.belt.width_mm = to_number(key, value);
    } else if (key == "camera") {
      s.belt.camera_mm = to_number(key, value);
    } else if (key == "jitter") {
      s.belt.jitter = to_number(key, value);
    } else {
      throw std::invalid_argument("sim: unknown key \"" + key + "\"");
    }
  }
  for (double d : {s.near_mm, s.far_mm, s.depth_mm})
    if (d < 300.0 || d > 8000.0) throw std::invalid_argument("sim: depths must lie in [300, 8000] mm");
  if (std::abs(s.yaw_deg) > 85.0) throw std::invalid_argument("sim: yaw must lie in [-85, 85] degrees");
  if (std::abs(s.pitch_deg) > 85.0) throw std::invalid_argument("sim: pitch must lie in [-85, 85] degrees");
  if (s.scene == "regions" && s.materials.size() > 6)
    throw std::invalid_argument("sim: the regions scene holds at most 6 materials");
  if (s.scene == "objects" && (s.materials.size() < 2 || s.materials.size() > 6))
    throw std::invalid_argument("sim: the objects scene needs 2 to 6 materials (objects, then the plane's)");
  return s;
}

sim::Scene sim_scene_at(const SimSpec& spec, std::uint64_t frame) {
  if (spec.scene == "static")
    return sim::Scene::centred_target(spec.materials[0], spec.depth_mm, spec.yaw_deg, spec.size);
  if (spec.scene == "regions") {
    // A 3 x 2 grid of rectangles with a margin, depths spread near..far.
    sim::Scene scene;
    const std::size_t n = spec.materials.size();
    for (std::size_t i = 0; i < n; ++i) {
      sim::Target t;
      t.material = spec.materials[i];
      const int col = static_cast<int>(i % 3), row = static_cast<int>(i / 3);
      t.x0 = 16 + col * 164;
      t.x1 = t.x0 + 152;
      t.y0 = 32 + row * 188;
      t.y1 = t.y0 + 172;
      t.depth_mm =
          n > 1 ? spec.near_mm + (spec.far_mm - spec.near_mm) * static_cast<double>(i) / static_cast<double>(n - 1)
                : spec.depth_mm;
      t.yaw_deg = spec.yaw_deg;
      scene.targets.push_back(t);
    }
    return scene;
  }
  if (spec.scene == "objects") return objects_scene(spec);
  const std::uint64_t period = static_cast<std::uint64_t>(spec.frames + spec.gap);
  const std::uint64_t k = frame / period, t = frame % period;
  if (t >= static_cast<std::uint64_t>(spec.frames)) return sim::Scene{};  // nothing in front of the camera
  const std::string& material = spec.materials[k % spec.materials.size()];
  const double depth = spec.near_mm + (spec.far_mm - spec.near_mm) * static_cast<double>(t) / (spec.frames - 1);
  return sim::Scene::centred_target(material, depth, spec.yaw_deg, spec.size);
}

std::unique_ptr<Source> make_sim_source(const SimSpec& spec, const SourceOptions& options) {
  if (options.sim_data_dir.empty())
    throw std::invalid_argument(
        "sim: the simulator's data (device profiles, material libraries) was not found beside this tofmatd: "
        "pass --sim-data DIR");
  auto device = sim::load_device(spec.device, options.sim_data_dir);
  auto library = sim::load_library(spec.library, options.sim_data_dir);
  for (const auto& m : spec.materials) library.find(m);  // throws, naming a material the library lacks
  // One render thread: the daemon's other threads need the other core.
  auto renderer = std::make_shared<const sim::Renderer>(std::move(device), std::move(library), 1);
  const SimSpec s = spec;
  std::shared_ptr<BeltSim> belt;
  if (spec.scene == "belt") {
    // (The keys every scene has: the belt's own are parsed into spec.belt.)
    BeltSpec b = spec.belt;
    b.materials = spec.materials;
    b.depth_mm = spec.depth_mm;
    b.yaw_deg = spec.yaw_deg;
    b.seed = spec.seed;
    belt = std::make_shared<BeltSim>(b, options.sim_gpio);
  }
  // (The belt's frames show it as it is when they are taken: by the clock, not the frame count.)
  sim::SimulatedKinect::SceneAt scene_at = [s](std::uint64_t frame) { return sim_scene_at(s, frame); };
  if (belt) scene_at = [belt](std::uint64_t frame) { return belt->scene(frame, protocol::monotonic_ns()); };
  if (!spec.presses.empty()) {
    if (!options.sim_gpio)
      throw std::invalid_argument("sim: presses= presses a button on the simulated GPIO chip: it needs --gpio sim");
    // A finger on the button at the frame, off it three frames (100 ms) later.
    auto gpio = options.sim_gpio;
    gpio->drive(kSimButtonLine, true, protocol::monotonic_ns());  // released (pulled up)
    const std::set<std::uint64_t> presses(spec.presses.begin(), spec.presses.end());
    scene_at = [inner = std::move(scene_at), gpio, presses](std::uint64_t frame) {
      if (presses.count(frame)) gpio->drive(kSimButtonLine, false, protocol::monotonic_ns());
      if (frame >= 3 && presses.count(frame - 3)) gpio->drive(kSimButtonLine, true, protocol::monotonic_ns());
      return inner(frame);
    };
  }
  auto kinect = std::make_shared<sim::SimulatedKinect>(renderer, scene_at, spec.realtime);
  if (spec.unplug_at >= 0) {
    sim::KinectFaults faults;
    faults.unplug_at_frame = spec.unplug_at;
    kinect->set_faults(faults);
  }
  // The simulated replug: once unplugged, the next open after replug_ms
  // plugs it back in (as a person would) and only then succeeds.
  auto unplugged_since = std::make_shared<std::chrono::steady_clock::time_point>();
  const int replug_ms = spec.replug_ms;
  auto open = [kinect, unplugged_since, replug_ms]() -> std::unique_ptr<kinect::UsbTransport> {
    if (!kinect->plugged()) {
      const auto now = std::chrono::steady_clock::now();
      if (*unplugged_since == std::chrono::steady_clock::time_point{}) *unplugged_since = now;
      if (now - *unplugged_since >= std::chrono::milliseconds(replug_ms)) {
        kinect->replug();
        *unplugged_since = {};
      }
    }
    return kinect->connect();
  };
  auto truth = [kinect, s, belt](std::uint32_t sequence) -> std::shared_ptr<const FrameTruth> {
    auto frame = kinect->truth(sequence);
    if (!frame || frame->width != kWidth || frame->height != kHeight) return nullptr;
    auto t = std::make_shared<FrameTruth>();
    if (belt)
      t->materials = belt->truth_materials(sequence);
    else
      for (const auto& target : sim_scene_at(s, sequence).targets) t->materials.push_back(target.material);
    t->target = frame->target;
    t->depth_mm = frame->depth_mm;
    return t;
  };
  std::string description = "simulated Kinect v2 (scene " + spec.scene + ", device " + spec.device + ")";
  auto camera =
      std::make_unique<DeviceSource>(description, open, truth, std::min(options.retry_ms, 100), /*simulated=*/true);
  if (!belt) return camera;
  return std::make_unique<BeltSource>(std::move(camera), belt);
}

}  // namespace tofmat::daemon
