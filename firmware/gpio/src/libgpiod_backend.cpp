// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The libgpiod v1 backend (libgpiod 1.6: Debian 12, Raspberry Pi OS
// bookworm). Each requested line keeps its own chip handle open, so lines
// are independent objects. v1 has no debounce and reports edges in the
// line's logical sense with the kernel's timestamp (CLOCK_MONOTONIC since
// Linux 5.7); the trigger filter (firmware/line) does the debouncing.
#include <gpiod.h>

#include <cerrno>
#include <filesystem>
#include <system_error>

#include "tofmat/gpio/gpio.hpp"

namespace tofmat::gpio {
namespace {

bool any_chip() {
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator("/dev", ec))
    if (e.path().filename().string().rfind("gpiochip", 0) == 0) return true;
  return false;
}

[[noreturn]] void fail(const LineSpec& spec, const std::string& what, int err) {
  std::string hint;
  if (err == EACCES || err == EPERM)
    hint = " (no permission: add the daemon's user to the gpio group, or see the udev rules of your board)";
  else if (err == EBUSY)
    hint = " (another program holds the line: gpioinfo shows which)";
  throw GpioError("GPIO line " + spec.describe() + ": " + what + ": " + std::generic_category().message(err) + hint);
}

struct Handle {
  gpiod_chip* chip = nullptr;
  gpiod_line* line = nullptr;
  Handle() = default;
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;
  ~Handle() {
    if (line) gpiod_line_release(line);
    if (chip) gpiod_chip_close(chip);
  }
};

void open_line(const LineSpec& spec, Handle& h) {
  if (!any_chip())
    throw GpioError("GPIO line " + spec.describe() +
                    ": this machine has no GPIO chip (no /dev/gpiochip*); the sorting line needs the board's "
                    "GPIO (tofmatd --gpio sim simulates one)");
  const bool path = !spec.chip.empty() && spec.chip[0] == '/';
  h.chip = path ? gpiod_chip_open(spec.chip.c_str()) : gpiod_chip_open_by_label(spec.chip.c_str());
  if (!h.chip) {
    const int err = errno;
    if (err == ENOENT)
      throw GpioError("GPIO line " + spec.describe() + ": no chip " + (path ? "at " : "labelled ") + spec.chip +
                      " (gpiodetect lists the chips and their labels)");
    fail(spec, "opening the chip", err);
  }
  if (spec.is_offset()) {
    const unsigned long offset = std::stoul(spec.line);
    h.line = offset <= 0xFFFF ? gpiod_chip_get_line(h.chip, static_cast<unsigned>(offset)) : nullptr;
    if (!h.line) throw GpioError("GPIO line " + spec.describe() + ": the chip has no line " + spec.line);
  } else {
    h.line = gpiod_chip_find_line(h.chip, spec.line.c_str());
    if (!h.line)
      throw GpioError("GPIO line " + spec.describe() + ": the chip has no line named " + spec.line +
                      " (gpioinfo lists them)");
  }
}

int bias_flags(Bias b) {
  switch (b) {
    case Bias::kAsIs: return 0;
    case Bias::kDisabled: return GPIOD_LINE_REQUEST_FLAG_BIAS_DISABLE;
    case Bias::kPullUp: return GPIOD_LINE_REQUEST_FLAG_BIAS_PULL_UP;
    case Bias::kPullDown: return GPIOD_LINE_REQUEST_FLAG_BIAS_PULL_DOWN;
  }
  return 0;
}

class LibgpiodInput : public InputLine {
 public:
  LibgpiodInput(const LineSpec& spec, const InputConfig& config, const std::string& consumer) : spec_(spec) {
    open_line(spec, h_);
    const int flags = (config.active_low ? GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW : 0) | bias_flags(config.bias);
    if (gpiod_line_request_both_edges_events_flags(h_.line, consumer.c_str(), flags) != 0)
      fail(spec, "requesting edge events", errno);
    fd_ = gpiod_line_event_get_fd(h_.line);
  }
  int fd() const override { return fd_; }
  std::size_t read_events(std::vector<EdgeEvent>& out, std::size_t max) override {
    std::size_t n = 0;
    const timespec zero{0, 0};
    while (n < max && gpiod_line_event_wait(h_.line, &zero) == 1) {  // (read only what waits: it blocks otherwise)
      gpiod_line_event events[16];
      const int got =
          gpiod_line_event_read_multiple(h_.line, events, static_cast<unsigned>(std::min<std::size_t>(16, max - n)));
      if (got < 0) fail(spec_, "reading edge events", errno);
      for (int k = 0; k < got; ++k)
        out.push_back({static_cast<std::uint64_t>(events[k].ts.tv_sec) * 1'000'000'000ull +
                           static_cast<std::uint64_t>(events[k].ts.tv_nsec),
                       events[k].event_type == GPIOD_LINE_EVENT_RISING_EDGE});
      n += static_cast<std::size_t>(got);
      if (got == 0) break;
    }
    return n;
  }
  bool value() override {
    const int v = gpiod_line_get_value(h_.line);
    if (v < 0) fail(spec_, "reading the value", errno);
    return v == 1;
  }
  std::string describe() const override { return spec_.describe(); }

 private:
  LineSpec spec_;
  Handle h_;
  int fd_ = -1;
};

class LibgpiodOutput : public OutputLine {
 public:
  LibgpiodOutput(const LineSpec& spec, const OutputConfig& config, const std::string& consumer) : spec_(spec) {
    open_line(spec, h_);
    const int flags = config.active_low ? GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW : 0;
    if (gpiod_line_request_output_flags(h_.line, consumer.c_str(), flags, config.initial ? 1 : 0) != 0)
      fail(spec, "requesting it as an output", errno);
  }
  void set(bool active) override {
    if (gpiod_line_set_value(h_.line, active ? 1 : 0) != 0) fail(spec_, "setting its value", errno);
  }
  std::string describe() const override { return spec_.describe(); }

 private:
  LineSpec spec_;
  Handle h_;
};

class LibgpiodBackend : public Backend {
 public:
  std::string name() const override { return "libgpiod"; }
  std::unique_ptr<InputLine> request_input(const LineSpec& spec, const InputConfig& config,
                                           const std::string& consumer) override {
    return std::make_unique<LibgpiodInput>(spec, config, consumer);
  }
  std::unique_ptr<OutputLine> request_output(const LineSpec& spec, const OutputConfig& config,
                                             const std::string& consumer) override {
    return std::make_unique<LibgpiodOutput>(spec, config, consumer);
  }
};

}  // namespace

std::unique_ptr<Backend> make_libgpiod_backend() { return std::make_unique<LibgpiodBackend>(); }

}  // namespace tofmat::gpio
