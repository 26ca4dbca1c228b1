// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// LogLimiter: the per-kind burst and interval that decide whether a log line is written or counted.
#include "tofmat/daemon/log_limiter.hpp"

namespace tofmat::daemon {

bool LogLimiter::allow(const std::string& kind, std::uint64_t now_ns, std::uint64_t& suppressed) {
  Window& w = windows_[kind];
  if (now_ns - w.start_ns >= interval_ns_) {
    w.start_ns = now_ns;
    w.lines = 0;
  }
  if (w.lines >= burst_) {
    ++w.suppressed;
    ++total_suppressed_;
    return false;
  }
  ++w.lines;
  suppressed = w.suppressed;
  w.suppressed = 0;
  return true;
}

}  // namespace tofmat::daemon
