// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// libFuzzer target: the depth stream parser under any sequence of bus faults.
// The input is a program of 3-byte steps (op, 16-bit parameter) acting on a
// clean scripted stream of numbered frames: pass the next packet, drop it,
// duplicate the last one, truncate the next one, insert garbage of any
// length (up to 64 KiB) or an empty packet, or reset the parser. Oracles:
// no crash or sanitizer report; counters consistent; and every frame passed on
// is exactly a frame that was sent, unless the program both lost data (a
// dropped packet, a reset, or data the parser itself discarded) and added a
// packet that can stand in for it (a duplicate, a full-size insert or a cut
// packet), or inserted garbage of exactly the length that completes the
// pending sub-packet (its tail then reads as a footer): no framing can tell
// these from real data, the protocol carries no checksum (docs/kinect-driver.md).
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

#include "tofmat/kinect/constants.hpp"
#include "tofmat/kinect/depth_stream_parser.hpp"

namespace {

using namespace tofmat::kinect;
constexpr std::size_t kPacket = 0x8400;

std::uint8_t payload_byte(std::uint32_t frame, std::uint32_t sub, std::size_t i) {
  return static_cast<std::uint8_t>((frame * 31u + sub * 7u + static_cast<std::uint32_t>(i / 997)) & 0xFFu);
}

// The clean stream, produced one iso packet at a time.
struct Script {
  std::uint32_t frame = 0, sub = 0;
  std::size_t offset = 0;
  std::vector<std::uint8_t> current;
  std::vector<std::uint8_t> next_packet() {
    if (offset == 0) {
      static std::vector<std::uint8_t> p(kSubImageBytes);
      for (std::size_t i = 0; i < p.size(); i += 997) {  // constant over blocks of 997 bytes
        std::memset(p.data() + i, payload_byte(frame, sub, i), std::min<std::size_t>(997, p.size() - i));
      }
      current = encode_sub_packet(p.data(), frame, sub, frame * 10 + sub);
    }
    const std::size_t n = std::min(kPacket, current.size() - offset);
    std::vector<std::uint8_t> out(current.begin() + static_cast<std::ptrdiff_t>(offset),
                                  current.begin() + static_cast<std::ptrdiff_t>(offset + n));
    offset += n;
    if (offset == current.size()) {
      offset = 0;
      if (++sub == static_cast<std::uint32_t>(kSubImages)) {
        sub = 0;
        ++frame;
      }
    }
    return out;
  }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  bool intact = true;
  std::uint64_t emitted = 0;
  DepthStreamParser parser(kPacket, [&](const DepthPacket& p) {
    ++emitted;
    for (std::uint32_t s = 0; s < static_cast<std::uint32_t>(kSubImages) && intact; ++s) {
      const std::uint8_t* d = p.data + static_cast<std::size_t>(s) * kSubImageBytes;
      for (std::size_t i = 0; i < kSubImageBytes; i += 4099) intact = intact && d[i] == payload_byte(p.sequence, s, i);
    }
  });
  Script script;
  std::vector<std::uint8_t> last;
  bool lost = false, stand_in = false, completing_insert = false;
  for (std::size_t k = 0; k + 3 <= size; k += 3) {
    const std::uint8_t op = data[k] % 8;
    const std::size_t param = static_cast<std::size_t>(data[k + 1] | (data[k + 2] << 8));
    switch (op) {
      case 0:
      case 1:  // the common case twice as often
        last = script.next_packet();
        parser.feed(last.data(), last.size());
        break;
      case 2:
        script.next_packet();
        lost = true;
        break;
      case 3:
        stand_in = true;
        parser.feed(last.data(), last.size());
        break;
      case 4: {
        auto p = script.next_packet();
        p.resize(std::min(p.size(), param));
        stand_in = true;  // a cut packet can stand in for a dropped short one
        parser.feed(p.data(), p.size());
        break;
      }
      case 5: {
        std::vector<std::uint8_t> junk(param);
        for (std::size_t i = 0; i < junk.size(); ++i) junk[i] = data[(k + i) % size];
        stand_in = stand_in || param == kPacket;
        completing_insert = completing_insert || parser.pending_bytes() + param == kSubPacketBytes;
        parser.feed(junk.data(), junk.size());
        break;
      }
      case 6:
        parser.feed(nullptr, 0);
        lost = true;
        break;
      default:
        parser.reset();
        lost = true;
        break;
    }
  }
  const auto& c = parser.counters();
  if (c.frames != emitted) __builtin_trap();
  if (c.frames * static_cast<std::uint64_t>(kSubImages) > c.sub_images) __builtin_trap();
  lost = lost || c.broken_sub_images > 0;
  if (!intact && !(lost && stand_in) && !completing_insert) __builtin_trap();
  return 0;
}
