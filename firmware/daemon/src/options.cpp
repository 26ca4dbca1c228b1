// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// tofmatd's flags and configuration file parsed with CLI11 into a CommandLine, with every value checked.
#include "tofmat/daemon/options.hpp"

#include <fcntl.h>
#include <grp.h>
#include <sys/stat.h>
#include <unistd.h>

#include <CLI/CLI.hpp>

#include <cctype>
#include <cerrno>
#include <cstdio>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <system_error>

#include "tofmat/daemon/log.hpp"
#include "tofmat/protocol/wire.hpp"

namespace tofmat::daemon {
namespace {

// The simulator's data beside the running program: <prefix>/share/tofmat/sim
// for a package (/usr/sbin/tofmatd), <package>/sim_data for the Python SDK's
// copy (tofmat/bin/tofmatd). "" when neither is there: the sim source then
// asks for --sim-data. No path of the build machine is compiled in.
std::string installed_sim_data_dir() {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (ec) return "";
  const fs::path bin = exe.parent_path();
  for (const fs::path& dir : {bin / ".." / "share" / "tofmat" / "sim", bin / ".." / "sim_data"})
    if (fs::is_directory(dir / "devices", ec)) return fs::weakly_canonical(dir, ec).string();
  return "";
}

PixelRegion parse_roi(const std::string& text) {
  PixelRegion r;
  char c1 = 0, c2 = 0, c3 = 0;
  std::istringstream in(text);
  if (!(in >> r.x0 >> c1 >> r.y0 >> c2 >> r.x1 >> c3 >> r.y1) || c1 != ',' || c2 != ',' || c3 != ',' || !in.eof())
    throw CLI::ValidationError("--roi", "expected X0,Y0,X1,Y1 (pixels), got \"" + text + "\"");
  return r;
}

// A token file: a regular file (opened without blocking: a FIFO is refused,
// not waited on) of at most kMaxTokenFileBytes that no other user may read,
// whose first line, without the blanks around it, is the token: at least 16
// characters, none of them a control character.
constexpr std::size_t kMaxTokenFileBytes = 4096;

std::string read_token(const std::string& flag, const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY);
  if (fd < 0)
    throw CLI::ValidationError(flag, "cannot read \"" + path + "\": " + std::generic_category().message(errno));
  struct stat st {};
  std::string text;
  const bool ok = ::fstat(fd, &st) == 0 && S_ISREG(st.st_mode) && st.st_size <= static_cast<off_t>(kMaxTokenFileBytes);
  if (ok) {
    text.resize(kMaxTokenFileBytes);
    const ssize_t n = ::read(fd, text.data(), text.size());
    text.resize(n > 0 ? static_cast<std::size_t>(n) : 0);
  }
  ::close(fd);
  if (!ok)
    throw CLI::ValidationError(
        flag, "\"" + path + "\" is not a regular file of at most " + std::to_string(kMaxTokenFileBytes) + " bytes");
  if ((st.st_mode & 0007) != 0)
    throw CLI::ValidationError(
        flag, "\"" + path + "\" can be read or written by other users (mode " + [&] {
          char m[8];
          std::snprintf(m, sizeof m, "%04o", static_cast<unsigned>(st.st_mode & 07777));
          return std::string(m);
        }() + "): chmod o-rwx it");
  std::string token = text.substr(0, text.find('\n'));
  const auto blank = [](char c) { return c == ' ' || c == '\t' || c == '\r'; };
  while (!token.empty() && blank(token.back())) token.pop_back();
  token.erase(0, token.find_first_not_of(" \t\r"));
  if (token.empty()) throw CLI::ValidationError(flag, "\"" + path + "\": the token's line has no visible character");
  for (const char c : token)
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f)
      throw CLI::ValidationError(flag, "\"" + path + "\": the token holds a control character");
  if (token.size() < 16) throw CLI::ValidationError(flag, "the token must be at least 16 characters");
  return token;
}

long group_id(const std::string& name) {
  std::vector<char> buf(16384);
  group gr{};
  group* found = nullptr;
  if (::getgrnam_r(name.c_str(), &gr, buf.data(), buf.size(), &found) != 0 || !found)
    throw CLI::ValidationError("--control-group", "no group \"" + name + "\" on this system");
  return static_cast<long>(found->gr_gid);
}

// The configuration file named on the command line (--config FILE or
// --config=FILE), checked before CLI11 reads it: a regular file of at most
// kMaxConfigBytes (a FIFO or /dev/zero would otherwise be read without end).
constexpr std::uintmax_t kMaxConfigBytes = 64 * 1024;

// Returns the path ("" for none).
std::string check_config_file(int argc, char** argv) {
  namespace fs = std::filesystem;
  std::string named;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    std::string path;
    if (a == "--config" && i + 1 < argc)
      path = argv[i + 1];
    else if (a.rfind("--config=", 0) == 0)
      path = a.substr(9);
    else
      continue;
    named = path;
    std::error_code ec;
    const auto st = fs::status(path, ec);
    if (ec || !fs::exists(st)) continue;  // (CLI11 says it is not readable)
    if (!fs::is_regular_file(st)) throw CLI::ValidationError("--config", "\"" + path + "\" is not a regular file");
    const auto size = fs::file_size(path, ec);
    if (ec || size > kMaxConfigBytes)
      throw CLI::ValidationError("--config", "\"" + path + "\" is larger than " +
                                                 std::to_string(kMaxConfigBytes / 1024) +
                                                 " KiB: not a tofmatd configuration");
  }
  return named;
}

// The line of the configuration file that sets the flag an error names
// ("--top-k", or the key CLI11 quotes), so the error can point at it: 0 when
// the error names no flag, the flag came from the command line, or no line
// sets it. Keys may use '-' or '_'; a TOML/INI line is `key = value`.
int config_line_of(const std::string& config_file, const std::string& error, int argc, char** argv) {
  if (config_file.empty()) return 0;
  std::vector<std::string> keys;
  for (std::size_t at = error.find("--"); at != std::string::npos; at = error.find("--", at + 2)) {
    std::size_t end = at + 2;
    while (end < error.size() && (std::isalnum(static_cast<unsigned char>(error[end])) || error[end] == '-')) ++end;
    if (end > at + 2) keys.push_back(error.substr(at + 2, end - at - 2));
  }
  for (const char quote : {'"', '\''}) {  // ("The following argument was not expected: ..." quotes none; others do)
    for (std::size_t at = error.find(quote); at != std::string::npos; at = error.find(quote, at + 1)) {
      const std::size_t end = error.find(quote, at + 1);
      if (end == std::string::npos) break;
      keys.push_back(error.substr(at + 1, end - at - 1));
      at = end;
    }
  }
  // CLI11's "INI was not able to parse KEY" (a key that is no flag), or the whole line it could not read.
  std::string unparsed;
  if (const std::size_t at = error.find("able to parse "); at != std::string::npos) {
    unparsed = error.substr(at + 14);
    keys.push_back(unparsed);
  }
  const auto norm = [](std::string k) {
    for (char& c : k) c = c == '_' ? '-' : c;
    return k;
  };
  std::ifstream in(config_file);
  std::vector<std::string> lines;
  for (std::string line; lines.size() < 10000 && std::getline(in, line);) lines.push_back(line);
  const auto trimmed = [](const std::string& t) {
    const std::size_t a = t.find_first_not_of(" \t\r"), b = t.find_last_not_of(" \t\r");
    return a == std::string::npos ? std::string() : t.substr(a, b - a + 1);
  };
  if (!unparsed.empty())
    for (std::size_t n = 0; n < lines.size(); ++n)
      if (trimmed(lines[n]) == trimmed(unparsed)) return static_cast<int>(n + 1);
  for (const std::string& raw : keys) {
    const std::string key = norm(raw);
    if (key.empty()) continue;
    bool on_command_line = false;
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      on_command_line |= a == "--" + key || a.rfind("--" + key + "=", 0) == 0;
    }
    if (on_command_line) continue;
    for (std::size_t n = 0; n < lines.size(); ++n) {
      const std::string& line = lines[n];
      const std::size_t start = line.find_first_not_of(" \t");
      const std::size_t eq = line.find('=');
      if (start == std::string::npos || eq == std::string::npos || eq <= start) continue;
      std::string k = line.substr(start, eq - start);
      while (!k.empty() && (k.back() == ' ' || k.back() == '\t')) k.pop_back();
      if (norm(k) == key) return static_cast<int>(n + 1);
    }
  }
  return 0;
}

// Prints a usage error the way CLI11 does, but with the bytes a file or an
// argument held escaped (a configuration file of garbage must not write raw
// bytes to a terminal or a journal), and, when a line of the configuration
// file set the flag it names, that file and line.
void usage_error(CLI::App& app, const std::string& what, const std::string& config_file, int argc, char** argv,
                 bool config_error) {
  std::string where;
  if (const int line = config_line_of(config_file, what, argc, argv); line > 0)
    where = "configuration file \"" + config_file + "\", line " + std::to_string(line) + ": ";
  else if (config_error)
    where = "configuration file \"" + config_file + "\": ";
  app.exit(CLI::ParseError(protocol::printable(where + what), static_cast<int>(CLI::ExitCodes::ValidationError)));
}

}  // namespace

std::optional<CommandLine> parse_command_line(int argc, char** argv, int& exit_code) {
  CommandLine cl;
  DaemonOptions& o = cl.daemon;
  o.server.socket_path = "/run/tofmat/tofmatd.sock";
  o.source_options.sim_data_dir = installed_sim_data_dir();
  std::string profile = o.profile.name, backend = "fixed", classifier = "session", roi, tcp, token_file,
              control_token_file, control_group, socket_mode = "0660";
  int idle_timeout_s = o.server.idle_timeout_ms / 1000;
  std::vector<std::string> candidates;

  CLI::App app{"tofmatd: material labels from a Time-of-Flight camera, served over a socket"};
  app.set_version_flag("--version", "tofmatd 0.1.0");
  app.set_config("--config", "", "configuration file (TOML/INI, the long flags as keys; at most 64 KiB)");
  // A key that is not a flag is an error (a misspelling would otherwise be
  // ignored and its setting silently not applied).
  app.allow_config_extras(CLI::config_extras_mode::error);
  app.add_option("--source", o.source,
                 "kinect[:SERIAL] (the camera) | sim[:SCENE[,key=value...]] | replay:FILE[,loop=0|1][,pace=0|1]")
      ->capture_default_str();
  app.add_option("--profile", profile, "handheld | segmentation | sorting")->capture_default_str();
  app.add_option("--table", o.table, "exemplar table (.tmx, or a folder of <material>.npy)")->required();
  app.add_option("--table-dir", o.table_dir,
                 "folder a client's load_table may read from (default: the folder holding --table)");
  app.add_option("--socket", o.server.socket_path, "Unix socket path (\"\" for none)")->capture_default_str();
  app.add_option("--socket-mode", socket_mode, "permissions of the Unix socket (octal, at most 0660)")
      ->capture_default_str();
  app.add_option("--control-group", control_group,
                 "Unix clients in this group may control (profile, ROI, candidates, trigger, reset, load_table); "
                 "the daemon's user and root always may, everyone else reads only");
  app.add_option("--tcp", tcp, "also listen on HOST:PORT (needs --token-file; use 127.0.0.1 unless you mean it)");
  app.add_option("--token-file", token_file,
                 "file (mode 0600 or 0640) whose first line is the TCP clients' shared secret: it reads only");
  app.add_option("--control-token-file", control_token_file,
                 "file whose first line is the TCP secret that also controls (default: no TCP client controls)");
  app.add_option("--max-tcp-clients", o.server.max_tcp_clients, "TCP connections at once")
      ->capture_default_str()
      ->check(CLI::Range(1, 1024));
  app.add_option("--max-clients-per-peer", o.server.max_clients_per_peer,
                 "connections at once from one user (Unix) or address (TCP)")
      ->capture_default_str()
      ->check(CLI::Range(1, 1024));
  // (CLI::Range lets NaN through: a rate is a number from 1 to 1e6, NaN is not.)
  const CLI::Validator rate(
      [](std::string& text) {
        double v = 0;
        return CLI::detail::lexical_cast(text, v) && v >= 1.0 && v <= 1e6 ? std::string()
                                                                          : "must be a number from 1 to 1000000";
      },
      "RATE in [1 - 1000000]");
  app.add_option("--peer-request-rate", o.server.peer_request_rate,
                 "requests a second one user (Unix) or address (TCP) may send, and as many at once; more wait")
      ->capture_default_str()
      ->check(rate);
  app.add_option("--peer-connect-rate", o.server.peer_connect_rate,
                 "new connections a second from one user or address, and twice as many at once; more are refused")
      ->capture_default_str()
      ->check(rate);
  app.add_option("--idle-timeout", idle_timeout_s,
                 "seconds after which a client that neither asks nor subscribes, or takes nothing it is sent, is "
                 "closed (0: never)")
      ->capture_default_str()
      ->check(CLI::Range(0, 86400));
  app.add_option("--backend", backend, "fixed (integer path, NEON on aarch64) | float (reference)")
      ->capture_default_str();
  app.add_option("--classifier", classifier,
                 "eq12 (the paper's Eq. (12)) | session (the session-robust matcher, docs/evaluation.md) | onnx:FILE "
                 "(a learned model, tofmat train; docs/learned-models.md): how the handheld and sorting profiles "
                 "match a query")
      ->capture_default_str()
      ->check(CLI::Validator(
          [](std::string& text) {
            if (text == "eq12" || text == "session") return std::string();
            if (text.rfind("onnx:", 0) == 0 && text.size() > 5) return std::string();
            return std::string("must be eq12, session or onnx:FILE");
          },
          "eq12|session|onnx:FILE"));
  app.add_option("--onnxruntime-library", o.profile.model.library,
                 "the onnxruntime shared library for --classifier onnx:FILE (a path, or a name the loader finds)")
      ->capture_default_str();
  app.add_flag("--open-set", o.profile.open_set,
               "label a sweep no material explains 'unknown' (--classifier session; docs/evaluation.md)");
  CLI::Option* learning =
      app.add_flag("--session-learning,!--no-session-learning", o.profile.session_learning,
                   "the session matcher learns how far this capture session moved from the sweeps it has labelled "
                   "(the default with --classifier session; docs/evaluation.md); --no-session-learning: each "
                   "sweep on its own under the calibration's spread")
          ->capture_default_str();
  app.add_option("--roi", roi, "region of interest X0,Y0,X1,Y1 (default: 48 x 48 at the centre)");
  app.add_option("--candidates", candidates, "candidate materials (default: all in the table)")->delimiter(',');
  // (the ranges profile.cpp's check_config enforces, checked here so they are usage errors: status 2)
  app.add_option("--top-k", o.profile.top_k, "ranking entries per label event")
      ->capture_default_str()
      ->check(CLI::Range(1, 64));
  app.add_option("--burst", o.profile.burst, "sorting: frames per trigger")
      ->capture_default_str()
      ->check(CLI::Range(1, 300));
  app.add_option("--smooth", o.profile.smooth, "segmentation: window side (odd pixels)")
      ->capture_default_str()
      ->check(CLI::Validator(
          [](std::string& text) {
            int v = 0;
            return CLI::detail::lexical_cast(text, v) && v >= 1 && v <= 15 && v % 2 == 1
                       ? std::string()
                       : std::string("must be an odd number from 1 to 15");
          },
          "ODD in [1 - 15]"));
  app.add_option("--accumulate", o.profile.accumulate,
                 "segmentation: frames each pixel's features are averaged over, starting over where its depth "
                 "jumps (1: each frame on its own)")
      ->capture_default_str()
      ->check(CLI::Range(1, 256));
  app.add_flag_callback(
      "--no-region-vote", [&o] { o.profile.region_vote = false; },
      "segmentation: leave out the region vote (each surface of steady depth taking its majority label)");
  app.add_option("--threads", o.profile.threads, "segmentation: threads sharing each frame (0: every core)")
      ->capture_default_str()
      ->check(CLI::Range(0, 64));
  app.add_option("--queue-frames", o.queue_frames, "frames waiting for processing before the oldest is dropped")
      ->capture_default_str()
      ->check(CLI::Range(1, 64));
  app.add_option("--max-clients", o.server.max_clients, "Unix connections at once")
      ->capture_default_str()
      ->check(CLI::Range(1, 1024));
  app.add_option("--sim-data", o.source_options.sim_data_dir,
                 "simulator device profiles and material libraries (default: installed beside tofmatd)")
      ->capture_default_str();
  // The sorting line (issue 17; docs/sorting-line.md).
  LineOptions& line = o.line;
  const CLI::Validator non_negative(
      [](std::string& text) {
        double v = 0;
        return CLI::detail::lexical_cast(text, v) && v >= 0.0 && v <= 1e9 ? std::string()
                                                                          : "must be a number from 0 to 1e9";
      },
      "NUMBER in [0 - 1e9]");
  app.add_option("--gpio", line.gpio,
                 "GPIO of the sorting line and the reset button: libgpiod (the board's chips) | sim (a simulated "
                 "chip); none by default")
      ->check(CLI::IsMember({"libgpiod", "sim"}));
  app.add_option("--line-barrier", line.barrier, "the light barrier's input, CHIP:LINE (chip label or /dev path)");
  app.add_flag("--line-barrier-active-low", line.barrier_active_low,
               "the barrier's line is low while the beam is interrupted");
  app.add_option("--line-barrier-bias", line.barrier_bias, "as-is | disabled | pull-up | pull-down")
      ->capture_default_str()
      ->check(CLI::IsMember({"as-is", "disabled", "pull-up", "pull-down"}));
  app.add_option("--line-debounce-ms", line.debounce_ms, "an edge of the barrier counts when held this long")
      ->capture_default_str()
      ->check(non_negative);
  app.add_option("--line-min-gap-ms", line.min_gap_ms,
                 "items closer together than this are reported and rejected, never merged")
      ->capture_default_str()
      ->check(non_negative);
  app.add_option("--line-speed", line.speed_mm_s, "a belt of fixed speed, mm/s (or an encoder)")->check(non_negative);
  app.add_option("--line-encoder-a", line.encoder_a, "the belt encoder's channel A, CHIP:LINE");
  app.add_option("--line-encoder-b", line.encoder_b, "the belt encoder's channel B, CHIP:LINE");
  app.add_option("--line-encoder-counts-per-mm", line.encoder_counts_per_mm,
                 "encoder counts per mm of belt: 4 x pulses per turn / (pi x pulley diameter)")
      ->check(non_negative);
  app.add_option("--line-camera-mm", line.camera_mm, "from the barrier to the camera's ROI along the belt, mm")
      ->capture_default_str()
      ->check(non_negative);
  app.add_option("--outlet", line.outlets,
                 "an outlet, NAME:position=MM,line=CHIP:LINE[,materials=a+b][,pulse=MS][,active_low=1] (repeat "
                 "for each; position from the barrier)");
  app.add_option("--line-reject", line.reject,
                 "the outlet that takes rejects (default: none, they ride to the belt's end)");
  app.add_option("--line-alarm", line.alarm,
                 "an alarm output, CHIP:LINE: on while the camera is lost or labels come late");
  app.add_option("--line-margin-ms", line.margin_ms, "a label must come this long before its outlet fires")
      ->capture_default_str()
      ->check(non_negative);
  app.add_option("--line-alarm-hold-ms", line.alarm_hold_ms, "a late label keeps the alarm on this long")
      ->capture_default_str()
      ->check(non_negative);
  app.add_option("--line-max-distance", line.max_distance,
                 "a burst's label is confident when its Eq. (12) distance is at most this (mm^2; 0: any; over 0 "
                 "needs --classifier eq12)")
      ->capture_default_str()
      ->check(non_negative);
  auto& button = o.button;
  app.add_option("--reset-button", button.line,
                 "the front panel's button, CHIP:LINE: a press resets the accumulation (as the reset command)");
  app.add_flag("--reset-button-active-low", button.active_low, "the button's line is low while it is pressed");
  app.add_option("--reset-button-bias", button.bias, "as-is | disabled | pull-up | pull-down")
      ->capture_default_str()
      ->check(CLI::IsMember({"as-is", "disabled", "pull-up", "pull-down"}));
  app.add_option("--reset-button-debounce-ms", button.debounce_ms, "a press counts when held this long")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1000.0));
  app.add_option("--log-level", cl.log_level,
                 "LEVEL for every category, or CATEGORY=LEVEL,...[,*=LEVEL]: levels trace | debug | info | warn | "
                 "error; categories daemon, kinect, server, pipeline, profile, gpio, line")
      ->capture_default_str()
      ->check(
          [](const std::string& text) {
            try {
              parse_log_levels(text);
              return std::string();
            } catch (const std::invalid_argument& e) {
              return std::string(e.what());
            }
          },
          "LEVEL or CATEGORY=LEVEL,...");
  std::string config_file;
  try {
    config_file = check_config_file(argc, argv);
    app.parse(argc, argv);
    o.profile.name = profile;
    o.profile.backend = parse_backend(backend);
    o.profile.method = parse_method(classifier);
    if (o.profile.method == Method::kOnnx) {
      o.profile.model.path = classifier.substr(5);
      if (!tofmat::learn::onnxruntime_built())
        throw CLI::ValidationError("--classifier", tofmat::learn::unavailable_reason());
    }
    if (o.profile.method != Method::kEq12 && line.max_distance > 0)
      throw CLI::ValidationError("--line-max-distance",
                                 "it bounds an Eq. (12) distance (mm^2), so it needs --classifier eq12 (the "
                                 "default classifier is session, whose scores are no distance; so are a learned "
                                 "model's)");
    // (on by default: it is the session matcher's, so another classifier leaves it out unless asked for)
    if (o.profile.method != Method::kSession) {
      if (learning->count() > 0 && o.profile.session_learning)
        throw CLI::ValidationError("--session-learning",
                                   "learns the session matcher's session: it needs --classifier session");
      o.profile.session_learning = false;
    }
    if (o.profile.open_set && o.profile.method != Method::kSession)
      throw CLI::ValidationError("--open-set",
                                 "needs --classifier session: Eq. (12) has no noise model to judge a fit");
    o.profile.candidates = candidates;
    if (!roi.empty()) o.profile.roi = parse_roi(roi);
    const bool line_options = !line.barrier.empty() || !line.outlets.empty() || line.speed_mm_s > 0 ||
                              !line.encoder_a.empty() || !line.encoder_b.empty() || !line.alarm.empty() ||
                              !line.reject.empty();
    if (line.gpio.empty() && (line_options || button.enabled()))
      throw CLI::ValidationError("--gpio",
                                 "the sorting line's and the reset button's options need --gpio libgpiod (or sim)");
    if (!line.gpio.empty() && !line_options && !button.enabled())
      throw CLI::ValidationError("--gpio",
                                 "--gpio drives a sorting line (--line-barrier ...) or a reset button "
                                 "(--reset-button): give one of them");
    if (line_options && line.barrier.empty())
      throw CLI::ValidationError("--line-barrier", "the sorting line needs its light barrier, CHIP:LINE");
    o.server.tcp = tcp;
    if (tcp.empty() && !token_file.empty())
      throw CLI::ValidationError("--token-file", "a token is for TCP clients: give --tcp too, or leave the token out");
    if (tcp.empty() && !control_token_file.empty())
      throw CLI::ValidationError("--control-token-file", "a token is for TCP clients: give --tcp too");
    if (!tcp.empty() && token_file.empty()) throw CLI::ValidationError("--tcp", "TCP needs --token-file");
    if (!token_file.empty()) o.server.token = read_token("--token-file", token_file);
    if (!control_token_file.empty()) {
      o.server.control_token = read_token("--control-token-file", control_token_file);
      if (o.server.control_token == o.server.token)
        throw CLI::ValidationError("--control-token-file", "the control token must differ from --token-file's");
    }
    if (!control_group.empty()) o.server.control_gid = group_id(control_group);
    o.server.idle_timeout_ms = idle_timeout_s * 1000;
    std::size_t used = 0;
    const unsigned long mode = socket_mode.empty() ? 01000 : std::stoul(socket_mode, &used, 8);
    if (used != socket_mode.size() || mode > 0777)
      throw CLI::ValidationError("--socket-mode", "expected octal like 0660");
    // Anyone who can connect may read the labels: that is the group's
    // business, never every user's (and nobody executes a socket).
    if ((mode & ~0660ul) != 0)
      throw CLI::ValidationError("--socket-mode",
                                 "\"" + socket_mode + "\" is wider than 0660: give access through the socket's group");
    o.server.socket_mode = static_cast<unsigned>(mode);
  } catch (const CLI::ParseError& e) {
    // --help and --version are CLI11's "errors" with status 0; every other is
    // a usage error: status 2 (CLI11's own codes are 100 and up).
    if (e.get_exit_code() == 0) {
      exit_code = app.exit(e);
      return std::nullopt;
    }
    exit_code = 2;
    usage_error(app, e.what(), config_file, argc, argv, dynamic_cast<const CLI::ConfigError*>(&e) != nullptr);
    return std::nullopt;
  } catch (const std::exception& e) {
    exit_code = 2;
    usage_error(app, e.what(), config_file, argc, argv, false);
    return std::nullopt;
  }
  return cl;
}

}  // namespace tofmat::daemon
