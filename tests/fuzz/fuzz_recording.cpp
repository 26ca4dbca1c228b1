// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// libFuzzer target: parse_recording (firmware/daemon/recording.hpp) with
// max_frames 2. The only acceptable refusal is tofmat::FormatError.
//
// A recording's header alone is 2,605,076 bytes (3 x 512 x 424 float32 P0
// corrections) and a frame 3,907,604, far beyond the inputs libFuzzer grows
// (and too big for a committed seed). So each input is used twice:
//  - as a recording itself: every input the fuzzer makes is shorter than a
//    header, so this covers the short-input path (refused before anything
//    is read or allocated); the seeds are tiny on purpose and rely on it;
//  - written over a well-formed recording in memory (zero P0 corrections and
//    three frames) at the offset its first three bytes pick, and parsed up
//    to the end of the last header or frame it touched (even input sizes) or
//    cut short where it ends (odd sizes): the magic, size, flags, P0 and
//    frame marker checks, max_frames and the truncated flag all get reached.
//    One parse per input, no longer than needed: copying a frame costs
//    milliseconds under the fuzzer's instrumentation.
// Whatever parses must hold what the bytes say: finite P0 corrections within
// +-1000 rad, min(2, whole frames) frames of 9 x 512 x 424 samples, and
// `truncated` exactly when bytes are left after fewer than 2 frames.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

#include "tofmat/core/error.hpp"
#include "tofmat/daemon/recording.hpp"

namespace {

using namespace tofmat::daemon;
constexpr std::size_t kMaxFrames = 2;
constexpr std::size_t kTemplateFrames = 3;

void put_le(std::uint8_t* p, std::uint64_t v, int n) {
  for (int i = 0; i < n; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}

std::uint64_t get_le(const std::uint8_t* p, int n) {
  std::uint64_t v = 0;
  for (int i = n - 1; i >= 0; --i) v = v << 8 | p[i];
  return v;
}

// Built by hand (not by RecordingWriter, which writes files).
std::vector<std::uint8_t> make_template() {
  std::vector<std::uint8_t> b(kRecordingHeaderBytes + kTemplateFrames * kRecordedFrameBytes, 0);
  std::memcpy(b.data(), kRecordingMagic, 8);
  put_le(b.data() + 8, kWidth, 4);
  put_le(b.data() + 12, kHeight, 4);
  for (std::size_t f = 0; f < kTemplateFrames; ++f) {
    std::uint8_t* p = b.data() + kRecordingHeaderBytes + f * kRecordedFrameBytes;
    std::memcpy(p, kFrameMagic, 4);
    put_le(p + 4, 100 + f, 8);
    put_le(p + 12, f * 33'333'333u, 8);
    put_le(p + 20 + 2 * f, 0x1234, 2);  // a sample that is not zero
  }
  return b;
}

void check(const std::uint8_t* data, std::size_t size) {
  Recording r;
  try {
    r = parse_recording(data, size, kMaxFrames);
  } catch (const tofmat::FormatError&) {
    return;  // refused: fine
  }
  const std::size_t header = r.header_bytes;
  if (header != kRecordingHeaderBytes + (r.intrinsics ? kRecordingIntrinsicsBytes : 0)) __builtin_trap();
  if (size < header) __builtin_trap();
  if (r.intrinsics && !(r.intrinsics->fx > 0 && r.intrinsics->fy > 0)) __builtin_trap();
  if (r.p0_rad.size() != 3 * kPixels) __builtin_trap();
  for (float v : r.p0_rad)
    if (!std::isfinite(v) || std::abs(v) > 1000.0f) __builtin_trap();
  const std::size_t whole = (size - header) / kRecordedFrameBytes;
  const std::size_t frames = std::min(whole, kMaxFrames);
  if (r.frames.size() != frames) __builtin_trap();
  if (r.truncated != (frames < kMaxFrames && size != header + frames * kRecordedFrameBytes)) __builtin_trap();
  for (std::size_t f = 0; f < frames; ++f) {
    const std::uint8_t* p = data + header + f * kRecordedFrameBytes;
    if (r.frames[f].raw.size() != 9 * kPixels || r.frames[f].sequence != get_le(p + 4, 8) ||
        r.frames[f].offset_ns != get_le(p + 12, 8) || std::memcmp(r.frames[f].raw.data(), p + 20, 2) != 0)
      __builtin_trap();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::vector<std::uint8_t> base = make_template();
  static std::vector<std::uint8_t> buf = base;  // written over, then restored: no 14 MB copy per input
  check(data, size);
  if (size < 3) return 0;
  const std::size_t at = (std::size_t{data[0]} | std::size_t{data[1]} << 8 | std::size_t{data[2]} << 16) % buf.size();
  const std::size_t len = std::min(size - 3, buf.size() - at);
  std::memcpy(buf.data() + at, data + 3, len);
  const std::size_t end = at + len;
  std::size_t n = end;
  if (size % 2 == 0)
    n = end <= kRecordingHeaderBytes
            ? kRecordingHeaderBytes
            : std::min(buf.size(), kRecordingHeaderBytes + (end - kRecordingHeaderBytes + kRecordedFrameBytes - 1) /
                                                               kRecordedFrameBytes * kRecordedFrameBytes);
  check(buf.data(), n);
  std::memcpy(buf.data() + at, base.data() + at, len);
  return 0;
}
