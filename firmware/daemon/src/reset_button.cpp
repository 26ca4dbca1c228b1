// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// ResetButton: the thread that debounces the button's GPIO line and resets the accumulation on a press.
#include "tofmat/daemon/reset_button.hpp"

#include <poll.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "spec_text.hpp"
#include "tofmat/daemon/log.hpp"

namespace tofmat::daemon {

ResetButton::ResetButton(const ButtonOptions& options, std::shared_ptr<gpio::Backend> backend,
                         std::function<void(std::uint64_t)> on_press)
    : options_(options),
      backend_(std::move(backend)),
      on_press_(std::move(on_press)),
      filter_({ms_to_ns(options.debounce_ms), ms_to_ns(options.hold_off_ms)}) {
  for (const double v : {options.debounce_ms, options.hold_off_ms})
    if (!(v >= 0 && v <= 60'000) || !std::isfinite(v))
      throw std::invalid_argument("reset button: debounce and hold-off must be 0 to 60000 ms");
  input_ = backend_->request_input(gpio::LineSpec::parse(options.line),
                                   {options.active_low, gpio::parse_bias(options.bias)}, "tofmatd-button");
}

void ResetButton::wake() { wake_fd_.wake(); }

void ResetButton::run(const std::atomic<bool>& stop) {
  std::vector<gpio::EdgeEvent> edges;
  std::vector<line::ItemStart> pressed;
  pollfd fds[2] = {{wake_fd_.get(), POLLIN, 0}, {input_->fd(), POLLIN, 0}};
  while (!stop.load()) {
    // A press is confirmed `debounce` after its edge: wake then, or every
    // 200 ms (stop).
    std::uint64_t until = protocol::monotonic_ns() + 200'000'000ull;
    if (const auto d = filter_.next_deadline()) until = std::min(until, *d);
    protocol::poll_until(fds, 2, until);
    if (fds[0].revents & POLLIN) wake_fd_.drain();
    edges.clear();
    input_->read_events(edges, 64);
    pressed.clear();
    for (const auto& e : edges)
      if (const auto p = filter_.edge(e.timestamp_ns, e.rising)) pressed.push_back(*p);
    if (const auto p = filter_.advance(protocol::monotonic_ns())) pressed.push_back(*p);
    for (const auto& p : pressed) {
      if (p.too_close) {  // the same finger again, or a bounce past the debounce
        ++ignored_;
        continue;
      }
      ++presses_;
      logger(LogCategory::kGpio).info("reset button ({}): the accumulation starts over", options_.line);
      on_press_(p.timestamp_ns);
    }
  }
}

void ResetButton::stopped(const std::string& why) {
  std::lock_guard<std::mutex> lock(error_mutex_);
  error_ = why;
}

nlohmann::json ResetButton::status() const {
  nlohmann::json s = {{"line", options_.line}, {"presses", presses_.load()}, {"ignored", ignored_.load()}};
  std::lock_guard<std::mutex> lock(error_mutex_);
  if (!error_.empty()) s["error"] = error_;
  return s;
}

}  // namespace tofmat::daemon
