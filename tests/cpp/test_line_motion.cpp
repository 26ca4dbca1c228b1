// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The belt's motion (firmware/line): a fixed speed, and a quadrature encoder
// counted forwards and backwards, whose speed follows the belt and which
// reaches nothing while the belt stands.
#include <gtest/gtest.h>

#include "tofmat/line/belt_motion.hpp"

namespace {

using namespace tofmat::line;
constexpr std::uint64_t kMs = 1'000'000;

TEST(FixedSpeed, PositionsAndTimes) {
  FixedSpeed belt(500.0);
  EXPECT_DOUBLE_EQ(belt.position_mm(2'000 * kMs), 1000.0);
  EXPECT_EQ(belt.time_at(1100.0, 2'000 * kMs), 2'200 * kMs);
  EXPECT_EQ(belt.time_at(900.0, 2'000 * kMs), 2'000 * kMs) << "already passed: now";
  EXPECT_THROW(FixedSpeed(0.0), std::invalid_argument);
  EXPECT_THROW(FixedSpeed(-1.0), std::invalid_argument);
  EXPECT_THROW(FixedSpeed{std::numeric_limits<double>::quiet_NaN()}, std::invalid_argument);
}

// One full cycle forwards, A leading B: A up, B up, A down, B down.
void forward_cycle(Quadrature& q) {
  q.edge(false, true);
  q.edge(true, true);
  q.edge(false, false);
  q.edge(true, false);
}

TEST(Quadrature, CountsFourPerCycleEitherWay) {
  Quadrature q;
  forward_cycle(q);
  forward_cycle(q);
  EXPECT_EQ(q.count(), 8);
  // Backwards, B leading A: B up, A up, B down, A down.
  EXPECT_EQ(q.edge(true, true), -1);
  EXPECT_EQ(q.edge(false, true), -1);
  EXPECT_EQ(q.edge(true, false), -1);
  EXPECT_EQ(q.edge(false, false), -1);
  EXPECT_EQ(q.count(), 4);
  EXPECT_EQ(q.errors(), 0u);
  // Jitter on one channel (up, down) is +1 then -1: no drift.
  q.edge(false, true);
  q.edge(false, false);
  EXPECT_EQ(q.count(), 4);
}

TEST(Quadrature, ALostEdgeIsAnErrorNotAGuess) {
  Quadrature q;
  q.edge(false, true);
  EXPECT_EQ(q.edge(false, true), 0);  // A "up" again: its down edge was lost
  EXPECT_EQ(q.errors(), 1u);
  EXPECT_EQ(q.count(), 1);
}

// Feeds `cycles` forward cycles, one count every `step_ns` from `t`.
std::uint64_t run(EncoderMotion& m, int cycles, std::uint64_t t, std::uint64_t step_ns, bool forward = true) {
  bool a = false, b = false;
  for (int k = 0; k < cycles; ++k) {
    for (int e = 0; e < 4; ++e) {
      const bool on_b = forward ? (e % 2 == 1) : (e % 2 == 0);
      bool& ch = on_b ? b : a;
      ch = !ch;
      t += step_ns;
      m.edge(on_b, ch, t);
    }
  }
  return t;
}

TEST(EncoderMotion, FollowsTheBeltAndStopsWithIt) {
  EncoderMotion m(10.0);  // 10 counts per mm
  // 500 mm/s: 5000 counts/s, one every 200 us.
  std::uint64_t t = run(m, 250, 0, 200'000);  // 1000 counts, 100 mm
  EXPECT_DOUBLE_EQ(m.position_mm(t), 100.0);
  EXPECT_NEAR(m.speed_mm_s(t), 500.0, 1.0);
  const auto at = m.time_at(150.0, t);
  ASSERT_TRUE(at);
  EXPECT_NEAR(static_cast<double>(*at - t) / kMs, 100.0, 0.5);
  // Between counts the position moves on, but never a whole count beyond.
  EXPECT_GT(m.position_mm(t + 100'000), 100.0);
  EXPECT_LE(m.position_mm(t + 10 * kMs), 100.1 + 1e-9);
  // The belt stops: nothing is reached, the speed is 0.
  const std::uint64_t later = t + 150 * kMs;
  EXPECT_EQ(m.speed_mm_s(later), 0.0);
  EXPECT_FALSE(m.time_at(150.0, later));
  EXPECT_EQ(m.time_at(50.0, later), later) << "behind the belt: now";
  // It runs again, slower: the prediction follows.
  t = run(m, 50, later, 400'000);  // 250 mm/s
  EXPECT_NEAR(m.speed_mm_s(t), 250.0, 1.0);
  const auto at2 = m.time_at(m.position_mm(t) + 25.0, t);
  ASSERT_TRUE(at2);
  EXPECT_NEAR(static_cast<double>(*at2 - t) / kMs, 100.0, 1.0);
}

TEST(EncoderMotion, RunningBackwardsReachesNothingAhead) {
  EncoderMotion m(10.0);
  std::uint64_t t = run(m, 100, 0, 200'000);
  t = run(m, 50, t, 200'000, false);
  EXPECT_DOUBLE_EQ(m.position_mm(t), 20.0);
  EXPECT_LT(m.speed_mm_s(t), 0.0);
  EXPECT_FALSE(m.time_at(30.0, t));
}

TEST(EncoderMotion, ThePositionAtAMomentJustPast) {
  EncoderMotion m(10.0);
  const std::uint64_t t = run(m, 100, 0, 200'000);  // counts at 0.2, 0.4, ... ms
  EXPECT_DOUBLE_EQ(m.position_mm(t - 10 * kMs), (400 - 50) / 10.0);
  EXPECT_THROW(EncoderMotion(0.0), std::invalid_argument);
}

}  // namespace
