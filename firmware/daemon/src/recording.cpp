// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Writing, reading and checking raw-stream recordings, and the replay source that plays them back.
#include "tofmat/daemon/recording.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <mutex>
#include <thread>

#include "tofmat/core/error.hpp"
#include "tofmat/protocol/socket.hpp"

namespace tofmat::daemon {
namespace {

constexpr std::uint64_t kMaxFrameGapNs = 10'000'000'000ull;  // a replay's longest pause between frames

static_assert(sizeof(float) == 4, "recordings store IEEE float32");

void put_u32(std::ostream& out, std::uint32_t v) {
  std::uint8_t b[4];
  for (int i = 0; i < 4; ++i) b[i] = static_cast<std::uint8_t>(v >> (8 * i));
  out.write(reinterpret_cast<const char*>(b), 4);
}
void put_u64(std::ostream& out, std::uint64_t v) {
  std::uint8_t b[8];
  for (int i = 0; i < 8; ++i) b[i] = static_cast<std::uint8_t>(v >> (8 * i));
  out.write(reinterpret_cast<const char*>(b), 8);
}
std::uint32_t get_u32(const std::uint8_t* p) {
  std::uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = v << 8 | p[i];
  return v;
}
std::uint64_t get_u64(const std::uint8_t* p) {
  std::uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = v << 8 | p[i];
  return v;
}

struct Header {
  std::vector<float> p0_rad;
  bool simulated = false;
  bool has_intrinsics = false;  // kRecordingIntrinsicsBytes follow the first kRecordingHeaderBytes
};

float get_f32(const std::uint8_t* p) {
  const std::uint32_t bits = get_u32(p);
  float v;
  std::memcpy(&v, &bits, sizeof v);
  return v;
}
void put_f32(std::ostream& out, float v) {
  std::uint32_t bits;
  std::memcpy(&bits, &v, sizeof bits);
  put_u32(out, bits);
}

// The intrinsics block: read and held to the driver's own check.
kinect::DepthParams parse_intrinsics(const std::uint8_t* p) {
  kinect::DepthParams d;
  float* const fields[9] = {&d.fx, &d.fy, &d.cx, &d.cy, &d.k1, &d.k2, &d.k3, &d.p1, &d.p2};
  for (int i = 0; i < 9; ++i) *fields[i] = get_f32(p + 4 * i);
  try {
    kinect::check_depth_params(d);
  } catch (const FormatError& e) {
    throw FormatError(std::string("recording's intrinsics: ") + e.what());
  }
  return d;
}

// The first kRecordingHeaderBytes' checks, shared by the in-memory parser and the file reader.
Header parse_header(const std::uint8_t* h) {
  if (std::memcmp(h, kRecordingMagic, 8) != 0) throw FormatError("not a tofmat recording (bad magic)");
  const std::uint32_t width = get_u32(h + 8), height = get_u32(h + 12), flags = get_u32(h + 16);
  if (width != static_cast<std::uint32_t>(kWidth) || height != static_cast<std::uint32_t>(kHeight))
    throw FormatError("recording is " + std::to_string(width) + " x " + std::to_string(height) +
                      ", expected the Kinect v2's 512 x 424");
  if ((flags & ~(kRecordingFlagSimulated | kRecordingFlagIntrinsics)) != 0)
    throw FormatError("recording has unknown flags " + std::to_string(flags));
  Header header;
  header.simulated = (flags & kRecordingFlagSimulated) != 0;
  header.has_intrinsics = (flags & kRecordingFlagIntrinsics) != 0;
  header.p0_rad.resize(3 * kPixels);
  std::memcpy(header.p0_rad.data(), h + 20, header.p0_rad.size() * sizeof(float));
  for (float v : header.p0_rad)
    if (!std::isfinite(v) || std::abs(v) > 1000.0f)
      throw FormatError("recording holds a P0 correction that is not a finite phase");
  return header;
}

RecordedFrame parse_frame(const std::uint8_t* p) {
  if (std::memcmp(p, kFrameMagic, 4) != 0) throw FormatError("recording frame has a bad marker");
  RecordedFrame f;
  f.sequence = get_u64(p + 4);
  f.offset_ns = get_u64(p + 12);
  f.raw.resize(9 * kPixels);
  std::memcpy(f.raw.data(), p + 20, f.raw.size() * sizeof(std::int16_t));
  return f;
}

}  // namespace

RecordingWriter::RecordingWriter(const std::string& path, const std::vector<float>& p0_rad, bool simulated,
                                 const std::optional<kinect::DepthParams>& intrinsics)
    : out_(path, std::ios::binary | std::ios::trunc), path_(path) {
  if (!out_) throw std::runtime_error("cannot create recording \"" + path + "\"");
  if (p0_rad.size() != 3 * kPixels) throw std::invalid_argument("recording: P0 corrections must be 3 x 512 x 424");
  if (intrinsics) kinect::check_depth_params(*intrinsics);  // (a reader would refuse the file)
  out_.write(kRecordingMagic, 8);
  put_u32(out_, kWidth);
  put_u32(out_, kHeight);
  put_u32(out_, (simulated ? kRecordingFlagSimulated : 0) | (intrinsics ? kRecordingFlagIntrinsics : 0));
  out_.write(reinterpret_cast<const char*>(p0_rad.data()), static_cast<std::streamsize>(p0_rad.size() * sizeof(float)));
  if (intrinsics) {
    const kinect::DepthParams& d = *intrinsics;
    for (float v : {d.fx, d.fy, d.cx, d.cy, d.k1, d.k2, d.k3, d.p1, d.p2}) put_f32(out_, v);
  }
}

void RecordingWriter::write(const RawFrame& frame) {
  if (frame.raw.size() != 9 * kPixels)
    throw std::invalid_argument("recording: a frame must hold 9 x 512 x 424 samples");
  if (frames_ == 0) first_ns_ = frame.arrival_ns;
  out_.write(kFrameMagic, 4);
  put_u64(out_, frame.sequence);
  put_u64(out_, frame.arrival_ns - first_ns_);
  out_.write(reinterpret_cast<const char*>(frame.raw.data()),
             static_cast<std::streamsize>(frame.raw.size() * sizeof(std::int16_t)));
  if (!out_) throw std::runtime_error("cannot write recording \"" + path_ + "\" (disk full?)");
  ++frames_;
}

void RecordingWriter::close() {
  out_.flush();
  if (!out_) throw std::runtime_error("cannot write recording \"" + path_ + "\"");
  out_.close();
}

Recording parse_recording(const std::uint8_t* data, std::size_t size, std::size_t max_frames) {
  if (size < kRecordingHeaderBytes) throw FormatError("recording is shorter than its header");
  Recording r;
  Header header = parse_header(data);
  r.p0_rad = std::move(header.p0_rad);
  r.simulated = header.simulated;
  if (header.has_intrinsics) {
    if (size - kRecordingHeaderBytes < kRecordingIntrinsicsBytes)
      throw FormatError("recording is shorter than its header (the intrinsics are cut off)");
    r.intrinsics = parse_intrinsics(data + kRecordingHeaderBytes);
    r.header_bytes += kRecordingIntrinsicsBytes;
  }
  std::size_t at = r.header_bytes;
  while (size - at >= kRecordedFrameBytes && r.frames.size() < max_frames) {
    r.frames.push_back(parse_frame(data + at));
    at += kRecordedFrameBytes;
  }
  r.truncated = at != size && r.frames.size() < max_frames;
  return r;
}

RecordingReader::RecordingReader(const std::string& path) : in_(path, std::ios::binary), path_(path) {
  if (!in_) throw std::runtime_error("cannot open recording \"" + path + "\"");
  std::vector<std::uint8_t> header(kRecordingHeaderBytes);
  if (!in_.read(reinterpret_cast<char*>(header.data()), static_cast<std::streamsize>(header.size())))
    throw FormatError("recording \"" + path + "\" is shorter than its header");
  Header parsed = parse_header(header.data());
  p0_rad_ = std::move(parsed.p0_rad);
  simulated_ = parsed.simulated;
  if (parsed.has_intrinsics) {
    std::uint8_t block[kRecordingIntrinsicsBytes];
    if (!in_.read(reinterpret_cast<char*>(block), sizeof block))
      throw FormatError("recording \"" + path + "\" is shorter than its header (the intrinsics are cut off)");
    intrinsics_ = parse_intrinsics(block);
    header_bytes_ += kRecordingIntrinsicsBytes;
  }
}

std::optional<RecordedFrame> RecordingReader::next() {
  std::vector<std::uint8_t> buf(kRecordedFrameBytes);
  if (!in_.read(reinterpret_cast<char*>(buf.data()), static_cast<std::streamsize>(buf.size()))) return std::nullopt;
  return parse_frame(buf.data());
}

void RecordingReader::rewind() {
  in_.clear();
  in_.seekg(static_cast<std::streamoff>(header_bytes_));
}

namespace {

class ReplaySource : public Source {
 public:
  ReplaySource(std::string path, bool loop, bool paced)
      : path_(std::move(path)), loop_(loop), paced_(paced), reader_(path_) {}
  std::string describe() const override {
    return std::string(reader_.simulated() ? "replay of a simulated recording " : "replay of ") + path_;
  }
  bool simulated() const override { return reader_.simulated(); }
  bool lossless() const override { return !paced_; }
  nlohmann::json counters() const override {
    std::lock_guard<std::mutex> lock(mutex_);
    return {{"frames", frames_}, {"loops", loops_}};
  }
  void run(const SourceCallbacks& callbacks, const std::atomic<bool>& stop) override {
    auto calibration = std::make_shared<const Calibration>(reader_.p0_rad(), reader_.intrinsics());
    callbacks.state(DeviceState::kStreaming, describe());
    const auto start = std::chrono::steady_clock::now();
    std::uint64_t base_ns = 0, last_ns = 0;
    std::uint64_t previous_offset = 0, in_pass = 0;  // (this pass through the file)
    while (!stop.load()) {
      auto f = reader_.next();
      if (!f) {
        if (!loop_) break;
        // (A file without a frame would loop without end, doing nothing.)
        if (in_pass == 0) throw FormatError("recording \"" + path_ + "\" holds no frame to loop over");
        reader_.rewind();
        base_ns = last_ns + 33'333'333;  // keep the pace across the loop
        previous_offset = in_pass = 0;
        std::lock_guard<std::mutex> lock(mutex_);
        ++loops_;
        continue;
      }
      // Frames are in time order, at most kMaxFrameGapNs apart: a corrupt time
      // would otherwise make a paced replay wait for years (or rush).
      if (f->offset_ns < previous_offset || f->offset_ns - previous_offset > kMaxFrameGapNs)
        throw FormatError("recording \"" + path_ + "\" frame " + std::to_string(in_pass) + ": its time (" +
                          std::to_string(f->offset_ns) + " ns) is not within 10 s after the previous frame's (" +
                          std::to_string(previous_offset) + " ns)");
      previous_offset = f->offset_ns;
      ++in_pass;
      last_ns = base_ns + f->offset_ns;
      // Paced: as recorded (the stop flag is looked at every 100 ms of a long pause).
      if (paced_) {
        const auto due = start + std::chrono::nanoseconds(last_ns);
        while (!stop.load() && std::chrono::steady_clock::now() < due)
          std::this_thread::sleep_until(
              std::min(due, std::chrono::steady_clock::now() + std::chrono::milliseconds(100)));
      }
      RawFrame frame;
      frame.sequence = f->sequence;
      frame.arrival_ns = protocol::monotonic_ns();
      frame.raw = std::move(f->raw);
      frame.calibration = calibration;
      frame.simulated = reader_.simulated();
      {
        std::lock_guard<std::mutex> lock(mutex_);
        ++frames_;
      }
      callbacks.frame(std::move(frame));
    }
    callbacks.state(DeviceState::kStopped, stop.load() ? "stopped" : "end of recording");
  }

 private:
  std::string path_;
  bool loop_, paced_;
  RecordingReader reader_;
  mutable std::mutex mutex_;
  std::uint64_t frames_ = 0, loops_ = 0;
};

}  // namespace

std::unique_ptr<Source> make_replay_source(const std::string& spec) {
  // Options trail the path (which may itself hold commas): ",loop=0|1", ",pace=0|1".
  std::string path = spec;
  bool loop = false, paced = true;
  for (;;) {
    const auto comma = path.rfind(',');
    if (comma == std::string::npos) break;
    const std::string option = path.substr(comma + 1);
    const auto eq = option.find('=');
    const std::string key = option.substr(0, eq);
    if (eq == std::string::npos || (key != "loop" && key != "pace")) break;
    const std::string v = option.substr(eq + 1);
    if (v != "0" && v != "1") throw std::invalid_argument("replay: " + key + " must be 0 or 1");
    (key == "loop" ? loop : paced) = v == "1";
    path.erase(comma);
  }
  if (path.empty()) throw std::invalid_argument("replay: needs a file (replay:FILE)");
  return std::make_unique<ReplaySource>(path, loop, paced);
}

}  // namespace tofmat::daemon
