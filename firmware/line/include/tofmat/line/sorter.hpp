// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The sorting line's schedule (issue 17): a FIFO of the items on the belt,
// from the light barrier past the camera to the outlets. Everything is kept
// in belt positions (BeltMotion turns them into times), so a belt that slows
// or stops delays every step with it.
//
// An item's life: the barrier confirms it (TriggerFilter) -> it reaches the
// camera (`camera_mm` on from the barrier): a burst of frames starts ->
// the burst's label decides its outlet -> it reaches that outlet: the
// outlet's pusher is driven for its pulse -> it leaves at the belt's end.
// Fail safe: an item goes to the reject outlet when it came too close to the
// one before, found the camera busy with that one or lost, got no confident
// label, got a material no outlet takes, or got its label too late to fire in
// time (`decision_margin` before the outlet). A late label or a lost camera
// raises the alarm; every decision and every fault is reported.
// Pure: no clock, no GPIO, no threads; the caller feeds events and the time,
// and acts on what it is told through Hooks.
#pragma once
#include <cstdint>
#include <deque>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "tofmat/line/belt_motion.hpp"
#include "tofmat/line/trigger_filter.hpp"

namespace tofmat::line {

struct Outlet {
  std::string name;
  std::vector<std::string> materials;  // labels sent here (none: the reject outlet)
  double position_mm = 0;              // barrier -> the pusher, along the belt
  std::uint64_t pulse_ns = 50'000'000;
};

struct SorterConfig {
  double camera_mm = 200;  // barrier -> where the item is under the camera's ROI
  std::vector<Outlet> outlets;
  // The reject outlet's index in `outlets` (its pusher fires for rejects);
  // none: rejects ride on to the belt's end.
  std::optional<std::size_t> reject;
  std::uint64_t decision_margin_ns = 20'000'000;  // a label must come this long before its outlet fires
  std::uint64_t alarm_hold_ns = 5'000'000'000;    // a late label keeps the alarm on this long
  std::size_t max_items = 256;                    // on the belt at once (more: rejected and reported)
};
// Throws std::invalid_argument naming what is wrong (no outlet, a position
// behind the camera, a material in two outlets, a reject index out of range...).
void validate(const SorterConfig& config);

// Why an item went where it went.
enum class Reason {
  kSorted,
  kTooClose,
  kCameraBusy,
  kCameraLost,
  kNoTarget,
  kMixed,
  kUnknown,
  kNotConfident,
  kNoOutlet,
  kLate,
  kFull,
  kOutOfRange  // the item was seen only at depths the table's bins miss (protocol minor 11)
};
const char* reason_name(Reason r);

// A label for a burst, as the pipeline gave it.
struct BurstLabel {
  std::uint64_t trigger = 0;  // the burst's number (Hooks::start_burst)
  std::string material;       // "" when no target was seen
  bool confident = false;
  double distance = 0;
  std::optional<std::string> truth;  // a simulated item's real material (passed on, never used)
  bool mixed = false;                // the burst's frames disagreed (another item in the ROI): never sorted
  bool unknown = false;              // no material of the table explains it (open set): never sorted
  bool out_of_range = false;         // seen only at depths the table's bins miss (material ""): never sorted
};

struct SortEvent {
  std::string state;  // "decided" (the outlet is chosen; fire_ns planned) or "fired" (it was driven)
  std::uint64_t item = 0;
  std::uint64_t trigger_ns = 0;  // the barrier's edge
  std::string material;          // "" if none
  double distance = 0;
  std::string outlet;  // "" when rejects ride to the belt's end
  Reason reason = Reason::kSorted;
  std::uint64_t decided_ns = 0;
  std::optional<std::uint64_t> fire_ns;  // planned ("decided") or done ("fired"); none: no pusher / belt stopped
  double margin_ms = 0;                  // fire time minus decision time (how early the label came)
  std::optional<std::string> truth;      // a simulated item's real material, when its burst knew it
};

struct Hooks {
  // Start a burst for an item now; its number, or nullopt when it could not
  // start (no camera).
  std::function<std::optional<std::uint64_t>(std::uint64_t item)> start_burst;
  std::function<void(std::size_t outlet, bool on)> drive;
  std::function<void(bool on)> alarm;
  std::function<void(const SortEvent&)> event;
  std::function<void(const std::string& kind, const std::string& message)> fault;
};

class Sorter {
 public:
  // Throws std::invalid_argument (validate).
  Sorter(SorterConfig config, const BeltMotion& motion, Hooks hooks);

  // An item confirmed by the barrier, at `now_ns` (its edge may be earlier).
  void item(const ItemStart& start, std::uint64_t now_ns);
  void label(const BurstLabel& label, std::uint64_t now_ns);
  void camera(bool streaming, std::uint64_t now_ns);
  // Everything due by `now_ns`: bursts to start, pushers on and off, items
  // past their deadline, the alarm's hold.
  void poll(std::uint64_t now_ns);
  // When poll() next has something to do (nullopt: nothing scheduled, or
  // waiting on the belt to move).
  std::optional<std::uint64_t> next_wake(std::uint64_t now_ns) const;

  std::size_t on_belt() const { return items_.size(); }
  bool alarm_on() const { return alarm_; }
  struct Counts {
    std::uint64_t items = 0, sorted = 0, rejected = 0, late = 0, faults = 0;
  };
  const Counts& counts() const { return counts_; }
  const SorterConfig& config() const { return config_; }

 private:
  enum class Stage { kToCamera, kMeasuring, kDecided, kPassed };
  struct Item {
    std::uint64_t number = 0;
    std::uint64_t trigger_ns = 0;
    double start_mm = 0;  // the belt's position at the barrier's edge
    Stage stage = Stage::kToCamera;
    std::optional<std::uint64_t> burst;
    std::optional<std::size_t> outlet;  // where it goes (none: the belt's end)
    SortEvent event;
  };
  void decide(Item& it, std::optional<std::size_t> outlet, Reason reason, const BurstLabel* label,
              std::uint64_t now_ns);
  void reject(Item& it, Reason reason, std::uint64_t now_ns) { decide(it, config_.reject, reason, nullptr, now_ns); }
  // Too late to be sorted (no label in time, or one too late for its
  // outlet): reject, counted, reported, and the alarm held on.
  void late(Item& it, const std::string& why, const BurstLabel* label, std::uint64_t now_ns);
  std::optional<std::size_t> outlet_for(const std::string& material) const;
  double end_mm() const;
  std::optional<std::uint64_t> decision_deadline(const Item& it, std::uint64_t now_ns) const;
  void set_alarm(std::uint64_t now_ns);
  void fault(const std::string& kind, const std::string& message);

  SorterConfig config_;
  const BeltMotion& motion_;
  Hooks hooks_;
  std::deque<Item> items_;                                  // in the order they are on the belt
  std::vector<std::optional<std::uint64_t>> outlet_until_;  // a pusher on: until when
  std::uint64_t next_item_ = 1;
  bool camera_ok_ = true;
  std::uint64_t late_until_ns_ = 0;
  bool alarm_ = false;
  Counts counts_;
};

}  // namespace tofmat::line
