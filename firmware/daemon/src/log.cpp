// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// tofmatd's logs by category (log.hpp): the levels' syntax, the loggers, the journal's prefix.
#include "tofmat/daemon/log.hpp"

#include <spdlog/fmt/ranges.h>
#include <spdlog/pattern_formatter.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <sys/stat.h>

#include <algorithm>
#include <cstdlib>
#include <stdexcept>
#include <string>

namespace tofmat::daemon {
namespace {

std::array<std::shared_ptr<spdlog::logger>, kLogCategories.size()> loggers;

spdlog::level::level_enum level_named(const std::string& name, const std::string& where) {
  static const std::pair<const char*, spdlog::level::level_enum> levels[] = {{"trace", spdlog::level::trace},
                                                                             {"debug", spdlog::level::debug},
                                                                             {"info", spdlog::level::info},
                                                                             {"warn", spdlog::level::warn},
                                                                             {"error", spdlog::level::err}};
  for (const auto& [n, l] : levels)
    if (name == n) return l;
  throw std::invalid_argument("log level " + where + "\"" + name + "\": one of trace, debug, info, warn, error");
}

// "<N>": the syslog priority of the record's level, which the journal reads.
class SyslogPriority : public spdlog::custom_flag_formatter {
 public:
  void format(const spdlog::details::log_msg& msg, const std::tm&, spdlog::memory_buf_t& dest) override {
    char p = '6';
    switch (msg.level) {
      case spdlog::level::trace:
      case spdlog::level::debug: p = '7'; break;
      case spdlog::level::info: p = '6'; break;
      case spdlog::level::warn: p = '4'; break;
      case spdlog::level::err: p = '3'; break;
      default: p = '2'; break;  // critical
    }
    const char text[] = {'<', p, '>'};
    dest.append(text, text + 3);
  }
  std::unique_ptr<spdlog::custom_flag_formatter> clone() const override { return std::make_unique<SyslogPriority>(); }
};

}  // namespace

spdlog::level::level_enum LogLevels::of(LogCategory c) const {
  const auto it = by_category.find(kLogCategories[static_cast<std::size_t>(c)]);
  return it == by_category.end() ? others : it->second;
}

LogLevels parse_log_levels(const std::string& text) {
  LogLevels out;
  if (text.find('=') == std::string::npos) {
    out.others = level_named(text, "");
    return out;
  }
  bool others_given = false;
  std::size_t at = 0;
  while (at <= text.size()) {
    const std::size_t end = std::min(text.find(',', at), text.size());
    const std::string item = text.substr(at, end - at);
    at = end + 1;
    const auto eq = item.find('=');
    if (eq == std::string::npos)
      throw std::invalid_argument("log level \"" + item + "\": give CATEGORY=LEVEL (or one LEVEL for all)");
    const std::string name = item.substr(0, eq);
    const auto level = level_named(item.substr(eq + 1), "of " + name + ": ");
    if (name == "*") {
      if (others_given) throw std::invalid_argument("log level: \"*\" given twice");
      others_given = true;
      out.others = level;
      continue;
    }
    if (std::find(kLogCategories.begin(), kLogCategories.end(), name) == kLogCategories.end())
      throw std::invalid_argument(
          fmt::format("log category \"{}\": one of {}, *", name, fmt::join(kLogCategories, ", ")));
    if (!out.by_category.emplace(name, level).second)
      throw std::invalid_argument("log category \"" + name + "\" given twice");
  }
  return out;
}

void setup_logging(const LogLevels& levels, bool journal, std::shared_ptr<spdlog::sinks::sink> sink) {
  if (!sink) sink = std::make_shared<spdlog::sinks::stderr_color_sink_mt>();
  auto formatter = std::make_unique<spdlog::pattern_formatter>();
  if (journal)
    formatter->add_flag<SyslogPriority>('*').set_pattern("%*%n: %v");  // (the journal stamps the time)
  else
    formatter->set_pattern("%Y-%m-%d %H:%M:%S.%e %^%l%$ %n: %v");
  sink->set_formatter(std::move(formatter));
  sink->set_level(spdlog::level::trace);  // (each logger filters at its own level)
  for (std::size_t c = 0; c < kLogCategories.size(); ++c) {
    auto l = std::make_shared<spdlog::logger>(kLogCategories[c], sink);
    l->set_level(levels.of(static_cast<LogCategory>(c)));
    l->flush_on(spdlog::level::warn);
    loggers[c] = std::move(l);
  }
  spdlog::set_default_logger(loggers[static_cast<std::size_t>(LogCategory::kDaemon)]);
}

bool stderr_is_journal() {
  // systemd sets JOURNAL_STREAM=DEVICE:INODE of the stream it connected; stderr must be that one.
  // (Read once at start, before any thread: nothing sets the environment concurrently.)
  const char* v = std::getenv("JOURNAL_STREAM");  // NOLINT(concurrency-mt-unsafe)
  if (v == nullptr) return false;
  const std::string text(v);
  const auto colon = text.find(':');
  if (colon == std::string::npos || colon == 0 || colon + 1 == text.size()) return false;
  unsigned long long dev = 0, ino = 0;
  try {
    std::size_t used_dev = 0, used_ino = 0;
    dev = std::stoull(text.substr(0, colon), &used_dev);
    ino = std::stoull(text.substr(colon + 1), &used_ino);
    if (used_dev != colon || used_ino != text.size() - colon - 1) return false;
  } catch (const std::exception&) {  // (not numbers, or out of range)
    return false;
  }
  struct stat st {};
  if (::fstat(2, &st) != 0) return false;
  return static_cast<unsigned long long>(st.st_dev) == dev && static_cast<unsigned long long>(st.st_ino) == ino;
}

spdlog::logger& logger(LogCategory c) {
  const auto& l = loggers[static_cast<std::size_t>(c)];
  return l ? *l : *spdlog::default_logger_raw();
}

}  // namespace tofmat::daemon
