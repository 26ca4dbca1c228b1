// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// A depth-bin specification: `count` bins of `width_mm`, the first starting at
// `start_mm`. Bin j covers [start + j*width, start + (j+1)*width). It travels
// with every table as data; nothing assumes the real database's 600 mm / 200.
#pragma once

#include <cstdint>

namespace tofmat {

inline constexpr std::uint32_t kMaxBins = 65535;

struct BinSpec {
  double start_mm = 0.0;
  double width_mm = 1.0;
  std::uint32_t count = 1;

  // Bins whose left edges are np.linspace(start, stop, count), the way the
  // authors re-binned their captures: width = (stop - start) / (count - 1).
  static BinSpec linspace(double start_mm, double stop_mm, std::uint32_t count);

  // Throws std::invalid_argument unless start and width are finite, width > 0
  // and 1 <= count <= kMaxBins.
  void validate() const;

  // Index of the bin holding depth_mm, or -1 when it is outside every bin or not finite.
  std::int32_t index_of(double depth_mm) const;

  double lower_edge_mm(std::uint32_t j) const { return start_mm + width_mm * j; }
  double centre_mm(std::uint32_t j) const { return start_mm + width_mm * (j + 0.5); }
  double end_mm() const { return start_mm + width_mm * count; }

  bool operator==(const BinSpec& o) const {
    return start_mm == o.start_mm && width_mm == o.width_mm && count == o.count;
  }
};

}  // namespace tofmat
