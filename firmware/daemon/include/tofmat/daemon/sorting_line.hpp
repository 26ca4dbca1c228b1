// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The sorting line in tofmatd (issue 17): the light barrier, the belt's
// encoder, the outlets' pushers and the alarm on GPIO, and the line's
// schedule (firmware/line) on a thread of its own ("tofmatd-line").
//
// The barrier's edges (kernel timestamps) become items; an item under the
// camera starts the sorting profile's burst; the burst's label chooses its
// outlet; its pusher fires when the item gets there (in belt positions: a
// fixed speed, or the encoder's count). Every decision is a "sort" event,
// every fault and alarm change a "line" event (docs/protocol.md).
#pragma once
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tofmat/gpio/gpio.hpp"
#include "tofmat/line/sorter.hpp"
#include "tofmat/protocol/messages.hpp"
#include "tofmat/protocol/socket.hpp"

namespace tofmat::daemon {

// The GPIO backend by name: "libgpiod" (the board's chips) or "sim" (the
// simulated chip). Throws std::invalid_argument for another name.
std::shared_ptr<gpio::Backend> make_gpio_backend(const std::string& name);

struct OutletOptions {
  line::Outlet outlet;
  gpio::LineSpec line;
  bool active_low = false;
};
// "NAME:position=MM,line=CHIP:LINE[,materials=a+b][,pulse=MS][,active_low=0|1]".
// Throws std::invalid_argument naming what is wrong.
OutletOptions parse_outlet(const std::string& text);

struct LineOptions {
  std::string gpio;     // "" = no sorting line; "libgpiod" | "sim"
  std::string barrier;  // CHIP:LINE
  bool barrier_active_low = false;
  std::string barrier_bias = "as-is";
  double debounce_ms = 2, min_gap_ms = 100;
  double speed_mm_s = 0;             // a belt of fixed speed, or:
  std::string encoder_a, encoder_b;  // CHIP:LINE each
  double encoder_counts_per_mm = 0;
  double camera_mm = 200;
  std::vector<std::string> outlets;  // parse_outlet
  std::string reject;                // an outlet's name ("" = rejects ride to the belt's end)
  std::string alarm;                 // CHIP:LINE ("" = none)
  double margin_ms = 20, alarm_hold_ms = 5000;
  double max_distance = 0;  // a label is confident at most this far (Eq. 12, mm^2; 0 = any final label)
  bool enabled() const { return !gpio.empty() && !barrier.empty(); }  // (options check the rest)
};

class SortingLine {
 public:
  struct Hooks {
    // Starts the sorting profile's burst; its trigger number, or nullopt
    // (with why) when it cannot.
    std::function<std::optional<std::uint64_t>(std::string& why)> start_burst;
    std::function<void(const protocol::Message&, const std::string& stream)> publish;
    // A simulated belt's truth for the item its barrier edge at `trigger_ns`
    // announced (Source::item_truth); unset or nothing: the burst's own.
    std::function<std::optional<std::string>(std::uint64_t trigger_ns)> item_truth;
  };
  // Validates everything and requests every line (throws
  // std::invalid_argument for a bad option, gpio::GpioError for a line that
  // cannot be had). `materials`: the table's, which the outlets must name.
  SortingLine(const LineOptions& options, std::shared_ptr<gpio::Backend> backend,
              const std::vector<std::string>& materials, Hooks hooks);
  ~SortingLine();

  // The line thread: until `stop` (wake() to have it look).
  void run(const std::atomic<bool>& stop);
  void wake();
  // From the processing thread: a label of the sorting profile.
  void label(const protocol::LabelEvent& event);
  // From the source thread: whether the camera streams.
  void camera(bool streaming);
  nlohmann::json status() const;

 private:
  void handle_inbox(std::uint64_t now_ns);
  void take_snapshot(std::uint64_t now_ns);
  void publish_sort(const line::SortEvent& e);
  void publish_line(const std::string& kind, const std::string& message);

  LineOptions options_;
  std::shared_ptr<gpio::Backend> backend_;
  Hooks hooks_;
  std::unique_ptr<gpio::InputLine> barrier_, enc_a_, enc_b_;
  std::vector<std::unique_ptr<gpio::OutputLine>> outlets_;
  std::unique_ptr<gpio::OutputLine> alarm_;
  std::unique_ptr<line::BeltMotion> motion_;
  line::EncoderMotion* encoder_ = nullptr;  // motion_, when it is an encoder
  line::TriggerFilter filter_;
  std::unique_ptr<line::Sorter> sorter_;
  protocol::WakeFd wake_fd_;
  // From other threads, under inbox_mutex_.
  mutable std::mutex inbox_mutex_;
  std::vector<line::BurstLabel> labels_;
  std::optional<bool> camera_;
  // For status (under status_mutex_): the line thread's figures after each round,
  // and before each sort or line event goes out.
  struct Snapshot {
    line::Sorter::Counts counts;
    std::size_t on_belt = 0;
    bool alarm = false;
    double speed_mm_s = 0;
    std::uint64_t glitches = 0, bounces = 0, encoder_errors = 0;
  };
  mutable std::mutex status_mutex_;
  Snapshot snapshot_;
};

}  // namespace tofmat::daemon
