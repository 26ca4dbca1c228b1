// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Sorter: the FIFO of items on the belt, their decisions from burst labels, the outlets' pulses, faults and the alarm.
#include "tofmat/line/sorter.hpp"

#include <algorithm>
#include <cmath>
#include <set>
#include <stdexcept>

namespace tofmat::line {

const char* reason_name(Reason r) {
  switch (r) {
    case Reason::kSorted: return "sorted";
    case Reason::kTooClose: return "too_close";
    case Reason::kCameraBusy: return "camera_busy";
    case Reason::kCameraLost: return "camera_lost";
    case Reason::kNoTarget: return "no_target";
    case Reason::kMixed: return "mixed";
    case Reason::kUnknown: return "unknown";
    case Reason::kNotConfident: return "not_confident";
    case Reason::kNoOutlet: return "no_outlet";
    case Reason::kLate: return "late";
    case Reason::kFull: return "full";
    case Reason::kOutOfRange: return "out_of_range";
  }
  return "?";
}

void validate(const SorterConfig& c) {
  const auto bad = [](const std::string& what) { throw std::invalid_argument("sorting line: " + what); };
  if (!(c.camera_mm >= 0) || !std::isfinite(c.camera_mm)) bad("the camera's distance from the barrier must be >= 0 mm");
  if (c.outlets.empty()) bad("no outlet configured");
  if (c.max_items == 0) bad("max items must be at least 1");
  if (c.reject && *c.reject >= c.outlets.size()) bad("the reject outlet is not one of the outlets");
  std::set<std::string> names, materials;
  for (std::size_t k = 0; k < c.outlets.size(); ++k) {
    const Outlet& o = c.outlets[k];
    if (o.name.empty()) bad("an outlet has no name");
    if (!names.insert(o.name).second) bad("two outlets are named \"" + o.name + "\"");
    if (!std::isfinite(o.position_mm) || o.position_mm <= c.camera_mm)
      bad("outlet \"" + o.name + "\" must be further along the belt than the camera (" + std::to_string(c.camera_mm) +
          " mm from the barrier)");
    if (o.pulse_ns == 0) bad("outlet \"" + o.name + "\" has a pulse of 0 ms");
    const bool is_reject = c.reject && *c.reject == k;
    if (is_reject && !o.materials.empty()) bad("the reject outlet \"" + o.name + "\" takes no material");
    if (!is_reject && o.materials.empty()) bad("outlet \"" + o.name + "\" takes no material");
    for (const auto& m : o.materials)
      if (!materials.insert(m).second) bad("material \"" + m + "\" goes to two outlets");
  }
}

Sorter::Sorter(SorterConfig config, const BeltMotion& motion, Hooks hooks)
    : config_(std::move(config)), motion_(motion), hooks_(std::move(hooks)) {
  validate(config_);
  outlet_until_.assign(config_.outlets.size(), std::nullopt);
}

double Sorter::end_mm() const {
  double end = config_.camera_mm;
  for (const auto& o : config_.outlets) end = std::max(end, o.position_mm);
  return end + 1.0;
}

std::optional<std::size_t> Sorter::outlet_for(const std::string& material) const {
  for (std::size_t k = 0; k < config_.outlets.size(); ++k) {
    const auto& m = config_.outlets[k].materials;
    if (std::find(m.begin(), m.end(), material) != m.end()) return k;
  }
  return std::nullopt;
}

void Sorter::fault(const std::string& kind, const std::string& message) {
  ++counts_.faults;
  if (hooks_.fault) hooks_.fault(kind, message);
}

void Sorter::set_alarm(std::uint64_t now_ns) {
  const bool want = !camera_ok_ || now_ns < late_until_ns_;
  if (want == alarm_) return;
  alarm_ = want;
  if (hooks_.alarm) hooks_.alarm(want);
}

void Sorter::item(const ItemStart& start, std::uint64_t now_ns) {
  ++counts_.items;
  Item it;
  it.number = next_item_++;
  it.trigger_ns = start.timestamp_ns;
  it.start_mm = motion_.position_mm(start.timestamp_ns);
  it.event.item = it.number;
  it.event.trigger_ns = it.trigger_ns;
  if (items_.size() >= config_.max_items) {
    fault("full", "item " + std::to_string(it.number) + ": " + std::to_string(items_.size()) +
                      " items on the belt already; not tracked (it rides to the belt's end)");
    it.event.state = "decided";
    it.event.reason = Reason::kFull;
    it.event.decided_ns = now_ns;
    ++counts_.rejected;
    if (hooks_.event) hooks_.event(it.event);
    return;
  }
  items_.push_back(it);
  Item& added = items_.back();
  if (start.too_close) {
    fault("too_close", "item " + std::to_string(added.number) + " came " + std::to_string(start.gap_ns / 1'000'000) +
                           " ms after the one before (less than the minimum gap): rejected, not merged");
    reject(added, Reason::kTooClose, now_ns);
  } else if (!camera_ok_) {
    reject(added, Reason::kCameraLost, now_ns);
  }
}

void Sorter::decide(Item& it, std::optional<std::size_t> outlet, Reason reason, const BurstLabel* label,
                    std::uint64_t now_ns) {
  if (outlet && motion_.position_mm(now_ns) > it.start_mm + config_.outlets[*outlet].position_mm) {
    fault("missed", "item " + std::to_string(it.number) + " passed outlet \"" + config_.outlets[*outlet].name +
                        "\" before it was decided; it rides to the belt's end");
    outlet.reset();
  }
  it.stage = Stage::kDecided;
  it.outlet = outlet;
  SortEvent& e = it.event;
  e.state = "decided";
  e.reason = reason;
  e.decided_ns = now_ns;
  if (label) {
    e.material = label->material;
    e.distance = label->distance;
    e.truth = label->truth;
  }
  e.outlet = outlet ? config_.outlets[*outlet].name : "";
  e.fire_ns = outlet ? motion_.time_at(it.start_mm + config_.outlets[*outlet].position_mm, now_ns) : std::nullopt;
  e.margin_ms = e.fire_ns ? static_cast<double>(static_cast<std::int64_t>(*e.fire_ns - now_ns)) * 1e-6 : 0.0;
  if (reason == Reason::kSorted)
    ++counts_.sorted;
  else
    ++counts_.rejected;
  if (hooks_.event) hooks_.event(e);
}

void Sorter::late(Item& it, const std::string& why, const BurstLabel* label, std::uint64_t now_ns) {
  ++counts_.late;
  late_until_ns_ = now_ns + config_.alarm_hold_ns;
  fault("late", "item " + std::to_string(it.number) + ": " + why + ": rejected");
  set_alarm(now_ns);
  decide(it, config_.reject, Reason::kLate, label, now_ns);
}

void Sorter::label(const BurstLabel& l, std::uint64_t now_ns) {
  const auto it = std::find_if(items_.begin(), items_.end(),
                               [&](const Item& i) { return i.stage == Stage::kMeasuring && i.burst == l.trigger; });
  if (it == items_.end()) return;  // (its item was decided without it: late, or the camera was lost)
  if (l.material.empty())
    return decide(*it, config_.reject, l.out_of_range ? Reason::kOutOfRange : Reason::kNoTarget, &l, now_ns);
  if (l.mixed) return decide(*it, config_.reject, Reason::kMixed, &l, now_ns);
  if (l.unknown) return decide(*it, config_.reject, Reason::kUnknown, &l, now_ns);
  if (!l.confident) return decide(*it, config_.reject, Reason::kNotConfident, &l, now_ns);
  const auto outlet = outlet_for(l.material);
  if (!outlet) return decide(*it, config_.reject, Reason::kNoOutlet, &l, now_ns);
  const auto fire = motion_.time_at(it->start_mm + config_.outlets[*outlet].position_mm, now_ns);
  if (fire && *fire < now_ns + config_.decision_margin_ns)
    return late(*it,
                "its label came " + std::to_string((now_ns + config_.decision_margin_ns - *fire) / 1'000'000) +
                    " ms too late for outlet \"" + config_.outlets[*outlet].name + "\"",
                &l, now_ns);
  decide(*it, outlet, Reason::kSorted, &l, now_ns);
}

void Sorter::camera(bool streaming, std::uint64_t now_ns) {
  if (streaming == camera_ok_) return;
  camera_ok_ = streaming;
  if (!streaming) {
    fault("camera", "the camera is lost: items go to reject until it is back");
    for (auto& it : items_)
      if (it.stage == Stage::kMeasuring) reject(it, Reason::kCameraLost, now_ns);
  }
  set_alarm(now_ns);
}

void Sorter::poll(std::uint64_t now_ns) {
  const double here = motion_.position_mm(now_ns);
  // Pushers whose pulse is over (an outlet fired again meanwhile keeps on).
  for (std::size_t k = 0; k < outlet_until_.size(); ++k)
    if (outlet_until_[k] && now_ns >= *outlet_until_[k]) {
      outlet_until_[k].reset();
      if (hooks_.drive) hooks_.drive(k, false);
    }
  const bool measuring =
      std::any_of(items_.begin(), items_.end(), [](const Item& i) { return i.stage == Stage::kMeasuring; });
  bool burst_started = false;
  for (auto& it : items_) {
    if (it.stage == Stage::kToCamera && here >= it.start_mm + config_.camera_mm) {
      if (measuring || burst_started) {
        fault("camera_busy", "item " + std::to_string(it.number) +
                                 " reached the camera while the one before was still measured: rejected");
        reject(it, Reason::kCameraBusy, now_ns);
      } else if (const auto burst = (camera_ok_ && hooks_.start_burst) ? hooks_.start_burst(it.number) : std::nullopt) {
        it.burst = burst;
        it.stage = Stage::kMeasuring;
        burst_started = true;
      } else {
        reject(it, Reason::kCameraLost, now_ns);  // the camera is lost, or no burst could start
      }
    }
    if (it.stage == Stage::kMeasuring) {
      if (const auto d = decision_deadline(it, now_ns); d && now_ns >= *d)
        late(it, "no label before its last chance to be sorted", nullptr, now_ns);
    }
    if (it.stage == Stage::kDecided) {
      if (!it.outlet) {
        it.stage = Stage::kPassed;
      } else if (here >= it.start_mm + config_.outlets[*it.outlet].position_mm) {
        const Outlet& o = config_.outlets[*it.outlet];
        const bool was_on = outlet_until_[*it.outlet].has_value();
        outlet_until_[*it.outlet] = std::max(outlet_until_[*it.outlet].value_or(0), now_ns + o.pulse_ns);
        if (!was_on && hooks_.drive) hooks_.drive(*it.outlet, true);
        it.stage = Stage::kPassed;
        SortEvent e = it.event;
        e.state = "fired";
        e.fire_ns = now_ns;
        if (hooks_.event) hooks_.event(e);
      }
    }
  }
  while (!items_.empty() && items_.front().stage == Stage::kPassed && here >= items_.front().start_mm + end_mm())
    items_.pop_front();
  set_alarm(now_ns);
}

std::optional<std::uint64_t> Sorter::decision_deadline(const Item& it, std::uint64_t now_ns) const {
  // Unlabelled items must still reach reject: the reject pusher when there is
  // one, else the last outlet (after it nothing could be sorted anyway).
  double at = 0;
  if (config_.reject) {
    at = config_.outlets[*config_.reject].position_mm;
  } else {
    for (const auto& o : config_.outlets) at = std::max(at, o.position_mm);
  }
  const auto t = motion_.time_at(it.start_mm + at, now_ns);
  if (!t) return std::nullopt;
  return *t > config_.decision_margin_ns ? *t - config_.decision_margin_ns : 0;
}

std::optional<std::uint64_t> Sorter::next_wake(std::uint64_t now_ns) const {
  std::optional<std::uint64_t> wake;
  const auto take = [&](std::optional<std::uint64_t> t) {
    if (t) wake = wake ? std::min(*wake, *t) : *t;
  };
  for (const auto& u : outlet_until_) take(u);
  for (const auto& it : items_) {
    switch (it.stage) {
      case Stage::kToCamera: take(motion_.time_at(it.start_mm + config_.camera_mm, now_ns)); break;
      case Stage::kMeasuring: take(decision_deadline(it, now_ns)); break;
      case Stage::kDecided:
        take(it.outlet ? motion_.time_at(it.start_mm + config_.outlets[*it.outlet].position_mm, now_ns) : now_ns);
        break;
      case Stage::kPassed: take(motion_.time_at(it.start_mm + end_mm(), now_ns)); break;
    }
  }
  if (alarm_ && camera_ok_ && late_until_ns_ > now_ns) take(late_until_ns_);
  return wake;
}

}  // namespace tofmat::line
