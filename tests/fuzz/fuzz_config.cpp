// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// libFuzzer target: tofmatd's configuration file (--config FILE, CLI11's
// TOML/INI reader behind parse_command_line). Each input is written to a
// file and parsed as the daemon would at start: any input ends in options or
// a usage error, never a crash, a hang or unbounded memory. The sorting
// line's and the reset button's values and the simulated source's spec are
// parsed further at start (outlets, GPIO line names, bias, sim keys): those
// parsers take what the file gave them here too.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <iostream>
#include <string>

#include "tofmat/daemon/options.hpp"
#include "tofmat/daemon/sim_source.hpp"
#include "tofmat/daemon/sorting_line.hpp"
#include "tofmat/gpio/gpio.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::string path = "/tmp/tofmat_fuzz_config_" + std::to_string(::getpid()) + ".toml";
  static const bool quiet = [] {
    std::cerr.setstate(std::ios::badbit);  // (usage errors would print one line per input)
    std::cout.setstate(std::ios::badbit);
    return true;
  }();
  (void)quiet;
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) return 0;
  std::fwrite(data, 1, size, f);
  std::fclose(f);
  std::string a0 = "tofmatd", a1 = "--config", a2 = path;
  char* argv[] = {a0.data(), a1.data(), a2.data(), nullptr};
  int exit_code = 0;
  const auto cl = tofmat::daemon::parse_command_line(3, argv, exit_code);
  if (!cl && exit_code != 0 && exit_code != 2) __builtin_trap();  // only options, --help/--version or a usage error
  if (!cl) return 0;
  const auto& line = cl->daemon.line;
  for (const auto& text : line.outlets) {
    try {
      tofmat::daemon::parse_outlet(text);
    } catch (const std::invalid_argument&) {
    }
  }
  const auto& button = cl->daemon.button;
  for (const auto* text : {&line.barrier, &line.encoder_a, &line.encoder_b, &line.alarm, &button.line}) {
    try {
      tofmat::gpio::LineSpec::parse(*text);
    } catch (const std::invalid_argument&) {
    }
  }
  for (const auto* bias : {&line.barrier_bias, &button.bias}) {
    try {
      tofmat::gpio::parse_bias(*bias);
    } catch (const std::invalid_argument&) {
    }
  }
  const std::string& source = cl->daemon.source;
  const auto colon = source.find(':');
  if (source.substr(0, colon) == "sim") {  // (as make_source splits it)
    try {
      tofmat::daemon::parse_sim_spec(colon == std::string::npos ? "" : source.substr(colon + 1));
    } catch (const std::invalid_argument&) {
    }
  }
  return 0;
}
