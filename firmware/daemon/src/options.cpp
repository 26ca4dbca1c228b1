#include "tofmat/daemon/options.hpp"

#include <CLI/CLI.hpp>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <system_error>

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

std::string read_token(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw CLI::ValidationError("--token-file", "cannot read \"" + path + "\"");
  std::string token;
  std::getline(in, token);
  while (!token.empty() && (token.back() == '\r' || token.back() == ' ')) token.pop_back();
  if (token.size() < 16) throw CLI::ValidationError("--token-file", "the token must be at least 16 characters");
  return token;
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
    if (a == "--config" && i + 1 < argc) path = argv[i + 1];
    else if (a.rfind("--config=", 0) == 0) path = a.substr(9);
    else continue;
    named = path;
    std::error_code ec;
    const auto st = fs::status(path, ec);
    if (ec || !fs::exists(st)) continue;  // (CLI11 says it is not readable)
    if (!fs::is_regular_file(st)) throw CLI::ValidationError("--config", "\"" + path + "\" is not a regular file");
    const auto size = fs::file_size(path, ec);
    if (ec || size > kMaxConfigBytes)
      throw CLI::ValidationError("--config", "\"" + path + "\" is larger than " + std::to_string(kMaxConfigBytes / 1024) +
                                                 " KiB: not a tofmatd configuration");
  }
  return named;
}

}  // namespace

std::optional<CommandLine> parse_command_line(int argc, char** argv, int& exit_code) {
  CommandLine cl;
  DaemonOptions& o = cl.daemon;
  o.server.socket_path = "/run/tofmat/tofmatd.sock";
  o.source_options.sim_data_dir = installed_sim_data_dir();
  std::string profile = o.profile.name, backend = "fixed", roi, tcp, token_file, socket_mode = "0660";
  std::vector<std::string> candidates;

  CLI::App app{"tofmatd: material labels from a Time-of-Flight camera, served over a socket"};
  app.set_version_flag("--version", "tofmatd 0.1.0");
  app.set_config("--config", "", "configuration file (TOML/INI, the long flags as keys; at most 64 KiB)");
  // A key that is not a flag is an error (a misspelling would otherwise be
  // ignored and its setting silently not applied).
  app.allow_config_extras(CLI::config_extras_mode::error);
  app.add_option("--source", o.source, "kinect[:SERIAL] (the camera) | sim[:SCENE[,key=value...]] | replay:FILE[,loop=0|1][,pace=0|1]")
      ->capture_default_str();
  app.add_option("--profile", profile, "handheld | segmentation | sorting")->capture_default_str();
  app.add_option("--table", o.table, "exemplar table (.tmx, or a folder of <material>.npy)")->required();
  app.add_option("--table-dir", o.table_dir,
                 "folder a client's load_table may read from (default: the folder holding --table)");
  app.add_option("--socket", o.server.socket_path, "Unix socket path (\"\" for none)")->capture_default_str();
  app.add_option("--socket-mode", socket_mode, "permissions of the Unix socket (octal)")->capture_default_str();
  app.add_option("--tcp", tcp, "also listen on HOST:PORT (needs --token-file; use 127.0.0.1 unless you mean it)");
  app.add_option("--token-file", token_file, "file whose first line is the TCP clients' shared secret");
  app.add_option("--backend", backend, "fixed (integer path, NEON on aarch64) | float (reference)")
      ->capture_default_str();
  app.add_option("--roi", roi, "region of interest X0,Y0,X1,Y1 (default: 48 x 48 at the centre)");
  app.add_option("--candidates", candidates, "candidate materials (default: all in the table)")->delimiter(',');
  app.add_option("--top-k", o.profile.top_k, "ranking entries per label event")->capture_default_str();
  app.add_option("--burst", o.profile.burst, "sorting: frames per trigger")->capture_default_str();
  app.add_option("--smooth", o.profile.smooth, "segmentation: window side (odd pixels)")->capture_default_str();
  app.add_option("--threads", o.profile.threads, "segmentation: threads sharing each frame (0: every core)")
      ->capture_default_str()
      ->check(CLI::Range(0, 64));
  app.add_option("--queue-frames", o.queue_frames, "frames waiting for processing before the oldest is dropped")
      ->capture_default_str()
      ->check(CLI::Range(1, 64));
  app.add_option("--max-clients", o.server.max_clients, "connections at once")->capture_default_str()->check(CLI::Range(1, 1024));
  app.add_option("--sim-data", o.source_options.sim_data_dir,
                 "simulator device profiles and material libraries (default: installed beside tofmatd)")
      ->capture_default_str();
  app.add_option("--log-level", cl.log_level, "trace | debug | info | warn | error")
      ->capture_default_str()
      ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error"}));
  std::string config_file;
  try {
    config_file = check_config_file(argc, argv);
    app.parse(argc, argv);
    o.profile.name = profile;
    o.profile.backend = parse_backend(backend);
    o.profile.candidates = candidates;
    if (!roi.empty()) o.profile.roi = parse_roi(roi);
    o.server.tcp = tcp;
    if (!token_file.empty()) o.server.token = read_token(token_file);
    if (!tcp.empty() && token_file.empty()) throw CLI::ValidationError("--tcp", "TCP needs --token-file");
    std::size_t used = 0;
    const unsigned long mode = std::stoul(socket_mode, &used, 8);
    if (used != socket_mode.size() || mode > 0777) throw CLI::ValidationError("--socket-mode", "expected octal like 0660");
    o.server.socket_mode = static_cast<unsigned>(mode);
  } catch (const CLI::ConfigError& e) {
    // (CLI11's text names the key, not the file: say which file.)
    app.exit(CLI::ConfigError("configuration file \"" + config_file + "\": " + e.what()));
    exit_code = 2;
    return std::nullopt;
  } catch (const CLI::ParseError& e) {
    // --help and --version are CLI11's "errors" with status 0; every other is
    // a usage error: status 2 (CLI11's own codes are 100 and up).
    exit_code = app.exit(e) == 0 ? 0 : 2;
    return std::nullopt;
  } catch (const std::exception& e) {
    app.exit(CLI::ValidationError(e.what()));
    exit_code = 2;
    return std::nullopt;
  }
  return cl;
}

}  // namespace tofmat::daemon
