// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// GPIO lines of the sorting line (issue 17): the light barrier and the belt
// encoder as inputs with the kernel's edge timestamps, the outlets' pushers
// and the alarm as outputs. One interface, two backends registered by name:
//   libgpiod  the board's chips through libgpiod's v1 API (Debian 12 and
//             Raspberry Pi OS bookworm ship 1.6)
//   sim       a simulated chip for tests and the simulated belt: edges are
//             injected, output changes recorded with their times
// A line is named in the configuration as CHIP:LINE: CHIP a chip's label
// (`gpiodetect` shows it) or its device path, LINE a line name or an offset.
// Never a chip number alone: numbers change between kernels (the Raspberry
// Pi 5's header chip moved from gpiochip4 to gpiochip0).
#pragma once
#include <cstddef>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace tofmat::gpio {

// A failure of the GPIO system (no such chip or line, a line in use, no
// permission): the message says which line and what to do.
class GpioError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct LineSpec {
  std::string chip;  // label or /dev path
  std::string line;  // name or offset (decimal)
  // "CHIP:LINE"; throws std::invalid_argument (a chip number alone, an empty part).
  static LineSpec parse(const std::string& text);
  std::string describe() const { return chip + ":" + line; }
  bool is_offset() const;
  bool operator==(const LineSpec& o) const { return chip == o.chip && line == o.line; }
};

enum class Bias { kAsIs, kDisabled, kPullUp, kPullDown };
Bias parse_bias(const std::string& name);  // "as-is" | "disabled" | "pull-up" | "pull-down"
const char* bias_name(Bias b);

// Edges in the line's logical sense (active_low inverts them), timestamped by
// the kernel when the interrupt came (CLOCK_MONOTONIC since Linux 5.7), not
// when the daemon read them: schedules are computed from these.
struct EdgeEvent {
  std::uint64_t timestamp_ns = 0;
  bool rising = true;  // to active
};

struct InputConfig {
  bool active_low = false;
  Bias bias = Bias::kAsIs;
};

class InputLine {
 public:
  virtual ~InputLine() = default;
  // Readable (poll POLLIN) when events wait.
  virtual int fd() const = 0;
  // The events waiting, without blocking (appended; at most `max`).
  virtual std::size_t read_events(std::vector<EdgeEvent>& out, std::size_t max = 64) = 0;
  virtual bool value() = 0;  // active now
  virtual std::string describe() const = 0;
};

class OutputLine {
 public:
  virtual ~OutputLine() = default;
  virtual void set(bool active) = 0;
  virtual std::string describe() const = 0;
};

struct OutputConfig {
  bool active_low = false;
  bool initial = false;  // active at request
};

class Backend {
 public:
  virtual ~Backend() = default;
  virtual std::string name() const = 0;
  // Throw GpioError (no chip, no line, busy) naming the line.
  virtual std::unique_ptr<InputLine> request_input(const LineSpec& spec, const InputConfig& config,
                                                   const std::string& consumer) = 0;
  virtual std::unique_ptr<OutputLine> request_output(const LineSpec& spec, const OutputConfig& config,
                                                     const std::string& consumer) = 0;
};

// The libgpiod backend; its requests fail with GpioError where the machine
// has no such chip (these build machines have none at all).
std::unique_ptr<Backend> make_libgpiod_backend();

}  // namespace tofmat::gpio
