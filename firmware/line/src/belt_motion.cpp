// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// FixedSpeed and EncoderMotion: where the belt is at a time, and when it reaches a position.
#include "tofmat/line/belt_motion.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace tofmat::line {
namespace {

std::uint64_t add_seconds(std::uint64_t t_ns, double s) {
  if (!(s > 0)) return t_ns;
  const double ns = s * 1e9;
  if (ns >= 1.8e19 - static_cast<double>(t_ns)) return std::numeric_limits<std::uint64_t>::max();
  return t_ns + static_cast<std::uint64_t>(std::ceil(ns));
}

}  // namespace

FixedSpeed::FixedSpeed(double mm_per_s) : speed_(mm_per_s) {
  if (!(mm_per_s > 0) || !std::isfinite(mm_per_s))
    throw std::invalid_argument("belt speed must be a positive number of mm/s");
}

double FixedSpeed::position_mm(std::uint64_t t_ns) const { return speed_ * static_cast<double>(t_ns) * 1e-9; }

std::optional<std::uint64_t> FixedSpeed::time_at(double mm, std::uint64_t now_ns) const {
  const double here = position_mm(now_ns);
  if (mm <= here) return now_ns;
  return add_seconds(now_ns, (mm - here) / speed_);
}

int Quadrature::edge(bool channel_b, bool level) {
  // x4 with A leading B forwards: 00 -> 10 -> 11 -> 01 -> 00.
  bool& self = channel_b ? b_ : a_;
  if (self == level) {  // no change on this channel: its other edge was lost
    ++errors_;
    return 0;
  }
  self = level;
  const int step = channel_b ? (b_ == a_ ? +1 : -1) : (a_ != b_ ? +1 : -1);
  count_ += step;
  return step;
}

EncoderMotion::EncoderMotion(double counts_per_mm, std::uint64_t window_ns, std::uint64_t stopped_after_ns)
    : counts_per_mm_(counts_per_mm), window_ns_(window_ns), stopped_after_ns_(stopped_after_ns) {
  if (!(counts_per_mm > 0) || !std::isfinite(counts_per_mm) || window_ns == 0 || stopped_after_ns == 0)
    throw std::invalid_argument("encoder: counts per mm, window and stop time must be positive");
}

void EncoderMotion::edge(bool channel_b, bool level, std::uint64_t t_ns) {
  if (quad_.edge(channel_b, level) == 0) return;
  samples_.push_back({t_ns, quad_.count()});
  // Keep the window, and one sample older than it (the speed spans it).
  while (samples_.size() > 2 && samples_[1].t_ns + window_ns_ < t_ns) samples_.pop_front();
}

double EncoderMotion::speed_mm_s(std::uint64_t now_ns) const {
  if (samples_.size() < 2) return 0.0;
  const Sample& last = samples_.back();
  if (now_ns > last.t_ns + stopped_after_ns_) return 0.0;
  const Sample& first = samples_.front();
  if (last.t_ns <= first.t_ns) return 0.0;
  const double counts_per_s =
      static_cast<double>(last.count - first.count) / (static_cast<double>(last.t_ns - first.t_ns) * 1e-9);
  return counts_per_s / counts_per_mm_;
}

double EncoderMotion::position_mm(std::uint64_t t_ns) const {
  const double counted = static_cast<double>(quad_.count()) / counts_per_mm_;
  if (samples_.empty() || t_ns == samples_.back().t_ns) return counted;
  if (t_ns < samples_.back().t_ns) {
    // A moment in the recent past (an item's edge, confirmed a little
    // later): the count then, as far back as the window keeps.
    auto it = std::upper_bound(samples_.begin(), samples_.end(), t_ns,
                               [](std::uint64_t t, const Sample& s) { return t < s.t_ns; });
    if (it != samples_.begin()) --it;
    return static_cast<double>(it->count) / counts_per_mm_;
  }
  // Between counts: where the speed says, but never a whole count beyond the
  // last one (the belt cannot have moved that far without an edge).
  const double moved = speed_mm_s(t_ns) * static_cast<double>(t_ns - samples_.back().t_ns) * 1e-9;
  const double one = 1.0 / counts_per_mm_;
  return counted + std::clamp(moved, -one, one);
}

std::optional<std::uint64_t> EncoderMotion::time_at(double mm, std::uint64_t now_ns) const {
  const double here = position_mm(now_ns);
  if (mm <= here) return now_ns;
  const double v = speed_mm_s(now_ns);
  if (!(v > 0)) return std::nullopt;
  return add_seconds(now_ns, (mm - here) / v);
}

}  // namespace tofmat::line
