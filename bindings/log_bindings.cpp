// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The C++ core's logs in the SDK: a spdlog sink that queues records for Python's logging.
#include <spdlog/sinks/base_sink.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstddef>
#include <deque>
#include <memory>
#include <mutex>
#include <utility>
#include <vector>

#include "core_log.hpp"

namespace tofmat::py {
namespace {

struct CoreRecord {
  spdlog::level::level_enum level;
  std::string text;
};

// Threads of the core (a frame source) log without the GIL: they only queue. The queue is
// bounded so a core that logs while nobody forwards cannot grow without end.
class QueueSink final : public spdlog::sinks::base_sink<std::mutex> {
 public:
  std::vector<CoreRecord> take(std::size_t& dropped) {
    std::lock_guard<std::mutex> lock(mutex_);
    std::vector<CoreRecord> out(std::make_move_iterator(queue_.begin()), std::make_move_iterator(queue_.end()));
    queue_.clear();
    dropped = std::exchange(dropped_, 0);
    return out;
  }

  std::string take_last_problem() {
    std::lock_guard<std::mutex> lock(mutex_);
    return std::exchange(last_problem_, std::string());
  }

 protected:
  void sink_it_(const spdlog::details::log_msg& msg) override {
    std::string text(msg.payload.data(), msg.payload.size());
    if (msg.level >= spdlog::level::warn) last_problem_ = text;
    if (queue_.size() >= kMaxQueued) {
      ++dropped_;
      return;
    }
    queue_.push_back({msg.level, std::move(text)});
  }
  void flush_() override {}

 private:
  static constexpr std::size_t kMaxQueued = 1000;
  std::deque<CoreRecord> queue_;
  std::size_t dropped_ = 0;
  std::string last_problem_;
};

std::shared_ptr<QueueSink>& sink() {
  static auto s = std::make_shared<QueueSink>();
  return s;
}

int python_level(spdlog::level::level_enum level) {
  switch (level) {
    case spdlog::level::trace:
    case spdlog::level::debug: return 10;
    case spdlog::level::info: return 20;
    case spdlog::level::warn: return 30;
    case spdlog::level::err: return 40;
    default: return 50;
  }
}

spdlog::level::level_enum core_level(int python) {
  if (python <= 10) return spdlog::level::debug;
  if (python <= 20) return spdlog::level::info;
  if (python <= 30) return spdlog::level::warn;
  if (python <= 40) return spdlog::level::err;
  return spdlog::level::critical;
}

}  // namespace

void forward_core_logs() {
  std::size_t dropped = 0;
  auto records = sink()->take(dropped);
  auto logger = pyb::module_::import("logging").attr("getLogger")("tofmat.core");
  for (const auto& r : records) logger.attr("log")(python_level(r.level), "%s", r.text);
  if (dropped > 0) logger.attr("warning")("%d log records of the C++ core were dropped (queue full)", dropped);
  // Warnings always reach the sink, whatever Python shows: take_last_core_problem() needs them.
  spdlog::set_level(std::min(core_level(logger.attr("getEffectiveLevel")().cast<int>()), spdlog::level::warn));
}

std::string take_last_core_problem() { return sink()->take_last_problem(); }

void register_logging(pyb::module_& m) {
  auto logger = std::make_shared<spdlog::logger>("tofmat", sink());
  spdlog::set_default_logger(logger);
  spdlog::set_level(spdlog::level::warn);  // Python's own default, until forward_core_logs() reads it
  m.def("forward_core_logs", &forward_core_logs,
        "Hands the C++ core's queued log records to logging.getLogger('tofmat.core') and takes that logger's "
        "level for the core.");
}

}  // namespace tofmat::py
