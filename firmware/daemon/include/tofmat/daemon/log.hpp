// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// tofmatd's logs by category: one logger per part of the daemon (daemon,
// kinect, server, pipeline, profile, gpio, line), all on stderr, each at its
// own level (--log-level server=debug,*=info). Under systemd (the journal
// holds stderr: $JOURNAL_STREAM) a line starts with its syslog priority
// ("<3>" error ... "<7>" debug) and carries no timestamp of ours.
#pragma once

#include <spdlog/sinks/sink.h>
#include <spdlog/spdlog.h>

#include <array>
#include <map>
#include <memory>
#include <string>

namespace tofmat::daemon {

enum class LogCategory { kDaemon, kKinect, kServer, kPipeline, kProfile, kGpio, kLine };
inline constexpr std::array<const char*, 7> kLogCategories = {"daemon",  "kinect", "server", "pipeline",
                                                              "profile", "gpio",   "line"};

struct LogLevels {
  spdlog::level::level_enum others = spdlog::level::info;        // "*", or a level alone
  std::map<std::string, spdlog::level::level_enum> by_category;  // the categories given by name
  spdlog::level::level_enum of(LogCategory c) const;
};

// "LEVEL" (every category) or "CATEGORY=LEVEL,...[,*=LEVEL]"; levels trace,
// debug, info, warn, error. Throws std::invalid_argument naming an unknown
// category or level, or a category given twice.
LogLevels parse_log_levels(const std::string& text);

// Makes the categories' loggers on `sink` (stderr's when null) at their
// levels: with the time (a terminal, a file) or, for the journal, with a
// syslog priority prefix instead. Call before the daemon's threads start.
void setup_logging(const LogLevels& levels, bool journal, std::shared_ptr<spdlog::sinks::sink> sink = nullptr);

// Whether stderr goes to the journal ($JOURNAL_STREAM names stderr's device and inode).
bool stderr_is_journal();

// The category's logger; spdlog's default one until setup_logging runs (the
// Python extension, tests), so that library code logs the same either way.
spdlog::logger& logger(LogCategory c);

}  // namespace tofmat::daemon
