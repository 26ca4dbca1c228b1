// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// libFuzzer target: the simulator's device profiles and material libraries
// (profile_io: JSON files read by name or path, 4 MiB limit). The first byte
// picks the parser, the rest is the text. Only tofmat::FormatError is an
// acceptable refusal; any other exception, crash or sanitizer report is a
// finding. What parses must serialise and parse again to the same text, and a
// device with a session drift must give a valid session at state 0.
#include <cstddef>
#include <cstdint>
#include <string>

#include "tofmat/core/error.hpp"
#include "tofmat/sim/profile_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  try {
    if (data[0] & 1) {
      const tofmat::sim::MaterialLibrary lib = tofmat::sim::library_from_json(text);
      const std::string once = tofmat::sim::library_to_json(lib);
      if (tofmat::sim::library_to_json(tofmat::sim::library_from_json(once)) != once) __builtin_trap();
    } else {
      const tofmat::sim::DeviceProfile dev = tofmat::sim::device_from_json(text);
      const std::string once = tofmat::sim::device_to_json(dev);
      if (tofmat::sim::device_to_json(tofmat::sim::device_from_json(once)) != once) __builtin_trap();
      // The nominal session is the profile itself: always valid.
      (void)dev.in_session({0.0, 0.0, 0.0});
    }
  } catch (const tofmat::FormatError&) {
    return 0;  // refused: fine
  }
  return 0;
}
