// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// tofmatd's sorting line on the simulated chip, in real time: the barrier's
// edge starts an item, the item's burst is asked for when it is under the
// camera, its label picks the outlet and the pusher is driven when the item
// gets there (by the edge's timestamp, not by when the daemon saw it).
#include <gtest/gtest.h>

#include <chrono>
#include <condition_variable>
#include <map>
#include <thread>

#include "tofmat/daemon/sorting_line.hpp"
#include "tofmat/gpio/sim_gpio.hpp"

namespace {

using namespace tofmat;
using daemon::LineOptions;
using daemon::SortingLine;
constexpr std::uint64_t kMs = 1'000'000;

LineOptions options() {
  LineOptions o;
  o.gpio = "sim";
  o.barrier = "sim:barrier";
  o.barrier_active_low = true;  // (a common light barrier: open collector, low while interrupted)
  o.barrier_bias = "pull-up";
  o.speed_mm_s = 1000;  // 1 mm a ms
  o.camera_mm = 50;
  o.outlets = {"wood:position=150,line=sim:push_wood,materials=wood,pulse=30",
               "cork:position=200,line=sim:push_cork,materials=cork,pulse=30",
               "reject:position=250,line=sim:push_reject,pulse=30"};
  o.reject = "reject";
  o.alarm = "sim:alarm";
  o.margin_ms = 10;
  o.alarm_hold_ms = 100;
  return o;
}

struct Harness {
  explicit Harness(const LineOptions& o = options()) : gpio(gpio::SimGpio::create()) {
    SortingLine::Hooks h;
    h.start_burst = [this](std::string& why) -> std::optional<std::uint64_t> {
      std::lock_guard<std::mutex> lock(mutex);
      if (!camera_ok) {
        why = "no camera";
        return std::nullopt;
      }
      bursts.push_back(protocol::monotonic_ns());
      cv.notify_all();
      return 40 + bursts.size();
    };
    h.publish = [this](const protocol::Message& m, const std::string& stream) {
      std::lock_guard<std::mutex> lock(mutex);
      (stream == "sort" ? sorts : lines).push_back(m.meta);
      // What a client that reads this event and then asks for status would get.
      (stream == "sort" ? status_at_sort : status_at_line).push_back(line->status());
      cv.notify_all();
    };
    line = std::make_unique<SortingLine>(o, gpio, std::vector<std::string>{"wood", "cork", "pvc"}, std::move(h));
    thread = std::thread([this] { line->run(stop); });
  }
  ~Harness() {
    stop = true;
    line->wake();
    thread.join();
  }
  // The beam interrupted at `t` for `ms` (active low: the pin goes low).
  void item(std::uint64_t t, std::uint64_t ms) {
    gpio->drive("barrier", false, t);
    std::this_thread::sleep_for(std::chrono::milliseconds(ms));
    gpio->drive("barrier", true, t + ms * kMs);
  }
  void label(std::uint64_t trigger, const std::string& material) {
    protocol::LabelEvent e;
    e.state = material.empty() ? "no_target" : "final";
    e.material = material;
    e.trigger = trigger;
    e.distance = 3.0;
    line->label(e);
  }
  bool wait_for(const std::function<bool()>& done, int ms) {
    std::unique_lock<std::mutex> lock(mutex);
    return cv.wait_for(lock, std::chrono::milliseconds(ms), done);
  }
  std::size_t burst_count() {
    std::lock_guard<std::mutex> lock(mutex);
    return bursts.size();
  }
  std::vector<nlohmann::json> sort_events(const std::string& state) {
    std::lock_guard<std::mutex> lock(mutex);
    std::vector<nlohmann::json> out;
    for (const auto& s : sorts)
      if (s["state"] == state) out.push_back(s);
    return out;
  }
  std::shared_ptr<gpio::SimGpio> gpio;
  std::unique_ptr<SortingLine> line;
  std::atomic<bool> stop{false};
  std::thread thread;
  std::mutex mutex;
  std::condition_variable cv;
  bool camera_ok = true;
  std::vector<std::uint64_t> bursts;
  std::vector<nlohmann::json> sorts, lines, status_at_sort, status_at_line;
};

TEST(SortingLine, AnItemIsPushedAtItsOutletOnTimeFromTheBarriersTimestamp) {
  Harness h;
  // The edge happened 5 ms before the daemon is told (as a kernel
  // timestamp is earlier than the read): the schedule counts from the edge.
  const std::uint64_t edge = protocol::monotonic_ns() - 5 * kMs;
  h.item(edge, 10);
  ASSERT_TRUE(h.wait_for([&] { return !h.bursts.empty(); }, 1000)) << "no burst";
  EXPECT_GE(h.bursts[0], edge + 50 * kMs) << "the burst starts when the item is under the camera";
  EXPECT_LT(h.bursts[0], edge + 70 * kMs);
  h.label(41, "cork");
  ASSERT_TRUE(h.wait_for([&] { return h.sorts.size() >= 2; }, 1000));
  const auto decided = h.sort_events("decided");
  ASSERT_EQ(decided.size(), 1u);
  EXPECT_EQ(decided[0]["outlet"], "cork");
  EXPECT_EQ(decided[0]["reason"], "sorted");
  EXPECT_EQ(h.status_at_sort.at(0)["sorted"], 1) << "the decision went out before status counted it";
  EXPECT_EQ(decided[0]["trigger_ns"].get<std::uint64_t>(), edge);
  EXPECT_NEAR(static_cast<double>(decided[0]["fire_ns"].get<std::uint64_t>()), static_cast<double>(edge + 200 * kMs),
              1000.0)
      << "(positions are doubles: within a microsecond)";
  const auto fired = h.sort_events("fired");
  ASSERT_EQ(fired.size(), 1u);
  std::this_thread::sleep_for(std::chrono::milliseconds(60));
  const auto changes = h.gpio->changes("push_cork");
  ASSERT_EQ(changes.size(), 3u) << "initial off, on, off";
  const double late_ms = static_cast<double>(static_cast<std::int64_t>(changes[1].timestamp_ns) -
                                             static_cast<std::int64_t>(edge + 200 * kMs)) /
                         1e6;
  EXPECT_GE(changes[1].timestamp_ns + 1000, edge + 200 * kMs) << "never early (but for a double's rounding)";
  EXPECT_LT(late_ms, 15.0) << "the pusher fired " << late_ms << " ms late";
  EXPECT_NEAR(static_cast<double>(changes[2].timestamp_ns - changes[1].timestamp_ns) / 1e6, 30.0, 15.0);
  EXPECT_TRUE(h.gpio->changes("push_wood").size() == 1u) << "only its initial value";
  const auto status = h.line->status();
  EXPECT_EQ(status["items"], 1);
  EXPECT_EQ(status["sorted"], 1);
}

// A belt with an encoder on the simulated chip: one count (one edge of
// either channel) per mm, in real time, forwards (A leads) or backwards.
struct EncoderBelt {
  explicit EncoderBelt(std::shared_ptr<gpio::SimGpio> g) : gpio(std::move(g)) {}
  void move(int mm, bool forward = true, int ms_per_mm = 1) {
    for (int k = 0; k < mm; ++k) {
      std::this_thread::sleep_for(std::chrono::milliseconds(ms_per_mm));
      const bool on_a = forward ? a == b : a != b;  // (the next state of A-leads-B, or of B-leads-A)
      bool& ch = on_a ? a : b;
      ch = !ch;
      const auto now = protocol::monotonic_ns();
      gpio->drive(on_a ? "enc_a" : "enc_b", ch, now);
      position += forward ? 1 : -1;
      if (!reached.count(position)) reached[position] = now;
    }
  }
  void stand(int ms) { std::this_thread::sleep_for(std::chrono::milliseconds(ms)); }
  std::shared_ptr<gpio::SimGpio> gpio;
  bool a = false, b = false;
  int position = 0;
  std::map<int, std::uint64_t> reached;  // position -> when the belt first got there
};

TEST(SortingLine, WithAnEncoderThePusherWaitsWhileTheBeltStandsOrRunsBack) {
  auto o = options();
  o.speed_mm_s = 0;
  o.encoder_a = "sim:enc_a";
  o.encoder_b = "sim:enc_b";
  o.encoder_counts_per_mm = 1;
  Harness h(o);
  EncoderBelt belt(h.gpio);
  h.item(protocol::monotonic_ns(), 2);  // the item's leading edge at the barrier, belt at 0 mm
  belt.move(60);                        // past the camera (50 mm)
  ASSERT_TRUE(h.wait_for([&] { return !h.bursts.empty(); }, 1000)) << "no burst";
  EXPECT_GE(h.bursts[0] + 2 * kMs, belt.reached.at(50)) << "the burst starts when the belt has carried the item there";
  h.label(41, "cork");   // the cork outlet: 200 mm past the barrier
  belt.move(60);         // 120 mm
  belt.move(10, false);  // the belt jolts back: 110 mm
  belt.stand(300);
  EXPECT_EQ(h.gpio->changes("push_cork").size(), 1u) << "fired while the item was still 90 mm away";
  const auto stood_until = protocol::monotonic_ns();
  belt.move(100);                                                                       // 210 mm: past the outlet
  ASSERT_TRUE(h.wait_for([&] { return h.sorts.size() >= 2; }, 1000)) << "never fired";  // (decided, fired)
  const auto changes = h.gpio->changes("push_cork");
  ASSERT_GE(changes.size(), 2u);
  EXPECT_GT(changes[1].timestamp_ns, stood_until);
  const double off_ms =
      (static_cast<double>(changes[1].timestamp_ns) - static_cast<double>(belt.reached.at(200))) / 1e6;
  EXPECT_GT(off_ms, -3.0) << "fired before the item was at its outlet";
  EXPECT_LT(off_ms, 15.0) << "fired " << off_ms << " ms after the item was at its outlet";
  EXPECT_EQ(h.sort_events("decided").at(0)["outlet"], "cork");
  EXPECT_EQ(h.line->status()["encoder_errors"], 0);
}

TEST(SortingLine, NoLabelGoesToRejectAndRaisesTheAlarmOutput) {
  Harness h;
  const std::uint64_t edge = protocol::monotonic_ns();
  h.item(edge, 5);
  ASSERT_TRUE(h.wait_for([&] { return h.sorts.size() >= 2; }, 1000));
  const auto decided = h.sort_events("decided");
  ASSERT_EQ(decided.size(), 1u);
  EXPECT_EQ(decided[0]["reason"], "late");
  EXPECT_EQ(decided[0]["outlet"], "reject");
  EXPECT_EQ(h.status_at_sort.at(0)["rejected"], 1) << "the decision went out before status counted it";
  EXPECT_EQ(h.status_at_sort.at(0)["alarm"], true);
  const auto alarm = h.gpio->changes("alarm");
  ASSERT_GE(alarm.size(), 2u);
  EXPECT_TRUE(alarm[1].active);
  ASSERT_TRUE(h.wait_for([&] { return h.gpio->changes("alarm").size() >= 3; }, 1000)) << "the alarm never cleared";
  EXPECT_FALSE(h.gpio->changes("alarm")[2].active);
  EXPECT_GE(h.gpio->changes("push_reject").size(), 2u);
}

TEST(SortingLine, TheCameraLostRejectsAndAlarmsUntilItIsBack) {
  Harness h;
  h.line->camera(false);
  ASSERT_TRUE(h.wait_for([&] { return !h.lines.empty(); }, 1000));
  {
    std::lock_guard<std::mutex> lock(h.mutex);
    h.camera_ok = false;
  }
  h.item(protocol::monotonic_ns(), 5);
  ASSERT_TRUE(h.wait_for([&] { return !h.sorts.empty(); }, 1000));
  EXPECT_EQ(h.sort_events("decided").at(0)["reason"], "camera_lost");
  EXPECT_TRUE(h.gpio->changes("alarm").back().active);
  h.line->camera(true);
  ASSERT_TRUE(h.wait_for([&] { return !h.gpio->changes("alarm").back().active; }, 1000));
  EXPECT_EQ(h.burst_count(), 0u);
  // A client that reads the alarm's event and then asks for status sees the same alarm.
  ASSERT_TRUE(h.wait_for([&] { return !h.lines.empty() && h.lines.back()["message"] == "off"; }, 1000));
  std::lock_guard<std::mutex> lock(h.mutex);
  std::vector<bool> alarms;
  for (std::size_t k = 0; k < h.lines.size(); ++k)
    if (h.lines[k]["kind"] == "alarm") {
      EXPECT_EQ(h.status_at_line.at(k)["alarm"], h.lines[k]["message"] == "on") << h.lines[k];
      alarms.push_back(h.lines[k]["message"] == "on");
    }
  EXPECT_EQ(alarms, (std::vector<bool>{true, false}));
  EXPECT_GE(h.status_at_line.front()["faults"], 1) << "the camera's fault went out before status counted it";
}

TEST(SortingLine, AClientSeesWhatIsWrongWithTheConfiguration) {
  auto gpio = gpio::SimGpio::create();
  const auto refused = [&](const LineOptions& o, const std::string& says) {
    try {
      SortingLine l(o, gpio, {"wood", "cork", "pvc"}, {});
      ADD_FAILURE() << "accepted; wanted: " << says;
    } catch (const std::exception& e) {
      EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << e.what();
    }
  };
  LineOptions o = options();
  o.speed_mm_s = 0;
  refused(o, "give the belt's motion");
  o = options();
  o.encoder_a = "sim:enc_a";
  refused(o, "one of the two");
  o = options();
  o.outlets[0] = "wood:position=150,line=sim:push_wood,materials=oak";
  refused(o, "\"oak\", which the table does not hold");
  o = options();
  o.outlets[0] = "wood:position=150,materials=wood";
  refused(o, "no line=CHIP:LINE");
  o = options();
  o.outlets[0] = "wood:position=150,line=sim:push_wood,materials=wood,speed=3";
  refused(o, "unknown key \"speed\"");
  o = options();
  o.reject = "bin";
  refused(o, "is not an outlet");
  o = options();
  o.barrier = "gpiochip0:4";
  refused(o, "chip number");
  o = options();
  o.outlets[1] = "cork:position=200,line=sim:push_wood,materials=cork";
  refused(o, "busy");
  EXPECT_EQ(gpio->consumer("barrier"), "") << "a refused line releases what it took";
}

}  // namespace
