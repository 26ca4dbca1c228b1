// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The front panel's reset button on the simulated chip, in real time: a press
// held past the debounce resets once, at the edge's timestamp; bounces and a
// touch shorter than the debounce do not; a second press under the hold-off
// is counted as ignored; a line that cannot be had fails at construction;
// run() returns promptly on stop.
#include <gtest/gtest.h>

#include <chrono>
#include <condition_variable>
#include <thread>

#include "tofmat/daemon/reset_button.hpp"
#include "tofmat/gpio/sim_gpio.hpp"

namespace {

using namespace tofmat;
using daemon::ButtonOptions;
using daemon::ResetButton;
constexpr std::uint64_t kMs = 1'000'000;

ButtonOptions options() {
  ButtonOptions o;
  o.line = "sim:button";
  o.active_low = true;  // a button to ground with the pull-up
  o.bias = "pull-up";
  o.debounce_ms = 20;
  o.hold_off_ms = 300;
  return o;
}

struct Harness {
  explicit Harness(const ButtonOptions& o = options()) : gpio(gpio::SimGpio::create()) {
    gpio->drive("button", true, protocol::monotonic_ns());  // released
    button = std::make_unique<ResetButton>(o, gpio, [this](std::uint64_t t) {
      std::lock_guard<std::mutex> lock(mutex);
      presses.push_back(t);
      cv.notify_all();
    });
    thread = std::thread([this] { button->run(stop); });
  }
  ~Harness() {
    stop = true;
    button->wake();
    thread.join();
  }
  // Pressed at `t` (the pin pulled low) and released `ms` later.
  void press(std::uint64_t t, std::uint64_t ms) {
    gpio->drive("button", false, t);
    gpio->drive("button", true, t + ms * kMs);
  }
  std::vector<std::uint64_t> wait_presses(std::size_t n, int ms) {
    std::unique_lock<std::mutex> lock(mutex);
    cv.wait_for(lock, std::chrono::milliseconds(ms), [&] { return presses.size() >= n; });
    return presses;
  }
  std::shared_ptr<gpio::SimGpio> gpio;
  std::unique_ptr<ResetButton> button;
  std::atomic<bool> stop{false};
  std::thread thread;
  std::mutex mutex;
  std::condition_variable cv;
  std::vector<std::uint64_t> presses;
};

TEST(ResetButton, APressHeldPastTheDebounceResetsOnceAtItsEdge) {
  Harness h;
  const auto t = protocol::monotonic_ns();
  h.press(t, 120);
  const auto got = h.wait_presses(1, 2000);
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got[0], t);  // the kernel's timestamp, not when it was seen
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  EXPECT_EQ(h.wait_presses(2, 0).size(), 1u);
  EXPECT_EQ(h.button->status()["presses"], 1);
  EXPECT_EQ(h.button->status()["line"], "sim:button");
}

TEST(ResetButton, BouncesAndTouchesAreNoPressAndTheSameFingerIsIgnored) {
  Harness h;
  const auto t = protocol::monotonic_ns();
  h.press(t, 5);                // a touch under the debounce: nothing
  h.press(t + 40 * kMs, 2);     // a bounce ...
  h.press(t + 43 * kMs, 150);   // ... then held: one press, at its last bounce
  h.press(t + 260 * kMs, 100);  // again 217 ms later (under the 300 ms hold-off): ignored
  h.press(t + 600 * kMs, 100);  // a new press
  const auto got = h.wait_presses(2, 3000);
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got[0], t + 43 * kMs);
  EXPECT_EQ(got[1], t + 600 * kMs);
  const auto s = h.button->status();
  EXPECT_EQ(s["presses"], 2);
  EXPECT_EQ(s["ignored"], 1);
}

TEST(ResetButton, ALineThatCannotBeHadFailsAtStartAndNamesIt) {
  auto gpio = gpio::SimGpio::create();
  auto held = gpio->request_input(gpio::LineSpec::parse("sim:button"), {}, "someone");
  try {
    ResetButton b(options(), gpio, [](std::uint64_t) {});
    FAIL() << "a busy line was taken";
  } catch (const gpio::GpioError& e) {
    EXPECT_NE(std::string(e.what()).find("button"), std::string::npos) << e.what();
  }
  auto o = options();
  o.line = "gpiochip0";  // no line named
  EXPECT_THROW(ResetButton(o, gpio::SimGpio::create(), [](std::uint64_t) {}), std::invalid_argument);
  o = options();
  o.debounce_ms = -1;
  EXPECT_THROW(ResetButton(o, gpio::SimGpio::create(), [](std::uint64_t) {}), std::invalid_argument);
}

TEST(ResetButton, StopsPromptly) {
  auto h = std::make_unique<Harness>();
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  const auto t0 = std::chrono::steady_clock::now();
  h.reset();
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::milliseconds(100));
}

}  // namespace
