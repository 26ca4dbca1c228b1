// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Reassembles the depth stream (kinect2-protocol.md 2.1): isochronous packets
// -> sub-packets of 298,496 payload bytes ending with a 152-byte footer ->
// depth packets of ten sub-images with a sequence number and timestamp.
//
// Robustness beyond the reference driver: a sub-packet always ends in a short
// iso packet (298,648 is not a multiple of the packet size), so a short packet
// that does not complete the sub-packet marks it broken and the next packet
// starts afresh: after any lost, truncated, duplicated or garbage packet the
// parser is back in step at the next sub-packet, never misaligned for good.
// A frame is emitted as soon as its ten sub-images are in (not when the next
// frame begins), and only then: an incomplete or inconsistent frame is dropped
// and counted, never passed on. Every length is bounded by the fixed sizes.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

#include "tofmat/kinect/constants.hpp"

namespace tofmat::kinect {

struct DepthPacket {
  std::uint32_t sequence = 0;
  std::uint32_t timestamp = 0;         // of sub-image 0's footer, units of ~0.1 ms
  const std::uint8_t* data = nullptr;  // kDepthPacketBytes, valid during the callback only
};

struct DepthStreamCounters {
  std::uint64_t packets = 0;  // iso packets fed
  std::uint64_t bytes = 0;
  std::uint64_t sub_images = 0;         // accepted sub-packets
  std::uint64_t frames = 0;             // emitted depth packets
  std::uint64_t resyncs = 0;            // empty iso packets that discarded partial data
  std::uint64_t broken_sub_images = 0;  // overflowed or cut short: data lost or corrupt
  std::uint64_t bad_footers = 0;        // footer inconsistent with the payload
  std::uint64_t incomplete_frames = 0;  // frames dropped with sub-images missing
  std::uint64_t duplicate_sub_images = 0;
  std::uint64_t stray_sub_images = 0;  // for a frame already emitted
  // Frames the device numbered but of which not one sub-image arrived (a
  // stalled endpoint, a burst of lost packets): the gaps between the sequence
  // numbers seen, for forward gaps below kMaxSequenceGap.
  std::uint64_t skipped_frames = 0;
};
// A larger jump of the sequence number is a device restart, not lost frames.
inline constexpr std::uint32_t kMaxSequenceGap = 1u << 16;

class DepthStreamParser {
 public:
  using Callback = std::function<void(const DepthPacket&)>;

  // max_packet_bytes: the iso endpoint's packet size (wBytesPerInterval); a
  // packet shorter than it ends a sub-packet. Throws std::invalid_argument
  // unless 1 <= max_packet_bytes <= kSubPacketBytes.
  DepthStreamParser(std::size_t max_packet_bytes, Callback on_frame);

  // One completed iso packet (length as received, 0 allowed). Never throws
  // for any bytes; lengths above max_packet_bytes are treated as broken.
  void feed(const std::uint8_t* data, std::size_t length);

  // Forget partial data (after a stall or a reconnect).
  void reset();

  const DepthStreamCounters& counters() const { return counters_; }
  // Bytes of the sub-packet being collected (diagnostics and tests).
  std::size_t pending_bytes() const { return collected_; }

 private:
  void on_sub_packet();
  void finish_frame();

  std::size_t max_packet_;
  Callback on_frame_;
  std::vector<std::uint8_t> sub_;  // the sub-packet being collected
  std::size_t collected_ = 0;
  std::vector<std::uint8_t> frame_;  // kDepthPacketBytes
  bool have_frame_ = false;
  bool emitted_ = false;  // current sequence already passed on
  std::uint32_t sequence_ = 0;
  std::uint32_t timestamp_ = 0;
  std::uint32_t mask_ = 0;
  DepthStreamCounters counters_;
};

// The footer's fields (the first six uint32 of the 152 bytes).
struct DepthFooter {
  std::uint32_t magic0, magic1, timestamp, sequence, subsequence, length;
};
DepthFooter parse_depth_footer(const std::uint8_t* footer);  // reads kFooterBytes

// The device side: one sub-packet (kSubPacketBytes) of sub-image `subsequence`
// of depth packet `sequence`: its payload (kSubImageBytes) and the footer. The
// footer's magic words and 32 trailing fields are unknown (section 5): the
// device here sends zeros, and the parser does not read them.
std::vector<std::uint8_t> encode_sub_packet(const std::uint8_t* payload, std::uint32_t sequence,
                                            std::uint32_t subsequence, std::uint32_t timestamp);

}  // namespace tofmat::kinect
