// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Internal: the small text parsers of tofmatd's source and outlet specs, and ms to ns
// ("sim:belt,speed=500,...", "wood:position=600,materials=a+b,...").
#pragma once
#include <cmath>
#include <cstdint>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

namespace tofmat::daemon {

// `s` cut at every `sep` (empty parts kept: the caller says what they mean).
inline std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::stringstream in(s);
  std::string part;
  while (std::getline(in, part, sep)) out.push_back(part);
  return out;
}

// The finite number that is the whole of `text`, or nothing.
inline std::optional<double> whole_number(const std::string& text) {
  try {
    std::size_t used = 0;
    const double v = std::stod(text, &used);
    if (used == text.size() && std::isfinite(v)) return v;
  } catch (const std::exception&) {
  }
  return std::nullopt;
}

// A configured time in ms (checked finite and >= 0 by the caller) in ns.
inline std::uint64_t ms_to_ns(double ms) { return static_cast<std::uint64_t>(std::llround(ms * 1e6)); }

}  // namespace tofmat::daemon
