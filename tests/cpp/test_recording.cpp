// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Recordings keep the camera's intrinsics when they are known (header flag
// bit 1 and a 36-byte block after the P0 tables), recordings without them
// still load, and the block is held to the driver's own checks.
#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "test_util.hpp"
#include "tofmat/core/error.hpp"
#include "tofmat/daemon/recording.hpp"

namespace {

using namespace tofmat::daemon;
using tofmat::FormatError;
using tofmat::kinect::DepthParams;
using tofmat_test::error_of;
using tofmat_test::TempDir;

DepthParams kinect_like() {
  DepthParams p;
  p.fx = 365.5f;
  p.fy = 365.25f;
  p.cx = 255.5f;
  p.cy = 211.75f;
  p.k1 = 0.09f;
  p.k2 = -0.27f;
  p.k3 = 0.1f;
  p.p1 = 0.001f;
  p.p2 = -0.002f;
  return p;
}

RawFrame frame(std::uint64_t sequence, std::int16_t sample) {
  RawFrame f;
  f.sequence = sequence;
  f.arrival_ns = 1000 + sequence * 33'333'333;
  f.raw.assign(9 * kPixels, sample);
  return f;
}

std::vector<std::uint8_t> write(const std::string& path, const std::optional<DepthParams>& intrinsics) {
  RecordingWriter w(path, std::vector<float>(3 * kPixels, 0.25f), true, intrinsics);
  w.write(frame(7, 11));
  w.write(frame(8, 12));
  w.close();
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void expect_same(const DepthParams& a, const DepthParams& b) {
  EXPECT_EQ(std::vector<float>({a.fx, a.fy, a.cx, a.cy, a.k1, a.k2, a.k3, a.p1, a.p2}),
            std::vector<float>({b.fx, b.fy, b.cx, b.cy, b.k1, b.k2, b.k3, b.p1, b.p2}));
}

TEST(Recording, KeepsTheIntrinsicsWhenKnown) {
  TempDir dir;
  const std::string path = (dir.path() / "with.tmrec").string();
  const auto bytes = write(path, kinect_like());
  EXPECT_EQ(bytes.size(), kRecordingHeaderBytes + kRecordingIntrinsicsBytes + 2 * kRecordedFrameBytes);
  EXPECT_EQ(bytes[16], kRecordingFlagSimulated | kRecordingFlagIntrinsics);
  const Recording r = parse_recording(bytes.data(), bytes.size(), 10);
  ASSERT_TRUE(r.intrinsics);
  expect_same(*r.intrinsics, kinect_like());
  EXPECT_EQ(r.header_bytes, kRecordingHeaderBytes + kRecordingIntrinsicsBytes);
  ASSERT_EQ(r.frames.size(), 2u);
  EXPECT_EQ(r.frames[0].sequence, 7u);
  EXPECT_EQ(r.frames[1].raw[0], 12);
  EXPECT_FALSE(r.truncated);

  RecordingReader reader(path);
  ASSERT_TRUE(reader.intrinsics());
  expect_same(*reader.intrinsics(), kinect_like());
  EXPECT_TRUE(reader.simulated());
  EXPECT_EQ(reader.next()->sequence, 7u);
  EXPECT_EQ(reader.next()->sequence, 8u);
  EXPECT_FALSE(reader.next());
  reader.rewind();  // back to the first frame, past the intrinsics
  const auto again = reader.next();
  ASSERT_TRUE(again);
  EXPECT_EQ(again->sequence, 7u);
  EXPECT_EQ(again->raw[9 * kPixels - 1], 11);
}

TEST(Recording, WithoutIntrinsicsLoadsAsBefore) {
  TempDir dir;
  const std::string path = (dir.path() / "without.tmrec").string();
  const auto bytes = write(path, std::nullopt);
  EXPECT_EQ(bytes.size(), kRecordingHeaderBytes + 2 * kRecordedFrameBytes);
  EXPECT_EQ(bytes[16], kRecordingFlagSimulated);
  const Recording r = parse_recording(bytes.data(), bytes.size(), 10);
  EXPECT_FALSE(r.intrinsics);
  EXPECT_EQ(r.header_bytes, kRecordingHeaderBytes);
  EXPECT_EQ(r.frames.size(), 2u);
  RecordingReader reader(path);
  EXPECT_FALSE(reader.intrinsics());
  EXPECT_EQ(reader.next()->sequence, 7u);
}

TEST(Recording, BadOrCutIntrinsicsAreFormatErrors) {
  TempDir dir;
  const std::string path = (dir.path() / "bad.tmrec").string();
  const auto bytes = write(path, kinect_like());
  const auto refused = [](std::vector<std::uint8_t> b) {
    return error_of<FormatError>([&] { parse_recording(b.data(), b.size(), 10); });
  };
  // Each field in turn: fx 0 (focal), cx beyond the image, k1 NaN, p2 beyond 10.
  const struct {
    int field;
    float value;
    const char* says;
  } cases[] = {{0, 0.0f, "focal"}, {2, 600.0f, "centre"}, {4, std::nanf(""), "finite"}, {8, 11.0f, "distortion"}};
  for (const auto& c : cases) {
    auto b = bytes;
    std::memcpy(b.data() + kRecordingHeaderBytes + 4 * c.field, &c.value, 4);
    const std::string message = refused(b);
    EXPECT_CONTAINS(message, "intrinsics");
    EXPECT_CONTAINS(message, c.says);
  }
  // Cut inside the block.
  EXPECT_CONTAINS(refused({bytes.begin(), bytes.begin() + kRecordingHeaderBytes + 20}), "intrinsics are cut off");
  std::ofstream(path, std::ios::binary | std::ios::trunc)
      .write(reinterpret_cast<const char*>(bytes.data()), kRecordingHeaderBytes + 20);
  EXPECT_CONTAINS(error_of<FormatError>([&] { RecordingReader reader(path); }), "cut off");
  // Another unknown flag is still refused.
  auto b = bytes;
  b[16] |= 4;
  EXPECT_CONTAINS(refused(b), "unknown flags");
  // The writer will not make a file a reader refuses.
  DepthParams wild = kinect_like();
  wild.fy = -1.0f;
  EXPECT_CONTAINS(error_of<FormatError>([&] { RecordingWriter w(path, std::vector<float>(3 * kPixels), false, wild); }),
                  "focal");
}

}  // namespace
