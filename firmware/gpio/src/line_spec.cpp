// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Parsing of CHIP:LINE specs and of line bias names.
#include <algorithm>
#include <cctype>

#include "tofmat/gpio/gpio.hpp"

namespace tofmat::gpio {
namespace {

bool all_digits(const std::string& s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), [](unsigned char c) { return std::isdigit(c) != 0; });
}

}  // namespace

LineSpec LineSpec::parse(const std::string& text) {
  // (The last colon: a line name never holds one, a chip label might.)
  const auto colon = text.rfind(':');
  if (colon == std::string::npos || colon == 0 || colon + 1 == text.size())
    throw std::invalid_argument("GPIO line \"" + text +
                                "\": expected CHIP:LINE (a chip label or /dev path, then a line name or offset), "
                                "e.g. pinctrl-rp1:GPIO17");
  LineSpec s{text.substr(0, colon), text.substr(colon + 1)};
  const bool numbered = all_digits(s.chip) ||
                        (s.chip.rfind("gpiochip", 0) == 0 && all_digits(s.chip.substr(std::string("gpiochip").size())));
  if (numbered)
    throw std::invalid_argument("GPIO line \"" + text + "\": \"" + s.chip +
                                "\" is a chip number, which changes between kernels; name the chip by its label "
                                "(gpiodetect shows it) or by its /dev path");
  for (const char c : text)
    if (std::iscntrl(static_cast<unsigned char>(c)) || c == ' ')
      throw std::invalid_argument("GPIO line \"" + text + "\": no spaces or control characters");
  return s;
}

bool LineSpec::is_offset() const { return all_digits(line); }

Bias parse_bias(const std::string& name) {
  if (name == "as-is") return Bias::kAsIs;
  if (name == "disabled") return Bias::kDisabled;
  if (name == "pull-up") return Bias::kPullUp;
  if (name == "pull-down") return Bias::kPullDown;
  throw std::invalid_argument("GPIO bias \"" + name + "\": one of as-is, disabled, pull-up, pull-down");
}

const char* bias_name(Bias b) {
  switch (b) {
    case Bias::kAsIs: return "as-is";
    case Bias::kDisabled: return "disabled";
    case Bias::kPullUp: return "pull-up";
    case Bias::kPullDown: return "pull-down";
  }
  return "?";
}

}  // namespace tofmat::gpio
