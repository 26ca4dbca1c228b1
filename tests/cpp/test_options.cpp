// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// tofmatd's command line and configuration file (firmware/daemon/src/options.cpp):
// the defaults a box runs with (the camera, never the simulator; the
// simulator's data only beside an installed program), every flag reaching
// its option, the file's keys with the command line winning, and every bad
// input refused with status 2 (a usage error) and nothing returned.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

#include "tofmat/daemon/options.hpp"

namespace {

using tofmat::daemon::CommandLine;
using tofmat::daemon::parse_command_line;

struct Parsed {
  std::optional<CommandLine> cl;
  int exit_code = -1;
};

Parsed parse(std::vector<std::string> args) {
  args.insert(args.begin(), "tofmatd");
  std::vector<char*> argv;
  argv.reserve(args.size());
  for (auto& a : args) argv.push_back(a.data());
  Parsed p;
  p.cl = parse_command_line(static_cast<int>(argv.size()), argv.data(), p.exit_code);
  return p;
}

std::filesystem::path temp_file(const std::string& name, const std::string& text) {
  auto path = std::filesystem::temp_directory_path() / ("tofmat_test_options_" + name);
  std::ofstream(path) << text;
  return path;
}

// A token file as tofmatd wants one: nobody but its owner (and group) may read it.
std::filesystem::path token_file(const std::string& name, const std::string& text,
                                 std::filesystem::perms perms = std::filesystem::perms::owner_read |
                                                                std::filesystem::perms::owner_write) {
  auto path = temp_file(name, text);
  std::filesystem::permissions(path, perms);
  return path;
}

void expect_usage_error(std::vector<std::string> args) {
  const auto p = parse(args);
  EXPECT_FALSE(p.cl.has_value());
  EXPECT_EQ(p.exit_code, 2) << args.back();
}

TEST(Options, TheDefaultsAreTheCameraAndTheServicesSocket) {
  const auto p = parse({"--table", "t.tmx"});
  ASSERT_TRUE(p.cl.has_value());
  const auto& o = p.cl->daemon;
  EXPECT_EQ(o.source, "kinect");  // never the simulator by default
  EXPECT_TRUE(o.profile.region_vote);
  EXPECT_EQ(o.table, "t.tmx");
  EXPECT_EQ(o.server.socket_path, "/run/tofmat/tofmatd.sock");
  EXPECT_EQ(o.server.socket_mode, 0660u);
  EXPECT_TRUE(o.server.tcp.empty());
  EXPECT_EQ(o.profile.name, "handheld");
  EXPECT_EQ(o.profile.backend, tofmat::daemon::Backend::kFixed);
  EXPECT_EQ(o.profile.method, tofmat::daemon::Method::kSession);  // as the SDK's (ProfileConfig)
  EXPECT_FALSE(o.profile.open_set);                               // the open set asked for only
  EXPECT_TRUE(o.profile.session_learning);                        // the session matcher learns its session
  EXPECT_EQ(o.queue_frames, 2u);
  EXPECT_EQ(p.cl->log_level, "info");
  // This test program is not installed: no simulator data beside it, and no
  // path of the build machine compiled in.
  EXPECT_EQ(o.source_options.sim_data_dir, "");
}

TEST(Options, EveryFlagReachesItsOption) {
  const auto token = token_file("token", "  0123456789abcdef-secret \t\r\nsecond line\n");
  const auto control = token_file("control_token", "control-0123456789abcdef\n",
                                  std::filesystem::perms::owner_read | std::filesystem::perms::group_read);
  // One flag and its value a pair, as on a command line (clang-format would put one string a line).
  // clang-format off
  const auto p = parse({"--table", "t.tmx", "--source", "sim:static,material=cork", "--profile", "sorting",
                        "--backend", "float", "--classifier", "eq12",
                        "--socket", "/tmp/s.sock", "--socket-mode", "0600",
                        "--tcp", "127.0.0.1:7020", "--token-file", token.string(),
                        "--control-token-file", control.string(), "--control-group", "root",
                        "--max-tcp-clients", "5", "--max-clients-per-peer", "3", "--idle-timeout", "12",
                        "--peer-request-rate", "50", "--peer-connect-rate", "2.5", "--roi", "10,20,60,70",
                        "--candidates", "pvc,epvc", "--top-k", "3", "--burst", "12", "--smooth", "5", "--no-region-vote", "--accumulate", "8",
                        "--threads", "3", "--queue-frames", "4", "--max-clients", "9",
                        "--sim-data", "/opt/sim", "--log-level", "server=debug,*=warn"});
  // clang-format on
  std::filesystem::remove(token);
  std::filesystem::remove(control);
  ASSERT_TRUE(p.cl.has_value());
  const auto& o = p.cl->daemon;
  EXPECT_EQ(o.source, "sim:static,material=cork");
  EXPECT_EQ(o.profile.name, "sorting");
  EXPECT_EQ(o.profile.backend, tofmat::daemon::Backend::kFloat);
  EXPECT_EQ(o.profile.method, tofmat::daemon::Method::kEq12);
  EXPECT_EQ(o.server.socket_path, "/tmp/s.sock");
  EXPECT_EQ(o.server.socket_mode, 0600u);
  EXPECT_EQ(o.server.tcp, "127.0.0.1:7020");
  EXPECT_EQ(o.server.token, "0123456789abcdef-secret");  // (the first line, without the blanks around it)
  EXPECT_EQ(o.server.control_token, "control-0123456789abcdef");
  EXPECT_EQ(o.server.control_gid, 0);
  EXPECT_EQ(o.server.max_tcp_clients, 5u);
  EXPECT_EQ(o.server.max_clients_per_peer, 3u);
  EXPECT_EQ(o.server.idle_timeout_ms, 12000);
  EXPECT_EQ(o.server.peer_request_rate, 50.0);
  EXPECT_EQ(o.server.peer_connect_rate, 2.5);
  EXPECT_EQ(o.profile.roi.x0, 10);
  EXPECT_EQ(o.profile.roi.y1, 70);
  EXPECT_EQ(o.profile.candidates, (std::vector<std::string>{"pvc", "epvc"}));
  EXPECT_EQ(o.profile.top_k, 3);
  EXPECT_EQ(o.profile.burst, 12);
  EXPECT_EQ(o.profile.smooth, 5);
  EXPECT_FALSE(o.profile.region_vote);
  EXPECT_EQ(o.profile.accumulate, 8);
  EXPECT_EQ(o.profile.threads, 3);
  EXPECT_EQ(o.queue_frames, 4u);
  EXPECT_EQ(o.server.max_clients, 9u);
  EXPECT_EQ(o.source_options.sim_data_dir, "/opt/sim");
  EXPECT_EQ(p.cl->log_level, "server=debug,*=warn");
}

TEST(Options, TheResetButtonReachesItsOptionsWithOrWithoutALine) {
  const auto p =
      parse({"--table", "t", "--gpio", "libgpiod", "--reset-button", "pinctrl-rp1:GPIO5", "--reset-button-active-low",
             "--reset-button-bias", "pull-up", "--reset-button-debounce-ms", "35"});
  ASSERT_TRUE(p.cl.has_value());
  const auto& o = p.cl->daemon;
  EXPECT_EQ(o.button.line, "pinctrl-rp1:GPIO5");
  EXPECT_TRUE(o.button.active_low);
  EXPECT_EQ(o.button.bias, "pull-up");
  EXPECT_EQ(o.button.debounce_ms, 35.0);
  EXPECT_FALSE(o.line.enabled());  // GPIO for the button alone: no sorting line
  const auto both = parse({"--table", "t", "--gpio", "sim", "--line-barrier", "sim:barrier", "--line-speed", "500",
                           "--reset-button", "sim:button"});
  ASSERT_TRUE(both.cl.has_value());
  EXPECT_TRUE(both.cl->daemon.line.enabled());
  EXPECT_TRUE(both.cl->daemon.button.enabled());
}

TEST(Options, TheConfigurationFileHasTheFlagsKeysAndTheCommandLineWins) {
  const auto cfg =
      temp_file("cfg.toml",
                "table = \"/usr/share/t.tmx\"\nprofile = \"segmentation\"\nsmooth = 7\nno-region-vote = true\n"
                "candidates = [\"cork\", \"paper\"]\nlog-level = \"warn\"\n");
  const auto from_file = parse({"--config", cfg.string()});
  const auto overridden = parse({"--config", cfg.string(), "--profile", "sorting"});
  std::filesystem::remove(cfg);
  ASSERT_TRUE(from_file.cl.has_value());
  EXPECT_EQ(from_file.cl->daemon.table, "/usr/share/t.tmx");
  EXPECT_EQ(from_file.cl->daemon.profile.name, "segmentation");
  EXPECT_EQ(from_file.cl->daemon.profile.smooth, 7);
  EXPECT_FALSE(from_file.cl->daemon.profile.region_vote);
  EXPECT_EQ(from_file.cl->daemon.profile.candidates, (std::vector<std::string>{"cork", "paper"}));
  EXPECT_EQ(from_file.cl->log_level, "warn");
  EXPECT_EQ(from_file.cl->daemon.source, "kinect");  // the file does not name one: still the camera
  ASSERT_TRUE(overridden.cl.has_value());
  EXPECT_EQ(overridden.cl->daemon.profile.name, "sorting");
}

TEST(Options, TheConfigurationFileIsStrictAndBounded) {
  // (issue 16, case 6) A misspelt key, a line that is not a key, a file over
  // 64 KiB, a folder: each a usage error naming the problem; nothing is read
  // from a file that is not a regular one.
  const auto typo = temp_file("typo.toml", "table = \"t.tmx\"\nsmooht = 5\n");
  const auto garbage = temp_file("garbage.toml", "table = \"t.tmx\"\nthis is not a setting\n");
  const auto big = temp_file("big.toml", "table = \"t.tmx\"\n# " + std::string(70 * 1024, 'x') + "\n");
  for (const auto& f : {typo, garbage, big}) {
    SCOPED_TRACE(f.string());
    const auto p = parse({"--config", f.string()});
    EXPECT_FALSE(p.cl.has_value());
    EXPECT_EQ(p.exit_code, 2);
  }
  const auto folder = std::filesystem::temp_directory_path();
  EXPECT_EQ(parse({"--config=" + folder.string()}).exit_code, 2);
  // The same keys spelt right are taken.
  const auto right = temp_file("right.toml", "table = \"t.tmx\"\nsmooth = 5\nno-region-vote = false\n");
  const auto ok = parse({"--config", right.string()});
  ASSERT_TRUE(ok.cl.has_value());
  EXPECT_EQ(ok.cl->daemon.profile.smooth, 5);
  EXPECT_TRUE(ok.cl->daemon.profile.region_vote);  // (false: the vote stays)
  for (const auto& f : {typo, garbage, big, right}) std::filesystem::remove(f);
}

// The usage error's text on stderr, and its status.
std::pair<std::string, int> usage_text(std::vector<std::string> args) {
  testing::internal::CaptureStderr();
  const auto p = parse(std::move(args));
  const std::string text = testing::internal::GetCapturedStderr();
  EXPECT_FALSE(p.cl.has_value());
  return {text, p.exit_code};
}

TEST(Options, RangesOfTheProfilesFlagsAreUsageErrors) {
  // (issue 33) Out of range these once reached the profile and exited 1 at start.
  for (const auto& [flag, value] : std::vector<std::pair<std::string, std::string>>{{"--top-k", "0"},
                                                                                    {"--top-k", "65"},
                                                                                    {"--burst", "0"},
                                                                                    {"--burst", "301"},
                                                                                    {"--smooth", "4"},
                                                                                    {"--smooth", "17"},
                                                                                    {"--smooth", "-1"}}) {
    SCOPED_TRACE(flag);
    SCOPED_TRACE(value);
    const auto [text, status] = usage_text({"--table", "t", flag, value});
    EXPECT_EQ(status, 2);
    EXPECT_NE(text.find(flag), std::string::npos) << text;
  }
  for (const auto& [flag, value] :
       std::vector<std::pair<std::string, std::string>>{{"--top-k", "64"}, {"--burst", "300"}, {"--smooth", "15"}}) {
    EXPECT_TRUE(parse({"--table", "t", flag, value}).cl.has_value()) << flag;
  }
  // A number too large says the range, not "must be a number >= 0".
  const auto [text, status] = usage_text({"--table", "t", "--line-margin-ms", "1e308"});
  EXPECT_EQ(status, 2);
  EXPECT_NE(text.find("from 0 to 1e9"), std::string::npos) << text;
}

TEST(Options, AConfigurationErrorNamesItsLineAndEscapesWhatTheFileHeld) {
  const auto bad_value = temp_file("line.toml", "table = \"t.tmx\"\n# a comment\ntop-k = 0\n");
  {
    const auto [text, status] = usage_text({"--config", bad_value.string()});
    EXPECT_EQ(status, 2);
    EXPECT_NE(text.find("line 3"), std::string::npos) << text;
    EXPECT_NE(text.find(bad_value.string()), std::string::npos) << text;
  }
  {  // (the command line's own value is not the file's: no line)
    const auto [text, status] = usage_text({"--config", bad_value.string(), "--top-k", "99"});
    EXPECT_EQ(status, 2);
    EXPECT_EQ(text.find("line "), std::string::npos) << text;
  }
  const auto unknown = temp_file("unknown.toml", "table = \"t.tmx\"\n\nsmooht = 5\n");
  {
    const auto [text, status] = usage_text({"--config", unknown.string()});
    EXPECT_EQ(status, 2);
    EXPECT_NE(text.find("line 3"), std::string::npos) << text;
  }
  const auto garbage = temp_file("bytes.toml",
                                 "table = \"t.tmx\"\n\xff\xfe\x1b[2J\x07 = \x9b"
                                 "31m\n");
  const auto [text, status] = usage_text({"--config", garbage.string()});
  EXPECT_EQ(status, 2);
  for (const char c : text) {
    const auto b = static_cast<unsigned char>(c);
    EXPECT_TRUE(c == '\n' || (b >= 0x20 && b < 0x7f)) << "raw byte " << int(b) << " in: " << text;
  }
  for (const auto& f : {bad_value, unknown, garbage}) std::filesystem::remove(f);
}

TEST(Options, HelpAndVersionExitWithZero) {
  for (const char* flag : {"--help", "--version"}) {
    const auto p = parse({flag});
    EXPECT_FALSE(p.cl.has_value());
    EXPECT_EQ(p.exit_code, 0) << flag;
  }
}

TEST(Options, BadInputIsAUsageErrorWithStatusTwo) {
  const auto short_token = token_file("short_token", "too short\n");
  expect_usage_error({});                                                 // no table
  expect_usage_error({"--table", "t", "--no-such-flag"});                 // unknown flag
  expect_usage_error({"--table", "t", "stray"});                          // stray argument
  expect_usage_error({"--table"});                                        // a flag without its value
  expect_usage_error({"--table", "t", "--top-k", "many"});                // not a number
  expect_usage_error({"--table", "t", "--queue-frames", "0"});            // out of range
  expect_usage_error({"--table", "t", "--max-clients", "5000"});          // out of range
  expect_usage_error({"--table", "t", "--threads", "-1"});                // out of range
  expect_usage_error({"--config", "/dev/zero"});                          // not a regular file (endless)
  expect_usage_error({"--table", "t", "--log-level", "chatty"});          // not a level
  expect_usage_error({"--table", "t", "--log-level", "usb=debug"});       // not a category
  expect_usage_error({"--table", "t", "--log-level", "server=debug,x"});  // not CATEGORY=LEVEL
  expect_usage_error({"--table", "t", "--accumulate", "0"});              // out of range
  expect_usage_error({"--table", "t", "--accumulate", "257"});            // out of range
  expect_usage_error({"--table", "t", "--backend", "gpu"});               // not a backend
  expect_usage_error({"--table", "t", "--classifier", "knn"});            // not a classifier
  // The open set needs the session matcher's noise model; it reaches its option.
  expect_usage_error({"--table", "t", "--classifier", "eq12", "--open-set"});
  {
    const auto p = parse({"--table", "t", "--open-set"});  // (the session matcher, the default)
    ASSERT_TRUE(p.cl.has_value());
    EXPECT_TRUE(p.cl->daemon.profile.open_set);
  }
  // Learning the session is the session matcher's, on unless turned off; another classifier has none, and asking
  // for it there is a usage error.
  {
    const auto off = parse({"--table", "t", "--no-session-learning"});
    ASSERT_TRUE(off.cl.has_value());
    EXPECT_FALSE(off.cl->daemon.profile.session_learning);
    const auto eq12 = parse({"--table", "t", "--classifier", "eq12"});
    ASSERT_TRUE(eq12.cl.has_value());
    EXPECT_FALSE(eq12.cl->daemon.profile.session_learning);
    const auto eq12_off = parse({"--table", "t", "--classifier", "eq12", "--no-session-learning"});
    ASSERT_TRUE(eq12_off.cl.has_value());
    const auto cfg = temp_file("learning.toml", "table = \"t\"\nsession-learning = false\n");
    const auto from_file = parse({"--config", cfg.string()});
    std::filesystem::remove(cfg);
    ASSERT_TRUE(from_file.cl.has_value());
    EXPECT_FALSE(from_file.cl->daemon.profile.session_learning);
  }
  expect_usage_error({"--table", "t", "--classifier", "eq12", "--session-learning"});
  // An Eq. (12) distance bound means nothing to the session classifier's score.
  expect_usage_error({"--table", "t", "--gpio", "sim", "--line-barrier", "sim:barrier", "--line-speed", "500",
                      "--classifier", "session", "--line-max-distance", "2"});
  expect_usage_error({"--table", "t", "--gpio", "sim", "--line-barrier", "sim:barrier", "--line-speed", "500",
                      "--line-max-distance", "2"});  // (the default classifier is the session matcher)
  {
    const auto p = parse({"--table", "t", "--gpio", "sim", "--line-barrier", "sim:barrier", "--line-speed", "500",
                          "--classifier", "eq12", "--line-max-distance", "2"});
    ASSERT_TRUE(p.cl.has_value());
    EXPECT_EQ(p.cl->daemon.profile.method, tofmat::daemon::Method::kEq12);
  }
  // A learned model: onnx:FILE (the file is opened at start, not here), and its library.
  {
    const auto p = parse({"--table", "t", "--classifier", "onnx:models/m.onnx", "--onnxruntime-library", "/l.so"});
    ASSERT_TRUE(p.cl.has_value());
    EXPECT_EQ(p.cl->daemon.profile.method, tofmat::daemon::Method::kOnnx);
    EXPECT_EQ(p.cl->daemon.profile.model.path, "models/m.onnx");
    EXPECT_EQ(p.cl->daemon.profile.model.library, "/l.so");
    const auto d = parse({"--table", "t"});
    ASSERT_TRUE(d.cl.has_value());
    EXPECT_EQ(d.cl->daemon.profile.model.library, "libonnxruntime.so.1");
  }
  expect_usage_error({"--table", "t", "--classifier", "onnx:"});                 // no file
  expect_usage_error({"--table", "t", "--classifier", "onnx"});                  // no file
  expect_usage_error({"--table", "t", "--classifier", "onnx:m", "--open-set"});  // no noise model
  expect_usage_error({"--table", "t", "--gpio", "sim", "--line-barrier", "sim:barrier", "--line-speed", "500",
                      "--classifier", "onnx:m.onnx", "--line-max-distance", "2"});
  expect_usage_error({"--table", "t", "--roi", "1,2,3"});                         // three numbers
  expect_usage_error({"--table", "t", "--roi", "1;2;3;4"});                       // wrong separators
  expect_usage_error({"--table", "t", "--socket-mode", "0999"});                  // not octal
  expect_usage_error({"--table", "t", "--socket-mode", "01777"});                 // beyond 0777
  expect_usage_error({"--table", "t", "--tcp", "127.0.0.1:7020"});                // TCP without a token
  expect_usage_error({"--table", "t", "--token-file", short_token.string()});     // a token under 16 characters
  expect_usage_error({"--table", "t", "--token-file", "/nonexistent/token"});     // a token file not there
  expect_usage_error({"--config", "/nonexistent/tofmatd.toml"});                  // a config file not there
  expect_usage_error({"--table", "t", "--idle-timeout", "-1"});                   // out of range
  expect_usage_error({"--table", "t", "--max-tcp-clients", "0"});                 // out of range
  expect_usage_error({"--table", "t", "--max-clients-per-peer", "0"});            // out of range
  expect_usage_error({"--table", "t", "--peer-request-rate", "0"});               // out of range
  expect_usage_error({"--table", "t", "--peer-connect-rate", "nan"});             // not a number in range
  expect_usage_error({"--table", "t", "--control-group", "no-such-group-here"});  // no such group
  expect_usage_error({"--table", "t", "--reset-button", "sim:button"});           // a button without --gpio
  expect_usage_error({"--table", "t", "--gpio", "sim"});                          // GPIO for nothing
  expect_usage_error({"--table", "t", "--gpio", "sim", "--line-speed", "500"});   // a line without its barrier
  expect_usage_error({"--table", "t", "--gpio", "sim", "--reset-button", "sim:b", "--reset-button-bias", "up"});
  expect_usage_error({"--table", "t", "--gpio", "sim", "--reset-button", "sim:b", "--reset-button-debounce-ms", "-1"});
  std::filesystem::remove(short_token);
}

TEST(Options, AccessThatWouldOpenTheBoxIsRefused) {
  // (issue 16) Who may connect and control is never wider than asked for:
  // a socket every user may use, a token other users can read, a token
  // with nothing visible in it, a token that is not for TCP, one token for
  // both roles: each a usage error with status 2.
  namespace fs = std::filesystem;
  const auto good = token_file("good_token", "0123456789abcdef-secret\n");
  const auto readable = token_file("readable_token", "0123456789abcdef-secret\n",
                                   fs::perms::owner_read | fs::perms::owner_write | fs::perms::others_read);
  const auto blank = token_file("blank_token", " \t  \r\n0123456789abcdef-secret\n");
  const auto control_chars = token_file("control_char_token",
                                        "0123456789\x01"
                                        "abcdef-secret\n");
  const auto empty = token_file("empty_token", "");
  const std::vector<std::string> tcp = {"--table", "t", "--tcp", "127.0.0.1:7020"};
  const auto with = [&](std::vector<std::string> more) {
    std::vector<std::string> a = tcp;
    a.insert(a.end(), more.begin(), more.end());
    return a;
  };
  for (const char* mode : {"0666", "0664", "0670", "0770", "0661", "0700", "0760"}) {
    SCOPED_TRACE(mode);
    expect_usage_error({"--table", "t", "--socket-mode", mode});
  }
  for (const char* mode : {"0660", "0640", "0600", "0620"}) {
    SCOPED_TRACE(mode);
    EXPECT_TRUE(parse({"--table", "t", "--socket-mode", mode}).cl.has_value());
  }
  expect_usage_error(with({"--token-file", readable.string()}));
  expect_usage_error(with({"--token-file", blank.string()}));
  expect_usage_error(with({"--token-file", control_chars.string()}));
  expect_usage_error(with({"--token-file", empty.string()}));
  expect_usage_error(with({"--token-file", "/dev/zero"}));  // not a regular file
  expect_usage_error(
      with({"--token-file", good.string(), "--control-token-file", good.string()}));  // one token, two roles
  expect_usage_error({"--table", "t", "--token-file", good.string()});                // no TCP to use it
  expect_usage_error({"--table", "t", "--control-token-file", good.string()});
  EXPECT_TRUE(parse(with({"--token-file", good.string()})).cl.has_value());
  for (const auto& f : {good, readable, blank, control_chars, empty}) fs::remove(f);
}

}  // namespace
