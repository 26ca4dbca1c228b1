// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The simulated belt (sim:belt): items rendered where the belt has carried
// them, and the simulated light barrier driven at the moments they cross it,
// with those moments as the edges' timestamps.
#include <gtest/gtest.h>

#include <thread>

#include "tofmat/daemon/belt_sim.hpp"
#include "tofmat/protocol/socket.hpp"

namespace {

using namespace tofmat;
using daemon::BeltSim;
using daemon::BeltSpec;
constexpr std::uint64_t kMs = 1'000'000;

BeltSpec spec() {
  BeltSpec s;
  s.materials = {"cork", "wood", "acryl"};
  s.speed_mm_s = 500;
  s.rate_per_min = 120;  // one every 0.5 s on average
  s.item_mm = 100;
  s.camera_mm = 300;
  s.depth_mm = 730;  // 2 mm a pixel
  s.jitter = 0;
  return s;
}

TEST(BeltSim, ItemsAreRenderedWhereTheBeltHasCarriedThem) {
  BeltSim belt(spec(), nullptr);
  belt.start(0);
  // The first item reaches the barrier at 1 s; its leading edge is under the
  // camera's axis (300 mm on) at 1.6 s.
  const auto at = [&](std::uint64_t ms) { return belt.scene(ms, ms * kMs); };
  const auto s = at(1600);
  ASSERT_FALSE(s.targets.empty());
  const auto& t = s.targets.front();
  EXPECT_NEAR(t.x1, 256, 1) << "the leading edge on the optical axis";
  EXPECT_NEAR(t.x1 - t.x0, 50, 1) << "100 mm at 2 mm a pixel";
  EXPECT_NEAR(t.y1 - t.y0, 70, 1);
  EXPECT_DOUBLE_EQ(t.depth_mm, 730.0);
  const auto later = at(1700);  // 50 mm further: 25 pixels
  ASSERT_FALSE(later.targets.empty());
  EXPECT_NEAR(later.targets.front().x1, 281, 1);
  EXPECT_EQ(belt.truth_materials(1600).size(), s.targets.size());
  EXPECT_EQ(belt.truth_materials(1600).front(), t.material);
  EXPECT_TRUE(belt.truth_materials(99999).empty());
  EXPECT_TRUE(at(0).targets.empty()) << "nothing on the belt before the first item";
}

TEST(BeltSim, TheBarrierIsDrivenWhenEachItemCrossesIt) {
  auto gpio = gpio::SimGpio::create();
  auto barrier = gpio->request_input(gpio::LineSpec::parse("sim:barrier"), {true, gpio::Bias::kPullUp}, "test");
  BeltSim belt(spec(), gpio);
  const std::uint64_t t0 = protocol::monotonic_ns();
  belt.start(t0);
  std::atomic<bool> stop{false};
  std::thread run([&] { belt.run(stop); });
  std::this_thread::sleep_for(std::chrono::milliseconds(1800));
  stop = true;
  run.join();
  std::vector<gpio::EdgeEvent> edges;
  barrier->read_events(edges);
  const auto items = belt.items_until(t0 + 1800 * kMs);
  ASSERT_GE(items.size(), 2u);
  ASSERT_GE(edges.size(), 4u);
  for (std::size_t k = 0; k < 2; ++k) {
    EXPECT_TRUE(edges[2 * k].rising) << "interrupted (active)";
    EXPECT_EQ(edges[2 * k].timestamp_ns, t0 + items[k].arrival_ns);
    EXPECT_FALSE(edges[2 * k + 1].rising);
    EXPECT_EQ(edges[2 * k + 1].timestamp_ns, t0 + items[k].arrival_ns + 200 * kMs) << "100 mm at 500 mm/s";
  }
  EXPECT_EQ(items[0].arrival_ns, 1000 * kMs);
  EXPECT_EQ(items[1].arrival_ns, 1500 * kMs);
}

TEST(BeltSim, AnItemsTruthIsFoundByItsBarrierEdge) {
  // (issue 33) A sort decision's truth travels with its item: the barrier edge's moment names it,
  // whatever frame its burst ended on.
  BeltSim belt(spec(), nullptr);
  belt.start(5000 * kMs);
  const auto items = belt.items_until(5000 * kMs + 3000 * kMs);
  ASSERT_GE(items.size(), 4u);
  for (const auto& it : items) {
    const std::uint64_t edge = 5000 * kMs + it.arrival_ns;
    EXPECT_EQ(belt.item_at(edge), it.material);
    EXPECT_EQ(belt.item_at(edge + 15 * kMs), it.material);  // (a debounced edge: within 20 ms)
  }
  EXPECT_FALSE(belt.item_at(5000 * kMs + items[0].arrival_ns + 250 * kMs).has_value()) << "between items";
  EXPECT_FALSE(belt.item_at(0).has_value());
}

TEST(BeltSim, ItemsNeverLandOnEachOther) {
  BeltSpec s = spec();
  s.rate_per_min = 6000;  // asked for far more than fits
  BeltSim belt(s, nullptr);
  belt.start(0);
  const auto items = belt.items_until(20'000 * kMs);
  ASSERT_GE(items.size(), 3u);
  for (std::size_t k = 1; k < items.size(); ++k)
    EXPECT_GE(items[k].arrival_ns - items[k - 1].arrival_ns, 240 * kMs) << "100 mm and 20 mm apart at 500 mm/s";
}

TEST(BeltSim, ABeltThatCannotBeIsRefused) {
  for (auto change : {+[](BeltSpec& s) { s.materials.clear(); }, +[](BeltSpec& s) { s.speed_mm_s = 0; },
                      +[](BeltSpec& s) { s.rate_per_min = -1; }, +[](BeltSpec& s) { s.jitter = 2; },
                      +[](BeltSpec& s) { s.item_mm = 1; }}) {
    BeltSpec s = spec();
    change(s);
    EXPECT_THROW(BeltSim(s, nullptr), std::invalid_argument);
  }
}

}  // namespace
