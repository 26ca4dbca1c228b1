// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// BinSpec: bins spread over a depth range, their validation, and the bin index of a depth.
#include "tofmat/core/bin_spec.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

namespace tofmat {

BinSpec BinSpec::linspace(double start_mm, double stop_mm, std::uint32_t count) {
  if (count < 2) throw std::invalid_argument("BinSpec::linspace needs at least 2 bins");
  BinSpec s{start_mm, (stop_mm - start_mm) / static_cast<double>(count - 1), count};
  s.validate();
  return s;
}

void BinSpec::validate() const {
  if (!std::isfinite(start_mm) || !std::isfinite(width_mm) || !(width_mm > 0.0)) {
    throw std::invalid_argument("bin spec needs a finite start and a finite width > 0 (got start " +
                                std::to_string(start_mm) + " mm, width " + std::to_string(width_mm) + " mm)");
  }
  if (count < 1 || count > kMaxBins) {
    throw std::invalid_argument("bin count " + std::to_string(count) + " is outside 1.." + std::to_string(kMaxBins));
  }
  if (!std::isfinite(end_mm())) throw std::invalid_argument("bin spec end is not finite");
}

std::int32_t BinSpec::index_of(double depth_mm) const {
  if (!std::isfinite(depth_mm)) return -1;
  const double q = std::floor((depth_mm - start_mm) / width_mm);
  if (!(q >= -1.0) || q > static_cast<double>(count)) return -1;  // far outside; also keeps the cast defined
  auto j = static_cast<std::int64_t>(q);
  // The division can round across an edge: settle on the edges exactly as
  // lower_edge_mm() computes them, so bin j is [lower_edge(j), lower_edge(j+1)).
  if (j >= 0 && depth_mm < lower_edge_mm(static_cast<std::uint32_t>(j))) {
    --j;
  } else if (depth_mm >= lower_edge_mm(static_cast<std::uint32_t>(j + 1))) {
    ++j;
  }
  return j >= 0 && j < static_cast<std::int64_t>(count) ? static_cast<std::int32_t>(j) : -1;
}

}  // namespace tofmat
