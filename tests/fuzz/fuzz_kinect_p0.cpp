// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// libFuzzer target: the P0 tables parser's accepting path. A response is
// 1,302,572 bytes, far beyond the inputs libFuzzer grows from small seeds, so
// the input is written over a well-formed response (zero tables) at an offset
// its first three bytes pick: headers, pads and table values all get mutated.
// Acceptable outcomes: three 512 x 424 tables, or tofmat::FormatError.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

#include "tofmat/core/error.hpp"
#include "tofmat/kinect/command.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tofmat::kinect;
  static const std::vector<std::uint8_t> base = [] {
    P0Tables t;
    for (auto& tab : t.raw) tab.assign(512u * 424u, 0);
    return encode_p0_tables(t);
  }();
  static std::vector<std::uint8_t> buf = base;  // written over, then restored: no 1.3 MB copy per input
  if (size < 3) return 0;
  const std::size_t at = (std::size_t{data[0]} | std::size_t{data[1]} << 8 | std::size_t{data[2]} << 16) % buf.size();
  const std::size_t len = std::min(size - 3, buf.size() - at);
  std::memcpy(buf.data() + at, data + 3, len);
  // The whole response, and cut short where the input ends (a truncated read).
  for (const std::size_t n : {buf.size(), at + len}) {
    try {
      const auto t = parse_p0_tables(buf.data(), n);
      for (const auto& tab : t.raw) {
        if (tab.size() != 512u * 424u) __builtin_trap();
      }
    } catch (const tofmat::FormatError&) {
    }
  }
  std::memcpy(buf.data() + at, base.data() + at, len);
  return 0;
}
