// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// tofmatd's logs by category (firmware/daemon log.hpp): the --log-level
// syntax and its errors, each category at its own level, the line's shape on
// a terminal and for the journal, and when stderr counts as the journal.
#include "tofmat/daemon/log.hpp"

#include <gtest/gtest.h>
#include <spdlog/sinks/null_sink.h>
#include <spdlog/sinks/ostream_sink.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdlib>
#include <functional>
#include <sstream>
#include <stdexcept>
#include <string>

namespace {

using tofmat::daemon::LogCategory;
using tofmat::daemon::logger;
using tofmat::daemon::parse_log_levels;
using tofmat::daemon::setup_logging;

TEST(LogLevels, OneLevelForAllOrOnePerCategory) {
  auto all = parse_log_levels("debug");
  EXPECT_EQ(all.of(LogCategory::kServer), spdlog::level::debug);
  EXPECT_EQ(all.of(LogCategory::kGpio), spdlog::level::debug);
  auto some = parse_log_levels("server=debug,kinect=warn,*=error");
  EXPECT_EQ(some.of(LogCategory::kServer), spdlog::level::debug);
  EXPECT_EQ(some.of(LogCategory::kKinect), spdlog::level::warn);
  EXPECT_EQ(some.of(LogCategory::kPipeline), spdlog::level::err);
  EXPECT_EQ(parse_log_levels("line=trace").of(LogCategory::kDaemon), spdlog::level::info);  // others: info
}

TEST(LogLevels, BadTextIsAClearError) {
  const auto says = [](const std::string& text, const std::string& part) {
    try {
      parse_log_levels(text);
      ADD_FAILURE() << text << " was accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << text << ": " << e.what();
    }
  };
  says("loud", "\"loud\"");
  says("", "one of trace");
  says("warning", "one of trace");  // (the levels are the flag's own words)
  says("usb=debug", "log category \"usb\"");
  says("server=debug,server=info", "given twice");
  says("*=info,*=debug", "given twice");
  says("server=debug,info", "CATEGORY=LEVEL");
  says("server=", "of server");
  says("server=debug,", "CATEGORY=LEVEL");
}

std::string logged(bool journal, const std::string& levels, const std::function<void()>& what) {
  std::ostringstream out;
  setup_logging(parse_log_levels(levels), journal, std::make_shared<spdlog::sinks::ostream_sink_mt>(out));
  what();
  for (auto c : {LogCategory::kDaemon, LogCategory::kServer, LogCategory::kKinect}) logger(c).flush();
  // (then away from `out`, which goes out of scope with this function)
  setup_logging(parse_log_levels("info"), false, std::make_shared<spdlog::sinks::null_sink_mt>());
  return out.str();
}

TEST(Logging, EachCategoryAtItsOwnLevelAndNamed) {
  const std::string text = logged(false, "server=debug,*=warn", [] {
    logger(LogCategory::kServer).debug("a handshake");
    logger(LogCategory::kKinect).info("a state change");  // below kinect's level (warn): not written
    logger(LogCategory::kKinect).warn("a retry");
    spdlog::info("through the default logger: the daemon's category, below warn");
  });
  EXPECT_NE(text.find(" debug server: a handshake\n"), std::string::npos) << text;
  EXPECT_NE(text.find(" warning kinect: a retry\n"), std::string::npos) << text;
  EXPECT_EQ(text.find("state change"), std::string::npos) << text;
  EXPECT_EQ(text.find("default logger"), std::string::npos) << text;
  EXPECT_EQ(text.rfind("20", 0), 0u) << "a terminal's line starts with the date: " << text;
}

TEST(Logging, TheJournalGetsPrioritiesAndNoTimestamps) {
  const std::string text = logged(true, "debug", [] {
    logger(LogCategory::kDaemon).critical("a");
    logger(LogCategory::kServer).error("b");
    logger(LogCategory::kKinect).warn("c");
    logger(LogCategory::kDaemon).info("d");
    logger(LogCategory::kServer).debug("e");
  });
  EXPECT_EQ(text, "<2>daemon: a\n<3>server: b\n<4>kinect: c\n<6>daemon: d\n<7>server: e\n");
}

TEST(Logging, StderrIsTheJournalOnlyWhenJournalStreamNamesIt) {
  struct stat st {};
  ASSERT_EQ(::fstat(2, &st), 0);
  // (this test runs on one thread: nothing else reads the environment meanwhile)
  // NOLINTBEGIN(concurrency-mt-unsafe)
  ::unsetenv("JOURNAL_STREAM");
  EXPECT_FALSE(tofmat::daemon::stderr_is_journal());
  const std::string same = std::to_string(st.st_dev) + ":" + std::to_string(st.st_ino);
  ::setenv("JOURNAL_STREAM", same.c_str(), 1);
  EXPECT_TRUE(tofmat::daemon::stderr_is_journal());
  ::setenv("JOURNAL_STREAM", (std::to_string(st.st_dev) + ":" + std::to_string(st.st_ino + 1)).c_str(), 1);
  EXPECT_FALSE(tofmat::daemon::stderr_is_journal());  // another stream: stderr was redirected
  ::setenv("JOURNAL_STREAM", "junk", 1);
  EXPECT_FALSE(tofmat::daemon::stderr_is_journal());
  ::setenv("JOURNAL_STREAM", (same + "x").c_str(), 1);
  EXPECT_FALSE(tofmat::daemon::stderr_is_journal());
  ::unsetenv("JOURNAL_STREAM");
  // NOLINTEND(concurrency-mt-unsafe)
}

}  // namespace
