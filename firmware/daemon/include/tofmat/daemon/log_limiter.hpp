// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Rate-limited logging for what clients can cause (connections, refusals,
// protocol errors): per kind, at most `burst` lines per interval; the rest
// are counted and reported in one summary line when the kind may log again.
// A client that connects and closes in a loop, or floods bad requests, then
// costs the log a few lines a minute instead of two lines per attempt.
#pragma once
#include <cstdint>
#include <map>
#include <string>

namespace tofmat::daemon {

class LogLimiter {
 public:
  LogLimiter(int burst = 10, std::uint64_t interval_ns = 10'000'000'000ull)
      : burst_(burst), interval_ns_(interval_ns) {}
  // Whether a line of this kind may be logged now. When it may after some
  // were held back, `suppressed` says how many (log it with the line).
  bool allow(const std::string& kind, std::uint64_t now_ns, std::uint64_t& suppressed);
  // Lines held back so far, all kinds (status: log_suppressed).
  std::uint64_t total_suppressed() const { return total_suppressed_; }

 private:
  struct Window {
    std::uint64_t start_ns = 0;
    int lines = 0;
    std::uint64_t suppressed = 0;
  };
  int burst_;
  std::uint64_t interval_ns_;
  std::map<std::string, Window> windows_;  // (kinds are a fixed handful: bounded)
  std::uint64_t total_suppressed_ = 0;
};

}  // namespace tofmat::daemon
