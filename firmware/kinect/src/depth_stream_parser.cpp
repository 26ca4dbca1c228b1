// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// DepthStreamParser: isochronous packets reassembled into sub-packets and depth packets, with every fault counted.
#include "tofmat/kinect/depth_stream_parser.hpp"

#include <cstring>
#include <stdexcept>

namespace tofmat::kinect {
namespace {
std::uint32_t le32(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) |
         (static_cast<std::uint32_t>(p[2]) << 16) | (static_cast<std::uint32_t>(p[3]) << 24);
}
}  // namespace

DepthFooter parse_depth_footer(const std::uint8_t* f) {
  return {le32(f), le32(f + 4), le32(f + 8), le32(f + 12), le32(f + 16), le32(f + 20)};
}

std::vector<std::uint8_t> encode_sub_packet(const std::uint8_t* payload, std::uint32_t sequence,
                                            std::uint32_t subsequence, std::uint32_t timestamp) {
  std::vector<std::uint8_t> out(kSubPacketBytes, 0);
  std::memcpy(out.data(), payload, kSubImageBytes);
  const std::uint32_t words[6] = {0, 0, timestamp, sequence, subsequence, static_cast<std::uint32_t>(kSubImageBytes)};
  for (std::size_t k = 0; k < 6; ++k) {
    for (std::size_t b = 0; b < 4; ++b)
      out[kSubImageBytes + 4 * k + b] = static_cast<std::uint8_t>(words[k] >> (8 * b));
  }
  return out;
}

DepthStreamParser::DepthStreamParser(std::size_t max_packet_bytes, Callback on_frame)
    : max_packet_(max_packet_bytes), on_frame_(std::move(on_frame)), sub_(kSubPacketBytes), frame_(kDepthPacketBytes) {
  if (max_packet_bytes < 1 || max_packet_bytes > kSubPacketBytes) {
    throw std::invalid_argument("iso packet size must be 1.." + std::to_string(kSubPacketBytes) + " bytes");
  }
  if (kSubPacketBytes % max_packet_bytes == 0) {
    // Without a short final packet a lost packet could not be told from the
    // boundary; no real endpoint size (>= 0x8400) divides 298,648.
    throw std::invalid_argument("iso packet size must not divide the sub-packet size (298,648 bytes)");
  }
}

void DepthStreamParser::reset() {
  collected_ = 0;
  have_frame_ = false;
  emitted_ = false;
  mask_ = 0;
}

void DepthStreamParser::feed(const std::uint8_t* data, std::size_t length) {
  ++counters_.packets;
  counters_.bytes += length;
  if (length == 0) {  // the reference driver's resynchronisation point
    if (collected_ > 0) ++counters_.resyncs;
    collected_ = 0;
    return;
  }
  if (length > max_packet_) {  // impossible from a real endpoint: treat as garbage
    if (collected_ > 0) ++counters_.broken_sub_images;
    collected_ = 0;
    return;
  }
  if (collected_ + length > kSubPacketBytes) {
    // The previous sub-packet lost its short last packet: drop it, and let
    // this packet start the next one.
    ++counters_.broken_sub_images;
    collected_ = 0;
  }
  std::memcpy(sub_.data() + collected_, data, length);
  collected_ += length;
  if (collected_ == kSubPacketBytes) {
    on_sub_packet();
    collected_ = 0;
  } else if (length < max_packet_) {
    // A short packet ends a sub-packet; this one is incomplete.
    ++counters_.broken_sub_images;
    collected_ = 0;
  }
}

void DepthStreamParser::on_sub_packet() {
  const DepthFooter f = parse_depth_footer(sub_.data() + kSubImageBytes);
  if (f.length != kSubImageBytes || f.subsequence >= static_cast<std::uint32_t>(kSubImages)) {
    ++counters_.bad_footers;
    return;
  }
  if (!have_frame_ || f.sequence != sequence_) {
    finish_frame();
    const std::uint32_t gap = f.sequence - sequence_;  // modulo 2^32
    if (have_frame_ && gap > 1 && gap < kMaxSequenceGap) counters_.skipped_frames += gap - 1;
    have_frame_ = true;
    emitted_ = false;
    sequence_ = f.sequence;
    mask_ = 0;
  }
  if (emitted_) {
    ++counters_.stray_sub_images;
    return;
  }
  const std::uint32_t bit = 1u << f.subsequence;
  if (mask_ & bit) ++counters_.duplicate_sub_images;  // keep the newer copy
  mask_ |= bit;
  if (f.subsequence == 0) timestamp_ = f.timestamp;
  std::memcpy(frame_.data() + static_cast<std::size_t>(f.subsequence) * kSubImageBytes, sub_.data(), kSubImageBytes);
  ++counters_.sub_images;
  if (mask_ == kAllSubImages) {
    emitted_ = true;
    ++counters_.frames;
    if (on_frame_) on_frame_(DepthPacket{sequence_, timestamp_, frame_.data()});
  }
}

void DepthStreamParser::finish_frame() {
  if (have_frame_ && !emitted_ && mask_ != 0) ++counters_.incomplete_frames;
}

}  // namespace tofmat::kinect
