// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The light barrier's edges -> items (issue 17). libgpiod's v1 API has no
// debounce, so it is done here, on the kernel's timestamps:
//  - an item starts at an edge to "blocked" that is held for at least
//    `debounce` (a glitch shorter than that is no item; a bouncing leading
//    edge starts the item at its last bounce); the beam blocked again less
//    than `debounce` after an item cleared it is that item's trailing edge
//    bouncing, not a new item;
//  - the item's time is its edge's kernel timestamp, whenever it is
//    confirmed (confirmation only delays knowing, never the schedule);
//  - an item that starts less than `min_gap` after the one before is still
//    an item, flagged `too_close` (the caller reports it and rejects it):
//    two items are never merged silently.
// Pure: no clock of its own, no GPIO; the caller feeds edges and the time.
#pragma once
#include <cstdint>
#include <optional>
#include <vector>

namespace tofmat::line {

struct TriggerConfig {
  std::uint64_t debounce_ns = 2'000'000;   // 2 ms
  std::uint64_t min_gap_ns = 100'000'000;  // 100 ms between item starts
};

struct ItemStart {
  std::uint64_t timestamp_ns = 0;  // the leading edge
  bool too_close = false;          // under min_gap after the item before
  std::uint64_t gap_ns = 0;        // since the item before (0 for the first)
};

class TriggerFilter {
 public:
  explicit TriggerFilter(TriggerConfig config) : config_(config) {}
  // An edge of the barrier (blocked = the beam is interrupted), in order.
  // Returns the item it confirms, if any (an edge can confirm the one before).
  std::optional<ItemStart> edge(std::uint64_t timestamp_ns, bool blocked);
  // Time passing with no edge: confirms a pending item once it has been held
  // for `debounce`.
  std::optional<ItemStart> advance(std::uint64_t now_ns);
  // When advance() could next confirm something (nullopt: nothing pending).
  std::optional<std::uint64_t> next_deadline() const;
  std::uint64_t glitches() const { return glitches_; }  // blocked for less than debounce
  std::uint64_t bounces() const { return bounces_; }    // blocked again under debounce after clearing

 private:
  std::optional<ItemStart> confirm();
  TriggerConfig config_;
  bool blocked_ = false;
  bool started_ = false;                  // an edge seen (the first level is unknown before it)
  std::uint64_t last_edge_ns_ = 0;        // the last edge of either kind
  std::optional<std::uint64_t> pending_;  // a leading edge not yet confirmed
  bool in_item_ = false;                  // a confirmed item holds the beam (its bounces are no items)
  std::optional<std::uint64_t> last_item_ns_;
  std::uint64_t glitches_ = 0, bounces_ = 0;
};

}  // namespace tofmat::line
