// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The box's front-panel button (issue 17): a press on its GPIO line resets
// the accumulation, as the `reset` command does. tofmatd owns the GPIO (one
// libgpiod layer for the line and the panel); `tofmat panel` shows the
// result, through the `reset` stream.
//
// A mechanical button bounces for a few ms and a finger holds it for a
// hundred or more: a press is an edge to "pressed" held for `debounce`, and
// a press under `hold_off` after the one before is the same finger (counted,
// not acted on). The same edge rules as the light barrier's (TriggerFilter),
// on the kernel's timestamps. Its own thread ("tofmatd-button").
#pragma once
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>

#include <nlohmann/json.hpp>

#include "tofmat/gpio/gpio.hpp"
#include "tofmat/line/trigger_filter.hpp"
#include "tofmat/protocol/socket.hpp"

namespace tofmat::daemon {

struct ButtonOptions {
  std::string line;  // CHIP:LINE; "" = no button
  bool active_low = false;
  std::string bias = "as-is";
  double debounce_ms = 20, hold_off_ms = 500;
  bool enabled() const { return !line.empty(); }
};

class ResetButton {
 public:
  // Requests the line (throws gpio::GpioError naming it, or
  // std::invalid_argument for a bad option). `on_press` runs on the button's
  // thread with the press's kernel timestamp.
  ResetButton(const ButtonOptions& options, std::shared_ptr<gpio::Backend> backend,
              std::function<void(std::uint64_t timestamp_ns)> on_press);

  // Until `stop` (wake() to have it look).
  void run(const std::atomic<bool>& stop);
  void wake();
  // Its thread ended on an error (kept for status).
  void stopped(const std::string& why);
  // {"line", "presses", "ignored", "error"?}
  nlohmann::json status() const;

 private:
  ButtonOptions options_;
  std::shared_ptr<gpio::Backend> backend_;
  std::unique_ptr<gpio::InputLine> input_;
  std::function<void(std::uint64_t)> on_press_;
  line::TriggerFilter filter_;
  protocol::WakeFd wake_fd_;
  std::atomic<std::uint64_t> presses_{0}, ignored_{0};
  mutable std::mutex error_mutex_;
  std::string error_;
};

}  // namespace tofmat::daemon
