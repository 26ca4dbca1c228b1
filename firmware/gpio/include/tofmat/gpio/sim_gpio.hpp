// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The simulated GPIO backend ("sim"): one chip, labelled "sim", whose lines
// exist as soon as they are named. Inputs are driven from outside (a test, or
// the simulated belt's light barrier and encoder) with the time the edge
// happened; outputs record every change with the time it was made. It keeps
// the kernel's rules that matter here: a line is requested once at a time,
// edges are reported in the line's logical sense (active_low), an input's
// queue is bounded (the oldest event is lost, as a full kernel buffer loses
// them), and a level that does not change makes no edge.
#pragma once
#include <map>
#include <mutex>
#include <set>

#include "tofmat/gpio/gpio.hpp"

namespace tofmat::gpio {

class SimGpio : public Backend, public std::enable_shared_from_this<SimGpio> {
 public:
  static constexpr const char* kChip = "sim";
  static constexpr std::size_t kQueue = 1024;  // events an input holds unread

  struct Change {
    std::uint64_t timestamp_ns;
    bool active;  // logical
    bool high;    // the pin's level
  };

  static std::shared_ptr<SimGpio> create() { return std::shared_ptr<SimGpio>(new SimGpio()); }

  std::string name() const override { return "sim"; }
  std::unique_ptr<InputLine> request_input(const LineSpec& spec, const InputConfig& config,
                                           const std::string& consumer) override;
  std::unique_ptr<OutputLine> request_output(const LineSpec& spec, const OutputConfig& config,
                                             const std::string& consumer) override;

  // Drive an input line's pin to `high` at `timestamp_ns` (CLOCK_MONOTONIC).
  // The line need not be requested yet (its level is kept). Same level: no edge.
  void drive(const std::string& line, bool high, std::uint64_t timestamp_ns);
  // An output line's changes, oldest first (also after it was released).
  std::vector<Change> changes(const std::string& line) const;
  // Whether a line is requested now, and by whom ("" if not).
  std::string consumer(const std::string& line) const;
  std::uint64_t lost_events() const;

 private:
  SimGpio() = default;
  friend class SimInput;
  friend class SimOutput;
  struct Line {
    bool high = false;
    std::string consumer;  // "" = free
    // Input:
    bool active_low = false;
    std::vector<EdgeEvent> queue;
    int event_fd = -1;
    // Output:
    bool output = false;
    std::vector<Change> changes;
  };
  Line& line_of(const LineSpec& spec);  // checks the chip (mutex held)
  void release(const std::string& line);
  mutable std::mutex mutex_;
  std::map<std::string, Line> lines_;
  std::uint64_t lost_ = 0;
};

}  // namespace tofmat::gpio
