// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// libFuzzer target: the command protocol's parsers (command, completion,
// firmware versions, serial, depth parameters, P0 tables, status) on
// arbitrary bytes. The first byte picks the parser. The only acceptable
// outcomes are a value within the documented limits or tofmat::FormatError.
// The P0 parser's accepting path needs 1.3 MB: fuzz_kinect_p0 reaches it.
#include <cstddef>
#include <cstdint>

#include "tofmat/core/error.hpp"
#include "tofmat/kinect/command.hpp"

namespace {

void check_p0(const tofmat::kinect::P0Tables& t) {
  for (const auto& tab : t.raw) {
    if (tab.size() != 512u * 424u) __builtin_trap();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tofmat::kinect;
  if (size < 1) return 0;
  const std::uint8_t which = data[0] % 7;
  const std::uint8_t* p = data + 1;
  const std::size_t n = size - 1;
  try {
    switch (which) {
      case 0: {
        const auto c = decode_command(p, n);
        if (c.params.size() > kMaxCommandParams) __builtin_trap();
        break;
      }
      case 1: parse_completion(p, n); break;
      case 2: {
        const auto v = parse_firmware_versions(p, n);
        if (v.empty() || v.size() > 7 || v.size() * 16 > n) __builtin_trap();
        break;
      }
      case 3: {
        const auto s = parse_serial(p, n);
        if (s.empty() || s.size() > (n + 1) / 2) __builtin_trap();
        break;
      }
      case 4: parse_depth_params(p, n); break;
      case 5:  // (its accepting path: fuzz_kinect_p0)
        check_p0(parse_p0_tables(p, n));
        break;
      default: parse_status(p, n); break;
    }
  } catch (const tofmat::FormatError&) {
  }
  return 0;
}
