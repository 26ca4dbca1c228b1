// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The fixed-point path against the float reference at its stiff and extreme
// cases, one case at a time: near-zero amplitude, saturation, the largest
// sample magnitudes, the wrap points, the ends of each frequency's range,
// materials of tiny and huge subsurface delay tau, a depth bin holding one
// observation and one holding many, and the box mean's widest window at the
// decode's extremes and with one valid element. Each row is the worst error
// of one quantity of one stage next to the budget docs/numerics.md states.
// test_stiff_cases asserts every row is within it; `tofmat_bench_fixed --op
// stiff` prints the rows for `tofmat report`. (The Eq. (12) classifier's
// stiff cases, one valid element and the largest tables, are computed in
// Python by the report: the SDK binds it.)
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "tofmat/core/frame_decode.hpp"

namespace tofmat_test {

struct StiffRow {
  std::string stage;     // the fixed-point stage (its function or class)
  std::string scenario;  // the stiff case
  std::string inputs;    // what was computed
  std::size_t compared;  // pixels, bins or windows the worst is taken over
  std::string quantity;  // with its unit
  double worst;          // the largest error found
  double budget;         // docs/numerics.md
  bool within() const { return worst <= budget; }
};

// Every case; `pixels` per decode case (the test uses fewer than the bench).
std::vector<StiffRow> stiff_cases(std::size_t pixels);

// The rows as a Markdown table under the heading "Stiff cases".
std::string stiff_cases_markdown(const std::vector<StiffRow>& rows);

// Where the float and fixed decodes flag pixel i differently, whether the
// pixel sits on a threshold's edge (an amplitude rule within 0.01 count, an
// unwrap gap within 0.01 mm of its limit: DecodeOptions' defaults) or at
// the 16 MHz wrap point (0 = 9375 mm, where either side is a right answer):
// the only places docs/numerics.md allows the flags to differ.
bool flag_difference_allowed(const tofmat::DecodedFrame& f, std::size_t i);

}  // namespace tofmat_test
