// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// BeltSim: the items generated along the belt, the scene the camera sees at a time, and the barrier edges they cause.
#include "tofmat/daemon/belt_sim.hpp"

#include <time.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <thread>

#include "tofmat/protocol/socket.hpp"

namespace tofmat::daemon {
namespace {

// The simulated Kinect v2's depth camera (firmware/sim's device profile).
constexpr double kFocalPx = 365.0, kCx = 256.0, kCy = 212.0, kWidthPx = 512.0;
constexpr std::size_t kMaxItems = 4096, kMaxTruthFrames = 64;
constexpr std::uint64_t kFirstArrivalNs = 1'000'000'000ull;  // a second to get going

std::uint64_t ns(double s) { return static_cast<std::uint64_t>(std::llround(s * 1e9)); }

}  // namespace

BeltSim::BeltSim(BeltSpec spec, std::shared_ptr<gpio::SimGpio> gpio)
    : spec_(std::move(spec)), gpio_(std::move(gpio)), rng_(spec_.seed) {
  const auto bad = [](const std::string& what) { throw std::invalid_argument("sim: belt: " + what); };
  if (spec_.materials.empty()) bad("no material");
  if (!(spec_.speed_mm_s >= 10 && spec_.speed_mm_s <= 5000)) bad("speed must be 10 to 5000 mm/s");
  if (!(spec_.rate_per_min > 0 && spec_.rate_per_min <= 6000)) bad("rate must be above 0 and at most 6000 items/min");
  if (!(spec_.item_mm >= 10 && spec_.item_mm <= 2000) || !(spec_.width_mm >= 10 && spec_.width_mm <= 2000))
    bad("item length and width must be 10 to 2000 mm");
  if (!(spec_.camera_mm >= 0 && spec_.camera_mm <= 100000)) bad("camera must be 0 to 100000 mm from the barrier");
  if (!(spec_.jitter >= 0 && spec_.jitter <= 1)) bad("jitter must be 0 to 1");
  next_arrival_ns_ = kFirstArrivalNs;
}

void BeltSim::start(std::uint64_t t0_ns) { t0_ns_ = t0_ns; }

const BeltSim::Item& BeltSim::item(std::uint64_t number) {
  while (items_.empty() || items_.back().number < number) {
    Item it;
    it.number = items_.empty() ? 1 : items_.back().number + 1;
    it.arrival_ns = next_arrival_ns_;
    it.material = spec_.materials[rng_() % spec_.materials.size()];
    // The next: the mean gap varied by the jitter, but never onto this one
    // (a loader puts items down one after another, 20 mm apart at least).
    const double u = std::uniform_real_distribution<double>(-0.5, 0.5)(rng_);
    const double gap_s =
        std::max(60.0 / spec_.rate_per_min * (1.0 + spec_.jitter * u), (spec_.item_mm + 20.0) / spec_.speed_mm_s);
    next_arrival_ns_ += ns(gap_s);
    items_.push_back(std::move(it));
    if (items_.size() > kMaxItems) items_.pop_front();
  }
  const auto first = items_.front().number;
  if (number < first) throw std::logic_error("belt: item " + std::to_string(number) + " is long gone");
  return items_[number - first];
}

sim::Scene BeltSim::scene(std::uint64_t frame, std::uint64_t now_ns) {
  const std::uint64_t t0 = t0_ns_.load();
  const double t = now_ns > t0 ? static_cast<double>(now_ns - t0) * 1e-9 : 0.0;
  const double mm_per_px = spec_.depth_mm / kFocalPx;
  const double view_lo = spec_.camera_mm - kCx * mm_per_px, view_hi = spec_.camera_mm + (kWidthPx - kCx) * mm_per_px;
  sim::Scene scene;  // (the belt itself returns nothing: read noise only)
  std::vector<std::string> materials;
  std::lock_guard<std::mutex> lock(mutex_);
  for (std::uint64_t n = items_.empty() ? 1 : items_.front().number;; ++n) {
    const Item& it = item(n);
    const double lead = spec_.speed_mm_s * (t - static_cast<double>(it.arrival_ns) * 1e-9);
    if (lead < view_lo) break;  // this one and every later one are still upstream of the view
    const double trail = lead - spec_.item_mm;
    if (trail > view_hi) continue;  // gone past
    sim::Target target;
    target.material = it.material;
    target.depth_mm = spec_.depth_mm;
    target.yaw_deg = spec_.yaw_deg;
    target.x0 = std::clamp(static_cast<int>(std::lround(kCx + (trail - spec_.camera_mm) / mm_per_px)), 0, 512);
    target.x1 = std::clamp(static_cast<int>(std::lround(kCx + (lead - spec_.camera_mm) / mm_per_px)), 0, 512);
    target.y0 = std::clamp(static_cast<int>(std::lround(kCy - spec_.width_mm / 2 / mm_per_px)), 0, 424);
    target.y1 = std::clamp(static_cast<int>(std::lround(kCy + spec_.width_mm / 2 / mm_per_px)), 0, 424);
    if (target.x1 <= target.x0 || target.y1 <= target.y0) continue;
    scene.targets.push_back(target);
    materials.push_back(it.material);
  }
  truth_[frame] = std::move(materials);
  while (truth_.size() > kMaxTruthFrames) truth_.erase(truth_.begin());
  return scene;
}

std::vector<std::string> BeltSim::truth_materials(std::uint64_t frame) const {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto it = truth_.find(frame);
  return it == truth_.end() ? std::vector<std::string>{} : it->second;
}

std::vector<BeltSim::Item> BeltSim::items_until(std::uint64_t now_ns) {
  const std::uint64_t t0 = t0_ns_.load();
  const std::uint64_t t = now_ns > t0 ? now_ns - t0 : 0;
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<Item> out;
  for (std::uint64_t n = items_.empty() ? 1 : items_.front().number; item(n).arrival_ns <= t; ++n)
    out.push_back(item(n));
  return out;
}

std::optional<std::string> BeltSim::item_at(std::uint64_t edge_ns) const {
  const std::uint64_t t0 = t0_ns_.load();
  std::lock_guard<std::mutex> lock(mutex_);
  for (const Item& it : items_) {
    const std::uint64_t at = t0 + it.arrival_ns;
    if ((at > edge_ns ? at - edge_ns : edge_ns - at) <= 20'000'000ull) return it.material;
  }
  return std::nullopt;
}

void BeltSim::run(const std::atomic<bool>& stop) {
  if (!gpio_) return;
  const bool blocked_level = !spec_.barrier_active_low;
  gpio_->drive(spec_.barrier_line, !blocked_level, t0_ns_.load());  // the beam clear
  const std::uint64_t pass_ns = ns(spec_.item_mm / spec_.speed_mm_s);
  for (std::uint64_t n = 1; !stop.load(); ++n) {
    std::uint64_t arrival;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      arrival = item(n).arrival_ns;
    }
    for (const auto& [at, blocked] : {std::pair{arrival, true}, std::pair{arrival + pass_ns, false}}) {
      const std::uint64_t when = t0_ns_.load() + at;
      // (Sleeps in short steps: a stop is seen within 50 ms.)
      for (std::uint64_t now = protocol::monotonic_ns(); now < when && !stop.load(); now = protocol::monotonic_ns()) {
        const std::uint64_t step = std::min<std::uint64_t>(when - now, 50'000'000ull);
        timespec ts{static_cast<time_t>(step / 1'000'000'000ull), static_cast<long>(step % 1'000'000'000ull)};
        ::nanosleep(&ts, nullptr);
      }
      if (stop.load()) return;
      gpio_->drive(spec_.barrier_line, blocked ? blocked_level : !blocked_level, when);
    }
  }
}

}  // namespace tofmat::daemon
