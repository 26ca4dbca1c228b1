// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// FastNormal: the ziggurat tables, seeding, and the tail and wedge samples of the standard normal.
#include "tofmat/sim/gaussian.hpp"

#include <cmath>

namespace tofmat::sim {
namespace {

constexpr double kR = 3.442619855899;       // start of the tail
constexpr double kV = 9.91256303526217e-3;  // area of each layer
constexpr double kM1 = 2147483648.0;

struct Tables : ZigguratTables {
  Tables() {
    double dn = kR, tn = dn;
    const double q = kV / std::exp(-0.5 * dn * dn);
    kn[0] = static_cast<std::uint32_t>((dn / q) * kM1);
    kn[1] = 0;
    wn[0] = q / kM1;
    wn[127] = dn / kM1;
    fn[0] = 1.0;
    fn[127] = std::exp(-0.5 * dn * dn);
    for (int i = 126; i >= 1; --i) {
      dn = std::sqrt(-2.0 * std::log(kV / dn + std::exp(-0.5 * dn * dn)));
      kn[static_cast<std::size_t>(i + 1)] = static_cast<std::uint32_t>((dn / tn) * kM1);
      tn = dn;
      fn[static_cast<std::size_t>(i)] = std::exp(-0.5 * dn * dn);
      wn[static_cast<std::size_t>(i)] = dn / kM1;
    }
  }
};

const Tables& tables() {
  static const Tables t;
  return t;
}

std::uint64_t splitmix(std::uint64_t& x) {
  std::uint64_t z = (x += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

std::uint32_t abs32(std::int32_t v) {
  return v < 0 ? 0u - static_cast<std::uint32_t>(v) : static_cast<std::uint32_t>(v);
}

}  // namespace

FastNormal::FastNormal(std::uint64_t seed) : t_(&tables()) {
  for (auto& w : s_) w = splitmix(seed);
}

double FastNormal::uniform01() { return (static_cast<double>(next() >> 11) + 0.5) * (1.0 / 9007199254740992.0); }

double FastNormal::tail_or_wedge(std::int32_t hz, unsigned iz) {
  const auto& t = *t_;
  for (;;) {
    double x = hz * t.wn[iz];
    if (iz == 0) {  // the tail beyond kR, sampled exactly (Marsaglia 1964)
      double y;
      do {
        x = -std::log(uniform01()) / kR;
        y = -std::log(uniform01());
      } while (y + y < x * x);
      return hz > 0 ? kR + x : -kR - x;
    }
    if (t.fn[iz] + uniform01() * (t.fn[iz - 1] - t.fn[iz]) < std::exp(-0.5 * x * x)) return x;
    const std::uint64_t bits = next();
    hz = static_cast<std::int32_t>(static_cast<std::uint32_t>(bits >> 32));
    iz = static_cast<unsigned>(bits & 127u);
    if (abs32(hz) < t.kn[iz]) return hz * t.wn[iz];
  }
}

}  // namespace tofmat::sim
