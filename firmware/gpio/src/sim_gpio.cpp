// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// SimGpio: the simulated chip's input and output lines, driven and recorded with their timestamps.
#include "tofmat/gpio/sim_gpio.hpp"

#include <sys/eventfd.h>
#include <time.h>
#include <unistd.h>

#include <cerrno>
#include <system_error>

namespace tofmat::gpio {
namespace {

std::uint64_t now_ns() {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::uint64_t>(ts.tv_sec) * 1'000'000'000ull + static_cast<std::uint64_t>(ts.tv_nsec);
}

}  // namespace

class SimInput : public InputLine {
 public:
  SimInput(std::shared_ptr<SimGpio> gpio, std::string line, int fd)
      : gpio_(std::move(gpio)), line_(std::move(line)), fd_(fd) {}
  ~SimInput() override { gpio_->release(line_); }
  int fd() const override { return fd_; }
  std::size_t read_events(std::vector<EdgeEvent>& out, std::size_t max) override {
    std::lock_guard<std::mutex> lock(gpio_->mutex_);
    auto& q = gpio_->lines_.at(line_).queue;
    const std::size_t n = std::min(max, q.size());
    out.insert(out.end(), q.begin(), q.begin() + static_cast<std::ptrdiff_t>(n));
    q.erase(q.begin(), q.begin() + static_cast<std::ptrdiff_t>(n));
    if (q.empty()) {  // (drained: the fd stops being readable)
      std::uint64_t v;
      [[maybe_unused]] const auto r = ::read(fd_, &v, sizeof v);
    }
    return n;
  }
  bool value() override {
    std::lock_guard<std::mutex> lock(gpio_->mutex_);
    const auto& l = gpio_->lines_.at(line_);
    return l.high != l.active_low;
  }
  std::string describe() const override { return std::string(SimGpio::kChip) + ":" + line_ + " (simulated)"; }

 private:
  std::shared_ptr<SimGpio> gpio_;
  std::string line_;
  int fd_;
};

class SimOutput : public OutputLine {
 public:
  SimOutput(std::shared_ptr<SimGpio> gpio, std::string line, bool active_low)
      : gpio_(std::move(gpio)), line_(std::move(line)), active_low_(active_low) {}
  ~SimOutput() override { gpio_->release(line_); }
  void set(bool active) override {
    std::lock_guard<std::mutex> lock(gpio_->mutex_);
    auto& l = gpio_->lines_.at(line_);
    l.high = active != active_low_;
    l.changes.push_back({now_ns(), active, l.high});
  }
  std::string describe() const override { return std::string(SimGpio::kChip) + ":" + line_ + " (simulated)"; }

 private:
  std::shared_ptr<SimGpio> gpio_;
  std::string line_;
  bool active_low_;
};

SimGpio::Line& SimGpio::line_of(const LineSpec& spec) {
  if (spec.chip != kChip)
    throw GpioError("GPIO line " + spec.describe() + ": no chip \"" + spec.chip +
                    "\" (the simulated backend has one chip, \"sim\")");
  auto& l = lines_[spec.line];
  if (!l.consumer.empty())
    throw GpioError("GPIO line " + spec.describe() + " is busy: requested by \"" + l.consumer + "\"");
  return l;
}

std::unique_ptr<InputLine> SimGpio::request_input(const LineSpec& spec, const InputConfig& config,
                                                  const std::string& consumer) {
  std::lock_guard<std::mutex> lock(mutex_);
  Line& l = line_of(spec);
  const int fd = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (fd < 0) throw GpioError(std::string("eventfd: ") + std::generic_category().message(errno));
  if (config.bias == Bias::kPullUp) l.high = true;  // (an undriven pin follows its bias)
  if (config.bias == Bias::kPullDown) l.high = false;
  l.consumer = consumer.empty() ? "?" : consumer;
  l.active_low = config.active_low;
  l.output = false;
  l.queue.clear();
  l.event_fd = fd;
  return std::make_unique<SimInput>(shared_from_this(), spec.line, fd);
}

std::unique_ptr<OutputLine> SimGpio::request_output(const LineSpec& spec, const OutputConfig& config,
                                                    const std::string& consumer) {
  std::unique_ptr<SimOutput> out;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    Line& l = line_of(spec);
    l.consumer = consumer.empty() ? "?" : consumer;
    l.output = true;
    out = std::make_unique<SimOutput>(shared_from_this(), spec.line, config.active_low);
  }
  out->set(config.initial);
  return out;
}

void SimGpio::drive(const std::string& line, bool high, std::uint64_t timestamp_ns) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto& l = lines_[line];
  if (l.output) throw GpioError(std::string("GPIO line sim:") + line + " is an output; it cannot be driven");
  if (l.high == high) return;
  l.high = high;
  if (l.event_fd < 0 || l.consumer.empty()) return;  // nobody listens: no event
  if (l.queue.size() >= kQueue) {
    l.queue.erase(l.queue.begin());
    ++lost_;
  }
  l.queue.push_back({timestamp_ns, high != l.active_low});
  const std::uint64_t one = 1;
  [[maybe_unused]] const auto r = ::write(l.event_fd, &one, sizeof one);
}

std::vector<SimGpio::Change> SimGpio::changes(const std::string& line) const {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto it = lines_.find(line);
  return it == lines_.end() ? std::vector<Change>{} : it->second.changes;
}

std::string SimGpio::consumer(const std::string& line) const {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto it = lines_.find(line);
  return it == lines_.end() ? "" : it->second.consumer;
}

std::uint64_t SimGpio::lost_events() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return lost_;
}

void SimGpio::release(const std::string& line) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto& l = lines_.at(line);
  l.consumer.clear();
  l.queue.clear();
  if (l.event_fd >= 0) ::close(l.event_fd);
  l.event_fd = -1;
  l.output = false;
}

}  // namespace tofmat::gpio
