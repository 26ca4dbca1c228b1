// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// TriggerFilter: debounce of the light barrier's edges into item starts.
#include "tofmat/line/trigger_filter.hpp"

namespace tofmat::line {

std::optional<ItemStart> TriggerFilter::confirm() {
  ItemStart s;
  s.timestamp_ns = *pending_;
  if (last_item_ns_) {
    s.gap_ns = s.timestamp_ns - *last_item_ns_;
    s.too_close = s.gap_ns < config_.min_gap_ns;
  }
  last_item_ns_ = s.timestamp_ns;
  pending_.reset();
  in_item_ = true;
  return s;
}

std::optional<ItemStart> TriggerFilter::edge(std::uint64_t timestamp_ns, bool blocked) {
  std::optional<ItemStart> out;
  // (Edges out of order or repeated levels happen when events were lost: the
  // level is what counts.)
  if (started_ && blocked == blocked_) return out;
  if (pending_ && timestamp_ns >= *pending_ + config_.debounce_ns) out = confirm();
  const bool clear_long_enough = !started_ || timestamp_ns >= last_edge_ns_ + config_.debounce_ns;
  if (blocked) {
    if (in_item_ && !clear_long_enough) {
      ++bounces_;  // the same item's trailing edge bouncing
    } else {
      in_item_ = false;
      pending_ = timestamp_ns;
    }
  } else if (pending_) {
    ++glitches_;  // cleared before it was held for debounce
    pending_.reset();
  }
  blocked_ = blocked;
  started_ = true;
  last_edge_ns_ = timestamp_ns;
  return out;
}

std::optional<ItemStart> TriggerFilter::advance(std::uint64_t now_ns) {
  if (pending_ && blocked_ && now_ns >= *pending_ + config_.debounce_ns) return confirm();
  return std::nullopt;
}

std::optional<std::uint64_t> TriggerFilter::next_deadline() const {
  if (pending_) return *pending_ + config_.debounce_ns;
  return std::nullopt;
}

}  // namespace tofmat::line
