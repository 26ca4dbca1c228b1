// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// tofmatd's command line and configuration file (CLI11: the file is TOML or
// INI with the same keys as the long flags, e.g. `profile = "handheld"`).
// Flags given on the command line win over the file.
#pragma once
#include <optional>
#include <string>
#include <vector>

#include "tofmat/daemon/daemon.hpp"

namespace tofmat::daemon {

struct CommandLine {
  DaemonOptions daemon;
  std::string log_level = "info";
};

// Parses argv. Returns nothing when the program should exit with `exit_code`:
// 0 after --help or --version, 2 after a usage error (already printed to stderr).
std::optional<CommandLine> parse_command_line(int argc, char** argv, int& exit_code);

}  // namespace tofmat::daemon
