// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The light barrier's trigger filter (firmware/line): debounce on the
// kernel's timestamps, and items too close together reported, never merged.
#include <gtest/gtest.h>

#include "tofmat/line/trigger_filter.hpp"

namespace {

using namespace tofmat::line;
constexpr std::uint64_t kUs = 1'000, kMs = 1'000'000;

TriggerConfig config() { return {2 * kMs, 100 * kMs}; }

TEST(TriggerFilter, AnItemIsItsEdgeHeldForTheDebounceTime) {
  TriggerFilter f(config());
  EXPECT_FALSE(f.edge(10 * kMs, true));
  EXPECT_EQ(f.next_deadline(), 12 * kMs);
  EXPECT_FALSE(f.advance(11 * kMs));
  const auto item = f.advance(12 * kMs);
  ASSERT_TRUE(item);
  EXPECT_EQ(item->timestamp_ns, 10 * kMs) << "the edge's time, not the confirmation's";
  EXPECT_FALSE(item->too_close);
  EXPECT_FALSE(f.advance(20 * kMs)) << "confirmed once";
  EXPECT_FALSE(f.next_deadline());
}

TEST(TriggerFilter, AnEdgeConfirmsThePendingItemItFollows) {
  TriggerFilter f(config());
  f.edge(10 * kMs, true);
  const auto item = f.edge(40 * kMs, false);  // (no advance() in between)
  ASSERT_TRUE(item);
  EXPECT_EQ(item->timestamp_ns, 10 * kMs);
}

TEST(TriggerFilter, AGlitchIsNoItem) {
  TriggerFilter f(config());
  EXPECT_FALSE(f.edge(10 * kMs, true));
  EXPECT_FALSE(f.edge(10 * kMs + 500 * kUs, false));
  EXPECT_FALSE(f.advance(50 * kMs));
  EXPECT_EQ(f.glitches(), 1u);
}

TEST(TriggerFilter, ABouncingLeadingEdgeIsOneItemFromItsLastBounce) {
  TriggerFilter f(config());
  f.edge(10 * kMs, true);
  f.edge(10 * kMs + 50 * kUs, false);
  f.edge(10 * kMs + 120 * kUs, true);
  const auto item = f.advance(20 * kMs);
  ASSERT_TRUE(item);
  EXPECT_EQ(item->timestamp_ns, 10 * kMs + 120 * kUs);
  EXPECT_FALSE(f.advance(30 * kMs));
}

TEST(TriggerFilter, ABouncingTrailingEdgeIsNoNewItem) {
  TriggerFilter f(config());
  f.edge(10 * kMs, true);
  ASSERT_TRUE(f.advance(15 * kMs));
  f.edge(60 * kMs, false);
  EXPECT_FALSE(f.edge(60 * kMs + 80 * kUs, true));
  f.edge(60 * kMs + 200 * kUs, false);
  EXPECT_FALSE(f.advance(200 * kMs));
  EXPECT_EQ(f.bounces(), 1u);
  // A real next item after the beam was clear for longer than the debounce.
  f.edge(300 * kMs, true);
  const auto next = f.advance(303 * kMs);
  ASSERT_TRUE(next);
  EXPECT_EQ(next->timestamp_ns, 300 * kMs);
  EXPECT_EQ(next->gap_ns, 290 * kMs);
  EXPECT_FALSE(next->too_close);
}

TEST(TriggerFilter, AnItemUnderTheMinimumGapIsFlaggedNotMerged) {
  TriggerFilter f(config());
  f.edge(10 * kMs, true);
  ASSERT_TRUE(f.advance(13 * kMs));
  f.edge(40 * kMs, false);
  f.edge(70 * kMs, true);  // 60 ms after the first item's start: under 100 ms
  const auto second = f.advance(75 * kMs);
  ASSERT_TRUE(second) << "still an item of its own";
  EXPECT_TRUE(second->too_close);
  EXPECT_EQ(second->gap_ns, 60 * kMs);
}

TEST(TriggerFilter, ARepeatedLevelIsNoEdge) {
  // (Lost events can hand over the same level twice.)
  TriggerFilter f(config());
  f.edge(10 * kMs, true);
  EXPECT_FALSE(f.edge(11 * kMs, true));
  const auto item = f.advance(12 * kMs);
  ASSERT_TRUE(item);
  EXPECT_EQ(item->timestamp_ns, 10 * kMs);
}

}  // namespace
