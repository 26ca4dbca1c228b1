// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The sorting line's schedule (firmware/line): items followed from the
// barrier past the camera to their outlets in belt positions, and every way
// an item can fail sent to reject, with the alarm and a report.
#include <gtest/gtest.h>

#include <map>

#include "tofmat/line/sorter.hpp"

namespace {

using namespace tofmat::line;
constexpr std::uint64_t kMs = 1'000'000;

// A belt at 500 mm/s: camera 200 mm on (0.4 s), wood at 600 (1.2 s), cork
// at 800 (1.6 s), reject at 1000 (2.0 s).
SorterConfig line_config() {
  SorterConfig c;
  c.camera_mm = 200;
  c.outlets = {{"wood", {"wood"}, 600, 50 * kMs},
               {"cork", {"cork", "corkboard"}, 800, 50 * kMs},
               {"reject", {}, 1000, 80 * kMs}};
  c.reject = 2;
  c.decision_margin_ns = 20 * kMs;
  c.alarm_hold_ns = 1000 * kMs;
  return c;
}

struct Line {
  explicit Line(SorterConfig c = line_config(), const BeltMotion* m = nullptr)
      : motion(m ? *m : belt), sorter(std::move(c), motion, hooks()) {}
  Hooks hooks() {
    Hooks h;
    h.start_burst = [this](std::uint64_t item) -> std::optional<std::uint64_t> {
      if (!camera) return std::nullopt;
      bursts.push_back({item, now});
      return 100 + item;  // (a burst's number is not its item's)
    };
    h.drive = [this](std::size_t outlet, bool on) { drives.push_back({outlet, on, now}); };
    h.alarm = [this](bool on) { alarms.push_back({on, now}); };
    h.event = [this](const SortEvent& e) { events.push_back(e); };
    h.fault = [this](const std::string& kind, const std::string&) { faults.push_back(kind); };
    return h;
  }
  // Polls every ms up to t (as the line thread would wake), then at t.
  void run_to(std::uint64_t t) {
    while (now < t) {
      now = std::min(t, now + kMs);
      sorter.poll(now);
    }
  }
  void item_at(std::uint64_t t, bool too_close = false) {
    run_to(t + 2 * kMs);  // confirmed after the debounce
    sorter.item({t, too_close, 0}, now);
  }
  void label(std::uint64_t item, const std::string& material, bool confident = true) {
    sorter.label({100 + item, material, confident, 12.5, material}, now);
  }
  std::vector<SortEvent> of(std::uint64_t item, const std::string& state) const {
    std::vector<SortEvent> out;
    for (const auto& e : events)
      if (e.item == item && e.state == state) out.push_back(e);
    return out;
  }
  struct Drive {
    std::size_t outlet;
    bool on;
    std::uint64_t t;
  };
  struct Burst {
    std::uint64_t item, t;
  };
  FixedSpeed belt{500.0};
  const BeltMotion& motion;
  std::uint64_t now = 0;
  bool camera = true;
  std::vector<Burst> bursts;
  std::vector<Drive> drives;
  std::vector<std::pair<bool, std::uint64_t>> alarms;
  std::vector<SortEvent> events;
  std::vector<std::string> faults;
  Sorter sorter;
};

TEST(Sorter, AnItemIsMeasuredUnderTheCameraAndPushedAtItsOutlet) {
  Line l;
  l.item_at(1000 * kMs);
  l.run_to(1500 * kMs);
  ASSERT_EQ(l.bursts.size(), 1u);
  EXPECT_EQ(l.bursts[0].t, 1400 * kMs) << "when the item is 200 mm on, under the camera";
  l.label(1, "cork");
  const auto decided = l.of(1, "decided");
  ASSERT_EQ(decided.size(), 1u);
  EXPECT_EQ(decided[0].outlet, "cork");
  EXPECT_EQ(decided[0].reason, Reason::kSorted);
  EXPECT_EQ(decided[0].trigger_ns, 1000 * kMs);
  EXPECT_EQ(decided[0].truth, "cork") << "a simulated item's truth passes through";
  EXPECT_EQ(decided[0].fire_ns, 2600 * kMs);
  EXPECT_NEAR(decided[0].margin_ms, 1100.0, 1e-6);
  l.run_to(3200 * kMs);
  ASSERT_EQ(l.drives.size(), 2u);
  EXPECT_EQ(l.drives[0].outlet, 1u);
  EXPECT_TRUE(l.drives[0].on);
  EXPECT_EQ(l.drives[0].t, 2600 * kMs);
  EXPECT_FALSE(l.drives[1].on);
  EXPECT_EQ(l.drives[1].t, 2650 * kMs) << "the outlet's 50 ms pulse";
  const auto fired = l.of(1, "fired");
  ASSERT_EQ(fired.size(), 1u);
  EXPECT_EQ(fired[0].fire_ns, 2600 * kMs);
  EXPECT_EQ(l.sorter.on_belt(), 0u) << "gone past the belt's end";
  EXPECT_EQ(l.sorter.counts().sorted, 1u);
  EXPECT_TRUE(l.faults.empty());
  EXPECT_TRUE(l.alarms.empty());
}

TEST(Sorter, ItemsCloserThanTheOutletsAreEachSortedInTurn) {
  Line l;
  // Four items 300 ms (150 mm) apart: several are on the belt at once.
  const std::vector<std::string> materials{"wood", "cork", "corkboard", "wood"};
  std::map<std::uint64_t, std::string> want{{1, "wood"}, {2, "cork"}, {3, "cork"}, {4, "wood"}};
  // Each burst is answered 250 ms after it starts, before the next item
  // reaches the camera (the barrier has seen more of them by then).
  l.item_at(1000 * kMs);
  for (int k = 0; k < 4; ++k) {
    if (k < 3) l.item_at((1300 + 300 * k) * kMs);
    l.run_to((1400 + 300 * k + 250) * kMs);
    l.label(static_cast<std::uint64_t>(k + 1), materials[static_cast<std::size_t>(k)]);
  }
  l.run_to(4000 * kMs);
  EXPECT_EQ(l.bursts.size(), 4u);
  for (const auto& [item, outlet] : want) {
    const auto fired = l.of(item, "fired");
    ASSERT_EQ(fired.size(), 1u) << item;
    EXPECT_EQ(fired[0].outlet, outlet) << item;
    const double pos = outlet == "wood" ? 600 : 800;
    EXPECT_EQ(*fired[0].fire_ns, (1000 + 300 * (item - 1)) * kMs + static_cast<std::uint64_t>(pos / 0.5) * kMs);
  }
  EXPECT_EQ(l.sorter.counts().sorted, 4u);
  EXPECT_TRUE(l.faults.empty());
}

TEST(Sorter, AnItemWithNoLabelInTimeGoesToRejectAndRaisesTheAlarm) {
  Line l;
  l.item_at(1000 * kMs);
  l.run_to(3100 * kMs);
  const auto decided = l.of(1, "decided");
  ASSERT_EQ(decided.size(), 1u);
  EXPECT_EQ(decided[0].reason, Reason::kLate);
  EXPECT_EQ(decided[0].outlet, "reject");
  EXPECT_EQ(decided[0].decided_ns, 2980 * kMs) << "the reject pusher (at 3.0 s) less the margin";
  ASSERT_FALSE(l.alarms.empty());
  EXPECT_TRUE(l.alarms[0].first);
  EXPECT_EQ(l.alarms[0].second, 2980 * kMs);
  ASSERT_EQ(l.of(1, "fired").size(), 1u);
  EXPECT_EQ(*l.of(1, "fired")[0].fire_ns, 3000 * kMs);
  l.label(1, "wood");  // the label after all: ignored
  EXPECT_EQ(l.of(1, "decided").size(), 1u);
  l.run_to(4100 * kMs);
  ASSERT_EQ(l.alarms.size(), 2u);
  EXPECT_FALSE(l.alarms[1].first) << "cleared after the hold";
  EXPECT_EQ(l.alarms[1].second, 3980 * kMs);
}

TEST(Sorter, ALabelTooLateForItsOutletIsRejected) {
  Line l;
  l.item_at(1000 * kMs);
  l.run_to(2190 * kMs);  // wood fires at 2.2 s: 10 ms left, the margin is 20
  l.label(1, "wood");
  const auto decided = l.of(1, "decided");
  ASSERT_EQ(decided.size(), 1u);
  EXPECT_EQ(decided[0].reason, Reason::kLate);
  EXPECT_EQ(decided[0].outlet, "reject");
  EXPECT_EQ(decided[0].material, "wood");
  EXPECT_EQ(l.sorter.counts().late, 1u);
  EXPECT_TRUE(l.sorter.alarm_on());
  ASSERT_EQ(l.faults.size(), 1u);
  EXPECT_EQ(l.faults[0], "late");
  l.run_to(3100 * kMs);
  EXPECT_EQ(l.of(1, "fired").at(0).outlet, "reject");
  EXPECT_TRUE(l.drives.size() >= 1 && l.drives[0].outlet == 2u) << "only the reject pusher moved";
}

TEST(Sorter, UnconfidentUnknownAndUnsortedMaterialsGoToReject) {
  Line l;
  l.item_at(1000 * kMs);
  l.run_to(1500 * kMs);
  l.label(1, "wood", false);
  l.item_at(1500 * kMs);
  l.run_to(2000 * kMs);
  l.label(2, "acryl");
  l.item_at(2000 * kMs);
  l.run_to(2500 * kMs);
  l.label(3, "");
  l.item_at(2500 * kMs);
  l.run_to(3000 * kMs);
  // A burst whose frames disagreed (the next item in the ROI): its material
  // has an outlet and the label is confident, but it is never sorted.
  BurstLabel mixed{104, "wood", true, 12.5, "wood"};
  mixed.mixed = true;
  l.sorter.label(mixed, l.now);
  l.item_at(3500 * kMs);
  l.run_to(4000 * kMs);
  // A burst no material explains (open set): its nearest has an outlet, but it is never sorted.
  BurstLabel unknown{105, "wood", true, 12.5, "wood"};
  unknown.unknown = true;
  l.sorter.label(unknown, l.now);
  l.item_at(4500 * kMs);
  l.run_to(5000 * kMs);
  // A burst that saw the item only outside the table's bins (issue 33): no material, its own reason.
  BurstLabel out{106, "", false, 0.0, std::nullopt};
  out.out_of_range = true;
  l.sorter.label(out, l.now);
  l.run_to(8000 * kMs);
  EXPECT_EQ(l.bursts.size(), 6u);
  EXPECT_EQ(l.of(1, "decided").at(0).reason, Reason::kNotConfident);
  EXPECT_EQ(l.of(2, "decided").at(0).reason, Reason::kNoOutlet);
  EXPECT_EQ(l.of(3, "decided").at(0).reason, Reason::kNoTarget);
  EXPECT_EQ(l.of(4, "decided").at(0).reason, Reason::kMixed);
  EXPECT_STREQ(reason_name(Reason::kMixed), "mixed");
  EXPECT_EQ(l.of(5, "decided").at(0).reason, Reason::kUnknown);
  EXPECT_STREQ(reason_name(Reason::kUnknown), "unknown");
  EXPECT_EQ(l.of(6, "decided").at(0).reason, Reason::kOutOfRange);
  EXPECT_STREQ(reason_name(Reason::kOutOfRange), "out_of_range");
  for (std::uint64_t i = 1; i <= 6; ++i) EXPECT_EQ(l.of(i, "fired").at(0).outlet, "reject") << i;
  EXPECT_EQ(l.sorter.counts().rejected, 6u);
  EXPECT_TRUE(l.alarms.empty()) << "no fault of the line";
  EXPECT_TRUE(l.faults.empty());
}

TEST(Sorter, ATriggerTooCloseIsReportedAndRejectedNotMerged) {
  Line l;
  l.item_at(1000 * kMs);
  l.item_at(1040 * kMs, true);
  ASSERT_EQ(l.faults.size(), 1u);
  EXPECT_EQ(l.faults[0], "too_close");
  EXPECT_EQ(l.of(2, "decided").at(0).reason, Reason::kTooClose);
  l.run_to(1600 * kMs);
  l.label(1, "wood");
  l.run_to(4000 * kMs);
  EXPECT_EQ(l.bursts.size(), 1u) << "no burst for the rejected one";
  EXPECT_EQ(l.of(1, "fired").at(0).outlet, "wood");
  EXPECT_EQ(l.of(2, "fired").at(0).outlet, "reject");
}

TEST(Sorter, AnItemReachingTheCameraWhileTheOneBeforeIsMeasuredIsRejected) {
  Line l;
  l.item_at(1000 * kMs);
  l.item_at(1150 * kMs);  // under the camera at 1.55 s, the first's label comes at 1.6
  l.run_to(1600 * kMs);
  l.label(1, "cork");
  l.run_to(4000 * kMs);
  EXPECT_EQ(l.of(2, "decided").at(0).reason, Reason::kCameraBusy);
  EXPECT_EQ(l.of(1, "fired").at(0).outlet, "cork");
  EXPECT_EQ(l.bursts.size(), 1u);
}

TEST(Sorter, TheCameraLostMidRunRejectsWhatItCannotSeeAndRaisesTheAlarm) {
  Line l;
  l.item_at(1000 * kMs);
  l.run_to(1450 * kMs);  // measuring
  l.sorter.camera(false, l.now);
  l.camera = false;
  EXPECT_TRUE(l.sorter.alarm_on());
  EXPECT_EQ(l.of(1, "decided").at(0).reason, Reason::kCameraLost);
  l.item_at(1600 * kMs);
  EXPECT_EQ(l.of(2, "decided").at(0).reason, Reason::kCameraLost);
  l.run_to(2500 * kMs);
  l.sorter.camera(true, l.now);
  l.camera = true;
  EXPECT_FALSE(l.sorter.alarm_on());
  l.item_at(3000 * kMs);
  l.run_to(3700 * kMs);
  l.label(3, "wood");
  l.run_to(6000 * kMs);
  EXPECT_EQ(l.of(3, "fired").at(0).outlet, "wood");
  ASSERT_EQ(l.alarms.size(), 2u);
  EXPECT_TRUE(l.alarms[0].first);
  EXPECT_FALSE(l.alarms[1].first);
  EXPECT_EQ(l.of(1, "fired").at(0).outlet, "reject");
  EXPECT_EQ(l.of(2, "fired").at(0).outlet, "reject");
}

TEST(Sorter, NoRejectOutletMeansRejectsRideToTheBeltsEnd) {
  SorterConfig c = line_config();
  c.outlets.pop_back();
  c.reject.reset();
  Line l(c);
  l.item_at(1000 * kMs);
  l.run_to(3000 * kMs);
  const auto d = l.of(1, "decided");
  ASSERT_EQ(d.size(), 1u);
  EXPECT_EQ(d[0].outlet, "");
  EXPECT_FALSE(d[0].fire_ns);
  EXPECT_EQ(d[0].decided_ns, 2580 * kMs) << "the last outlet (800 mm at 2.6 s) less the margin";
  EXPECT_TRUE(l.drives.empty());
}

TEST(Sorter, AStoppedBeltDelaysEveryStepWithIt) {
  EncoderMotion enc(1.0);  // one count per mm
  Line l(line_config(), &enc);
  std::uint64_t t = 0;
  bool a = false, b = false;
  int phase = 0;
  // Moves the belt `mm` at 500 mm/s (one count every 2 ms), polling as it goes.
  const auto move = [&](int mm) {
    for (int k = 0; k < mm; ++k) {
      const bool on_b = phase % 2 == 1;
      bool& ch = on_b ? b : a;
      ch = !ch;
      ++phase;
      t += 2 * kMs;
      enc.edge(on_b, ch, t);
      l.run_to(t);
    }
  };
  move(100);
  l.item_at(l.now);
  const std::uint64_t edge_t = l.now - 2 * kMs;
  const double start = enc.position_mm(edge_t);
  move(250);
  ASSERT_EQ(l.bursts.size(), 1u);
  l.label(1, "wood");
  move(300);  // 550 mm past the barrier: 50 mm short of wood
  // The belt stops for two seconds: nothing fires.
  l.run_to(l.now + 2000 * kMs);
  t = l.now;
  EXPECT_TRUE(l.drives.empty());
  EXPECT_EQ(l.of(1, "fired").size(), 0u);
  move(60);
  ASSERT_FALSE(l.drives.empty());
  EXPECT_TRUE(l.drives[0].on);
  EXPECT_NEAR(enc.position_mm(l.drives[0].t) - start, 600.0, 1.0) << "fired at the outlet's position, not a time";
}

TEST(SorterConfig, WhatCannotWorkIsRefused) {
  const auto refused = [](const SorterConfig& c, const std::string& says) {
    try {
      validate(c);
      ADD_FAILURE() << "accepted; wanted: " << says;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << e.what();
    }
  };
  EXPECT_NO_THROW(validate(line_config()));
  SorterConfig c = line_config();
  c.outlets.clear();
  c.reject.reset();
  refused(c, "no outlet");
  c = line_config();
  c.outlets[0].position_mm = 150;
  refused(c, "further along the belt than the camera");
  c = line_config();
  c.outlets[1].materials.push_back("wood");
  refused(c, "goes to two outlets");
  c = line_config();
  c.outlets[2].materials = {"pvc"};
  refused(c, "takes no material");
  c = line_config();
  c.reject = 7;
  refused(c, "not one of the outlets");
  c = line_config();
  c.outlets[1].name = "wood";
  refused(c, "two outlets are named");
  c = line_config();
  c.outlets[0].pulse_ns = 0;
  refused(c, "pulse of 0");
}

}  // namespace
