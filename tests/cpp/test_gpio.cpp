// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// GPIO backends (firmware/gpio): the line names the configuration takes, the
// simulated chip's kernel-like rules, and the libgpiod backend failing
// clearly on a machine without GPIO (these build machines have none).
#include <poll.h>

#include <filesystem>

#include <gtest/gtest.h>

#include "tofmat/gpio/gpio.hpp"
#include "tofmat/gpio/sim_gpio.hpp"

namespace {

using namespace tofmat::gpio;

bool readable(int fd) {
  pollfd p{fd, POLLIN, 0};
  return ::poll(&p, 1, 0) == 1 && (p.revents & POLLIN);
}

TEST(LineSpec, ChipByLabelOrPathAndLineByNameOrOffset) {
  const LineSpec a = LineSpec::parse("pinctrl-rp1:GPIO17");
  EXPECT_EQ(a.chip, "pinctrl-rp1");
  EXPECT_EQ(a.line, "GPIO17");
  EXPECT_FALSE(a.is_offset());
  const LineSpec b = LineSpec::parse("/dev/gpiochip0:17");
  EXPECT_EQ(b.chip, "/dev/gpiochip0");
  EXPECT_TRUE(b.is_offset());
  EXPECT_EQ(b.describe(), "/dev/gpiochip0:17");
}

TEST(LineSpec, AChipNumberAloneAndMalformedNamesAreRefused) {
  for (const char* bad : {"4:17", "gpiochip4:17", "GPIO17", ":17", "sim:", "", "sim:bar rier", "sim:a\tb"}) {
    try {
      LineSpec::parse(bad);
      ADD_FAILURE() << bad << " was accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("GPIO line"), std::string::npos) << e.what();
    }
  }
  try {
    LineSpec::parse("gpiochip4:17");
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("changes between kernels"), std::string::npos) << e.what();
  }
}

TEST(LineSpec, Bias) {
  EXPECT_EQ(parse_bias("pull-up"), Bias::kPullUp);
  EXPECT_STREQ(bias_name(parse_bias("pull-down")), "pull-down");
  EXPECT_THROW(parse_bias("up"), std::invalid_argument);
}

TEST(SimGpio, EdgesArriveWithTheirTimesInTheLinesLogicalSense) {
  auto gpio = SimGpio::create();
  auto barrier = gpio->request_input(LineSpec::parse("sim:barrier"), {true, Bias::kPullUp}, "test");
  EXPECT_FALSE(barrier->value()) << "pulled up, active low: inactive";
  EXPECT_FALSE(readable(barrier->fd()));
  gpio->drive("barrier", false, 1'000);  // the beam interrupted pulls the pin low
  gpio->drive("barrier", false, 1'500);  // the same level: no edge
  gpio->drive("barrier", true, 2'000);
  EXPECT_TRUE(readable(barrier->fd()));
  std::vector<EdgeEvent> got;
  EXPECT_EQ(barrier->read_events(got, 1), 1u);
  EXPECT_TRUE(readable(barrier->fd())) << "one event still waits";
  EXPECT_EQ(barrier->read_events(got), 1u);
  EXPECT_FALSE(readable(barrier->fd()));
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got[0].timestamp_ns, 1'000u);
  EXPECT_TRUE(got[0].rising) << "to active (low, active_low)";
  EXPECT_EQ(got[1].timestamp_ns, 2'000u);
  EXPECT_FALSE(got[1].rising);
  EXPECT_FALSE(barrier->value());
}

TEST(SimGpio, ALineIsRequestedOnceAtATimeOnItsChip) {
  auto gpio = SimGpio::create();
  auto a = gpio->request_input(LineSpec::parse("sim:barrier"), {}, "tofmatd");
  EXPECT_EQ(gpio->consumer("barrier"), "tofmatd");
  try {
    gpio->request_output(LineSpec::parse("sim:barrier"), {}, "other");
    ADD_FAILURE() << "a busy line was given out again";
  } catch (const GpioError& e) {
    EXPECT_NE(std::string(e.what()).find("busy"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("tofmatd"), std::string::npos) << e.what();
  }
  EXPECT_THROW(gpio->request_input(LineSpec::parse("pinctrl-rp1:GPIO17"), {}, "x"), GpioError);
  a.reset();
  EXPECT_EQ(gpio->consumer("barrier"), "");
  EXPECT_NO_THROW(gpio->request_output(LineSpec::parse("sim:barrier"), {}, "other"));
}

TEST(SimGpio, OutputsRecordEveryChangeWithItsTimeAndLevel) {
  auto gpio = SimGpio::create();
  {
    auto pusher = gpio->request_output(LineSpec::parse("sim:pusher1"), {true, false}, "test");
    pusher->set(true);
    pusher->set(false);
    EXPECT_THROW(gpio->drive("pusher1", true, 5), GpioError) << "an output is not driven from outside";
  }
  const auto c = gpio->changes("pusher1");
  ASSERT_EQ(c.size(), 3u);  // the initial value, on, off
  EXPECT_FALSE(c[0].active);
  EXPECT_TRUE(c[0].high) << "active low: inactive is high";
  EXPECT_TRUE(c[1].active);
  EXPECT_FALSE(c[1].high);
  EXPECT_LE(c[0].timestamp_ns, c[1].timestamp_ns);
  EXPECT_LE(c[1].timestamp_ns, c[2].timestamp_ns);
  EXPECT_GT(c[0].timestamp_ns, 0u);
}

TEST(SimGpio, AnUnreadQueueIsBoundedAndCountsWhatItLost) {
  auto gpio = SimGpio::create();
  auto in = gpio->request_input(LineSpec::parse("sim:enc_a"), {}, "test");
  const std::size_t n = SimGpio::kQueue + 10;
  for (std::size_t k = 0; k < n; ++k) gpio->drive("enc_a", k % 2 == 0, 100 + k);
  EXPECT_EQ(gpio->lost_events(), 10u);
  std::vector<EdgeEvent> got;
  while (in->read_events(got, 100) > 0) {
  }
  ASSERT_EQ(got.size(), SimGpio::kQueue);
  EXPECT_EQ(got.front().timestamp_ns, 110u) << "the oldest were lost";
  EXPECT_EQ(got.back().timestamp_ns, 100 + n - 1);
}

TEST(LibgpiodBackend, FailsClearlyWithoutTheChip) {
  auto backend = make_libgpiod_backend();
  EXPECT_EQ(backend->name(), "libgpiod");
  bool any = false;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator("/dev", ec))
    any = any || e.path().filename().string().rfind("gpiochip", 0) == 0;
  for (int output = 0; output < 2; ++output) {
    try {
      const LineSpec spec = LineSpec::parse("tofmat-no-such-chip:GPIO17");
      if (output)
        backend->request_output(spec, {}, "test");
      else
        backend->request_input(spec, {}, "test");
      ADD_FAILURE() << "a line of a chip that does not exist was given out";
    } catch (const GpioError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("tofmat-no-such-chip:GPIO17"), std::string::npos) << what;
      EXPECT_NE(what.find(any ? "no chip labelled tofmat-no-such-chip" : "no GPIO chip (no /dev/gpiochip*)"),
                std::string::npos)
          << what;
    }
  }
}

}  // namespace
