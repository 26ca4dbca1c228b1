// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The depth stream's pure parts (firmware/kinect): the 11-bit packed layout,
// sub-packet reassembly and its behaviour under every fault the bus can
// produce (shared/docs/kinect2-protocol.md 2.1-2.4).
#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <vector>

#include "tofmat/core/raw_lut.hpp"
#include "tofmat/kinect/constants.hpp"
#include "tofmat/kinect/depth_stream_parser.hpp"
#include "tofmat/kinect/raw_unpack.hpp"

namespace {

using namespace tofmat::kinect;
constexpr std::size_t kPacket = 0x8400;  // 33,792: the smallest endpoint size the device accepts

// ---------------------------------------------------------------------------
// 11-bit layout
// ---------------------------------------------------------------------------

std::vector<std::uint16_t> random_codes(std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::vector<std::uint16_t> c(kPixels);
  for (auto& v : c) v = static_cast<std::uint16_t>(rng() & 0x7FF);
  return c;
}

TEST(RawUnpack, PackThenUnpackGivesTheCodesBackExceptTheBorderColumns) {
  const auto codes = random_codes(1);
  std::vector<std::uint8_t> sub(kSubImageBytes);
  pack_codes(codes.data(), sub.data());
  std::vector<std::uint16_t> back(kPixels);
  unpack_codes(sub.data(), back.data());
  for (int y = 0; y < kHeight; ++y) {
    for (int x = 0; x < kWidth; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * kWidth + static_cast<std::size_t>(x);
      ASSERT_EQ(back[i], (x == 0 || x == kWidth - 1) ? 0 : codes[i]) << x << "," << y;
    }
  }
}

TEST(RawUnpack, DocumentedPositionsOfSingleCodes) {
  // One code at a time: output (x, y) must sit at stored row r(y), slot
  // 128 (x mod 4) + x / 4, bit 11 slot, LSB first.
  for (auto [x, y] : std::vector<std::pair<int, int>>{{1, 0}, {2, 5}, {3, 211}, {4, 212}, {510, 423}, {257, 300}}) {
    std::vector<std::uint16_t> codes(kPixels, 0);
    codes[static_cast<std::size_t>(y) * kWidth + static_cast<std::size_t>(x)] = 0x5A5;
    std::vector<std::uint8_t> sub(kSubImageBytes);
    pack_codes(codes.data(), sub.data());
    const int row = y < 212 ? y : 212 + (423 - y);
    const int slot = 128 * (x % 4) + x / 4;
    const std::size_t bit = static_cast<std::size_t>(row) * kRowBytes * 8 + 11u * static_cast<std::size_t>(slot);
    std::uint32_t v = 0;
    for (int b = 0; b < 11; ++b) {
      const std::size_t k = bit + static_cast<std::size_t>(b);
      v |= static_cast<std::uint32_t>((sub[k / 8] >> (k % 8)) & 1u) << b;
    }
    EXPECT_EQ(v, 0x5A5u) << x << "," << y;
    std::size_t set = 0;
    for (std::uint8_t byte : sub) set += static_cast<std::size_t>(__builtin_popcount(byte));
    EXPECT_EQ(set, static_cast<std::size_t>(__builtin_popcount(0x5A5))) << "nothing else written";
  }
  EXPECT_EQ(stored_row_of_output_row(0), 0);
  EXPECT_EQ(stored_row_of_output_row(211), 211);
  EXPECT_EQ(stored_row_of_output_row(423), 212);
  EXPECT_EQ(stored_row_of_output_row(212), 423);
}

TEST(RawUnpack, TheLastSlotOfTheLastRowReadsNothingBeyondTheSubImage) {
  // Slot 511 (column 511 - 0 ... the last slot is x = 511's) ends on the row's
  // last bit: unpacking a sub-image placed at the very end of an allocation
  // must not read past it (ASan checks this build).
  std::vector<std::uint8_t> sub(kSubImageBytes, 0xFF);
  std::vector<std::uint16_t> codes(kPixels);
  unpack_codes(sub.data(), codes.data());
  EXPECT_EQ(codes[kPixels - 2], 0x7FF);
  EXPECT_EQ(codes[kPixels - 1], 0);  // column 511 is forced to 0
  EXPECT_EQ(codes[0], 0);            // column 0 too
}

TEST(RawUnpack, RawValuesGoThroughTheDeviceTable) {
  auto codes = random_codes(2);
  codes[kWidth + 1] = tofmat::kRawSaturationCode;  // "minus zero": saturated
  std::vector<std::uint8_t> sub(kSubImageBytes);
  pack_codes(codes.data(), sub.data());
  std::vector<std::int16_t> raw(kPixels);
  unpack_raw(sub.data(), raw.data());
  EXPECT_EQ(raw[kWidth + 1], tofmat::kRawSaturated);
  for (std::size_t i = 0; i < kPixels; ++i) {
    const int x = static_cast<int>(i % kWidth);
    const std::int16_t want = (x == 0 || x == kWidth - 1) ? std::int16_t{0} : tofmat::raw_code_value(codes[i]);
    ASSERT_EQ(raw[i], want) << i;
  }
}

// ---------------------------------------------------------------------------
// Stream reassembly
// ---------------------------------------------------------------------------

// A depth packet whose sub-image s is filled with bytes derived from (frame, s).
std::vector<std::uint8_t> payload(std::uint32_t frame, int s) {
  std::vector<std::uint8_t> p(kSubImageBytes);
  for (std::size_t i = 0; i < p.size(); i += 4096)
    p[i] = static_cast<std::uint8_t>(frame * 16 + static_cast<std::uint32_t>(s));
  p[0] = static_cast<std::uint8_t>(frame);
  p[1] = static_cast<std::uint8_t>(s);
  return p;
}

using Packets = std::vector<std::vector<std::uint8_t>>;

// Iso packets of one sub-packet, cut at kPacket bytes as the device does.
Packets iso_of_sub(std::uint32_t frame, int s, std::uint32_t timestamp) {
  const auto sp = encode_sub_packet(payload(frame, s).data(), frame, static_cast<std::uint32_t>(s), timestamp);
  Packets out;
  for (std::size_t off = 0; off < sp.size(); off += kPacket) {
    out.emplace_back(sp.begin() + static_cast<std::ptrdiff_t>(off),
                     sp.begin() + static_cast<std::ptrdiff_t>(std::min(sp.size(), off + kPacket)));
  }
  return out;
}

Packets iso_of_frame(std::uint32_t frame) {
  Packets out;
  for (int s = 0; s < kSubImages; ++s) {
    for (auto& p : iso_of_sub(frame, s, 1000 + frame * 330 + static_cast<std::uint32_t>(s)))
      out.push_back(std::move(p));
  }
  return out;
}

struct Collector {
  std::vector<std::uint32_t> sequences, timestamps;
  std::vector<bool> intact;
  void operator()(const DepthPacket& p) {
    sequences.push_back(p.sequence);
    timestamps.push_back(p.timestamp);
    bool ok = true;
    for (int s = 0; s < kSubImages; ++s) {
      const auto want = payload(p.sequence, s);
      ok = ok && std::memcmp(p.data + static_cast<std::size_t>(s) * kSubImageBytes, want.data(), kSubImageBytes) == 0;
    }
    intact.push_back(ok);
  }
};

struct Harness {
  Collector got;
  DepthStreamParser parser{kPacket, [this](const DepthPacket& p) { got(p); }};
  void feed(const Packets& ps) {
    for (const auto& p : ps) parser.feed(p.data(), p.size());
  }
};

TEST(DepthStream, CleanStreamEmitsEveryFrameIntactAtItsLastSubImage) {
  Harness h;
  for (std::uint32_t f = 0; f < 4; ++f) {
    h.feed(iso_of_frame(f));
    ASSERT_EQ(h.got.sequences.size(), f + 1) << "emitted without waiting for the next frame";
  }
  EXPECT_EQ(h.got.sequences, (std::vector<std::uint32_t>{0, 1, 2, 3}));
  EXPECT_EQ(h.got.timestamps, (std::vector<std::uint32_t>{1000, 1330, 1660, 1990}));
  for (bool ok : h.got.intact) EXPECT_TRUE(ok);
  const auto& c = h.parser.counters();
  EXPECT_EQ(c.frames, 4u);
  EXPECT_EQ(c.sub_images, 40u);
  EXPECT_EQ(c.broken_sub_images + c.bad_footers + c.incomplete_frames + c.resyncs + c.duplicate_sub_images, 0u);
}

// Each fault hits frame 1 of frames 0..3: frame 1 is dropped and counted,
// the others come through intact.
void expect_only_frame_1_lost(Harness& h) {
  EXPECT_EQ(h.got.sequences, (std::vector<std::uint32_t>{0, 2, 3}));
  for (bool ok : h.got.intact) EXPECT_TRUE(ok);
  EXPECT_EQ(h.parser.counters().incomplete_frames, 1u);
}

TEST(DepthStream, DroppedIsoPacketLosesOnlyItsFrame) {
  for (std::size_t which : {0u, 3u, 8u}) {  // first, middle, short last packet of sub-image 4
    Harness h;
    h.feed(iso_of_frame(0));
    auto f1 = iso_of_frame(1);
    f1.erase(f1.begin() + static_cast<std::ptrdiff_t>(4 * 9 + which));
    h.feed(f1);
    h.feed(iso_of_frame(2));
    h.feed(iso_of_frame(3));
    expect_only_frame_1_lost(h);
    EXPECT_GE(h.parser.counters().broken_sub_images, 1u) << which;
  }
}

TEST(DepthStream, DuplicatedIsoPacketLosesOnlyItsFrame) {
  Harness h;
  h.feed(iso_of_frame(0));
  auto f1 = iso_of_frame(1);
  f1.insert(f1.begin() + 20, f1[20]);
  h.feed(f1);
  h.feed(iso_of_frame(2));
  h.feed(iso_of_frame(3));
  expect_only_frame_1_lost(h);
}

TEST(DepthStream, TruncatedIsoPacketLosesOnlyItsFrame) {
  Harness h;
  h.feed(iso_of_frame(0));
  auto f1 = iso_of_frame(1);
  f1[30].resize(1000);
  h.feed(f1);
  h.feed(iso_of_frame(2));
  h.feed(iso_of_frame(3));
  expect_only_frame_1_lost(h);
}

TEST(DepthStream, GarbagePacketsLoseOnlyTheirFrame) {
  std::mt19937 rng(5);
  for (std::size_t len : {std::size_t{1}, std::size_t{152}, kPacket, kPacket + 1, std::size_t{5000000}}) {
    Harness h;
    h.feed(iso_of_frame(0));
    auto f1 = iso_of_frame(1);
    std::vector<std::uint8_t> junk(len);
    for (auto& b : junk) b = static_cast<std::uint8_t>(rng());
    f1.insert(f1.begin() + 50, junk);
    h.feed(f1);
    h.feed(iso_of_frame(2));
    h.feed(iso_of_frame(3));
    expect_only_frame_1_lost(h);
  }
}

TEST(DepthStream, EmptyPacketResynchronises) {
  Harness h;
  h.feed(iso_of_frame(0));
  auto f1 = iso_of_frame(1);
  f1.insert(f1.begin() + 13, std::vector<std::uint8_t>{});
  h.feed(f1);
  h.feed(iso_of_frame(2));
  h.feed(iso_of_frame(3));
  expect_only_frame_1_lost(h);
  EXPECT_EQ(h.parser.counters().resyncs, 1u);
}

TEST(DepthStream, WrongFooterLengthIsRejected) {
  Harness h;
  h.feed(iso_of_frame(0));
  auto f1 = iso_of_frame(1);
  auto& last = f1[9 * 3 + 8];                     // the short packet ending sub-image 3 holds its footer
  last[last.size() - kFooterBytes + 20] ^= 0x01;  // length field
  h.feed(f1);
  h.feed(iso_of_frame(2));
  h.feed(iso_of_frame(3));
  expect_only_frame_1_lost(h);
  EXPECT_EQ(h.parser.counters().bad_footers, 1u);
}

TEST(DepthStream, SubImagesOutOfOrderStillMakeAFrameAndDuplicatesAreCounted) {
  Harness h;
  Packets ps;
  for (int s : {9, 2, 0, 5, 1, 3, 4, 6, 2, 8, 7}) {
    for (auto& p : iso_of_sub(0, s, 77)) ps.push_back(std::move(p));
  }
  h.feed(ps);
  ASSERT_EQ(h.got.sequences.size(), 1u);
  EXPECT_TRUE(h.got.intact[0]);
  EXPECT_EQ(h.parser.counters().duplicate_sub_images, 1u);
  // A sub-image of the frame already emitted is a stray, not a new frame.
  h.feed(iso_of_sub(0, 4, 77));
  EXPECT_EQ(h.got.sequences.size(), 1u);
  EXPECT_EQ(h.parser.counters().stray_sub_images, 1u);
}

TEST(DepthStream, ResetForgetsPartialData) {
  Harness h;
  auto f0 = iso_of_frame(0);
  h.feed(Packets(f0.begin(), f0.begin() + 40));
  h.parser.reset();
  h.feed(iso_of_frame(1));
  EXPECT_EQ(h.got.sequences, (std::vector<std::uint32_t>{1}));
  EXPECT_TRUE(h.got.intact[0]);
}

TEST(DepthStream, RejectsPacketSizesThatCannotMarkSubPacketEnds) {
  EXPECT_THROW(DepthStreamParser(0, {}), std::invalid_argument);
  EXPECT_THROW(DepthStreamParser(kSubPacketBytes + 1, {}), std::invalid_argument);
  EXPECT_THROW(DepthStreamParser(kSubPacketBytes / 8, {}), std::invalid_argument);  // 37,331 divides it
  EXPECT_NO_THROW(DepthStreamParser(kPacket, {}));
}

}  // namespace

TEST(DepthStream, SequenceGapsCountSkippedFramesButNotARestartOrAReset) {
  Harness h;
  for (std::uint32_t f : {0u, 1u, 5u, 6u}) h.feed(iso_of_frame(f));  // 2, 3, 4 never arrived (a stall)
  EXPECT_EQ(h.got.sequences, (std::vector<std::uint32_t>{0, 1, 5, 6}));
  EXPECT_EQ(h.parser.counters().skipped_frames, 3u);
  h.feed(iso_of_frame(6u + tofmat::kinect::kMaxSequenceGap));  // the device restarted its numbering
  EXPECT_EQ(h.parser.counters().skipped_frames, 3u);
  h.parser.reset();  // a reconnect: numbering starts again
  h.feed(iso_of_frame(40u));
  EXPECT_EQ(h.parser.counters().skipped_frames, 3u);
  EXPECT_EQ(h.got.sequences.size(), 6u);
}
