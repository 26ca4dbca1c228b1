// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Fast standard-normal samples for sensor noise: xoshiro256+ uniform bits and
// the ziggurat method (Marsaglia and Tsang, 2000, 128 layers), with the layer
// index and the magnitude taken from separate bits (Doornik, 2005). A full
// frame needs two million samples; std::normal_distribution takes ~25 ns each
// here, this a few ns. Exactly Gaussian (the tail is sampled exactly).
#pragma once

#include <array>
#include <cstdint>

namespace tofmat::sim {

struct ZigguratTables {
  std::array<std::uint32_t, 128> kn{};
  std::array<double, 128> wn{}, fn{};
};

class FastNormal {
 public:
  explicit FastNormal(std::uint64_t seed);

  double operator()() {
    const std::uint64_t bits = next();
    const auto hz = static_cast<std::int32_t>(static_cast<std::uint32_t>(bits >> 32));
    const auto iz = static_cast<unsigned>(bits & 127u);
    const std::uint32_t mag = hz < 0 ? 0u - static_cast<std::uint32_t>(hz) : static_cast<std::uint32_t>(hz);
    if (mag < t_->kn[iz]) return hz * t_->wn[iz];  // inside a layer: ~99 % of calls
    return tail_or_wedge(hz, iz);
  }

 private:
  std::uint64_t next() {  // xoshiro256+
    const std::uint64_t result = s_[0] + s_[3];
    const std::uint64_t t = s_[1] << 17;
    s_[2] ^= s_[0];
    s_[3] ^= s_[1];
    s_[1] ^= s_[2];
    s_[0] ^= s_[3];
    s_[2] ^= t;
    s_[3] = (s_[3] << 45) | (s_[3] >> 19);
    return result;
  }
  double uniform01();  // (0, 1)
  double tail_or_wedge(std::int32_t hz, unsigned iz);

  std::array<std::uint64_t, 4> s_{};
  const ZigguratTables* t_;
};

}  // namespace tofmat::sim
