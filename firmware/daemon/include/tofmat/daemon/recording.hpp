// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Recordings of the raw stream (`tofmat record`, `--source replay:FILE`):
// what the camera delivered, so a session can be replayed through the same
// pipeline. Little-endian, fixed sizes (docs/protocol.md, "Recordings"):
//   header  "TMREC001", u32 width (512), u32 height (424), u32 flags (bit 0:
//           the frames are the simulator's; bit 1: the intrinsics follow; no
//           other bit may be set), 3 x width x height float32 P0 corrections
//           (radians, finite), then with bit 1 the depth camera's intrinsics:
//           9 float32 fx, fy, cx, cy, k1, k2, k3, p1, p2
//   frames  "FRM1", u64 sequence, u64 time since the first frame (ns),
//           9 x width x height int16 raw samples
// A reader checks every size and value range; a recording cut short in the
// middle of a frame ends at the last whole frame.
#pragma once
#include <cstdint>
#include <fstream>
#include <optional>
#include <string>
#include <vector>

#include "tofmat/daemon/source.hpp"

namespace tofmat::daemon {

inline constexpr char kRecordingMagic[8] = {'T', 'M', 'R', 'E', 'C', '0', '0', '1'};
inline constexpr char kFrameMagic[4] = {'F', 'R', 'M', '1'};
inline constexpr std::size_t kRecordingHeaderBytes = 8 + 12 + 3 * kPixels * sizeof(float);  // without intrinsics
inline constexpr std::size_t kRecordingIntrinsicsBytes = 9 * sizeof(float);
inline constexpr std::uint32_t kRecordingFlagSimulated = 1;   // header flags: frames rendered by the simulator
inline constexpr std::uint32_t kRecordingFlagIntrinsics = 2;  // the header ends with the camera's intrinsics
inline constexpr std::size_t kRecordedFrameBytes = 4 + 16 + 9 * kPixels * sizeof(std::int16_t);

class RecordingWriter {
 public:
  // Throws std::runtime_error if the file cannot be created. `simulated`:
  // the frames come from the simulator (kept in the header's flags).
  // `intrinsics`: the depth camera's (kept when known).
  RecordingWriter(const std::string& path, const std::vector<float>& p0_rad, bool simulated,
                  const std::optional<kinect::DepthParams>& intrinsics = std::nullopt);
  void write(const RawFrame& frame);
  std::uint64_t frames() const { return frames_; }
  void close();

 private:
  std::ofstream out_;
  std::string path_;
  std::uint64_t frames_ = 0, first_ns_ = 0;
};

struct RecordedFrame {
  std::uint64_t sequence = 0, offset_ns = 0;
  std::vector<std::int16_t> raw;
};

// Parses a whole recording held in memory (the fuzz target's entry point).
// Throws tofmat::FormatError (core/error.hpp) naming what is wrong.
struct Recording {
  std::vector<float> p0_rad;
  bool simulated = false;
  std::optional<kinect::DepthParams> intrinsics;
  std::size_t header_bytes = kRecordingHeaderBytes;  // the frames start here
  std::vector<RecordedFrame> frames;
  bool truncated = false;  // bytes after the last whole frame
};
Recording parse_recording(const std::uint8_t* data, std::size_t size, std::size_t max_frames);

// Streams a recording file frame by frame.
class RecordingReader {
 public:
  explicit RecordingReader(const std::string& path);  // reads and checks the header
  const std::vector<float>& p0_rad() const { return p0_rad_; }
  bool simulated() const { return simulated_; }
  const std::optional<kinect::DepthParams>& intrinsics() const { return intrinsics_; }
  // The next frame; nothing at the end (or at a cut-short frame). Throws FormatError.
  std::optional<RecordedFrame> next();
  void rewind();

 private:
  std::ifstream in_;
  std::string path_;
  std::vector<float> p0_rad_;
  bool simulated_ = false;
  std::optional<kinect::DepthParams> intrinsics_;
  std::size_t header_bytes_ = kRecordingHeaderBytes;
};

// `replay:FILE[,loop=1]`: plays the frames at the pace they were recorded.
std::unique_ptr<Source> make_replay_source(const std::string& spec);

}  // namespace tofmat::daemon
