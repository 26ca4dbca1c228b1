// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// SimulatedKinect: the command responses, faults, unplugging, and frames emitted as packed isochronous packets.
#include "tofmat/sim/kinect_device.hpp"

#include <chrono>
#include <cstring>
#include <thread>

#include "tofmat/core/byte_writer.hpp"
#include "tofmat/core/error.hpp"
#include "tofmat/core/raw_lut.hpp"
#include "tofmat/kinect/command.hpp"
#include "tofmat/kinect/constants.hpp"
#include "tofmat/kinect/depth_stream_parser.hpp"
#include "tofmat/kinect/raw_unpack.hpp"

namespace tofmat::sim {

using kinect::UsbError;
using kinect::UsbErrorKind;

namespace {

// The 11-bit code of every 16-bit raw value (raw_code_nearest, 32767 the
// saturation code), tabulated once: a frame has 9 x 217,088 samples, and a
// binary search per sample cost more than rendering them.
const std::vector<std::uint16_t>& code_of_raw() {
  static const std::vector<std::uint16_t> table = [] {
    std::vector<std::uint16_t> t(65536);
    for (int v = -32768; v <= 32767; ++v)
      t[static_cast<std::size_t>(v + 32768)] =
          v == kRawSaturated ? kRawSaturationCode : raw_code_nearest(static_cast<double>(v));
    return t;
  }();
  return table;
}

constexpr std::uint32_t kTicksPerFrame = 333;  // footer timestamps: ~0.1 ms units at 30 frames/s
constexpr auto kFramePeriod = std::chrono::microseconds(33333);
constexpr std::size_t kTruthKept = 16;
}  // namespace

// The handle a driver holds: forwards to the device while it is plugged in.
class SimulatedKinectTransport : public kinect::UsbTransport {
 public:
  explicit SimulatedKinectTransport(std::shared_ptr<SimulatedKinect> d) : dev_(std::move(d)) {}
  ~SimulatedKinectTransport() override {
    std::lock_guard<std::mutex> lock(dev_->mutex_);
    dev_->held_ = false;
    dev_->streaming_ = false;
  }

  std::string describe() const override { return "simulated Kinect v2 (serial SIM000000001)"; }
  bool connected() const override { return dev_->plugged(); }

  void control(std::uint8_t, std::uint8_t, std::uint16_t, std::uint16_t, unsigned) override { check(); }

  void set_interface_alt(int interface, int alt) override {
    check();
    if (interface != kinect::kDepthInterface || (alt != 0 && alt != 1)) {
      throw UsbError(UsbErrorKind::kIo,
                     "simulated device: no interface " + std::to_string(interface) + " alt " + std::to_string(alt));
    }
    std::lock_guard<std::mutex> lock(dev_->mutex_);
    dev_->alt_ = alt;
    if (alt == 0) dev_->streaming_ = false;
  }

  std::size_t bulk_write(std::uint8_t endpoint, const std::uint8_t* data, std::size_t size, unsigned) override {
    check();
    if (endpoint != kinect::kCommandOutEndpoint) throw UsbError(UsbErrorKind::kIo, "simulated device: no OUT endpoint");
    dev_->respond(data, size);
    return size;
  }

  std::size_t bulk_read(std::uint8_t endpoint, std::uint8_t* data, std::size_t capacity, unsigned) override {
    check();
    if (endpoint != kinect::kResponseInEndpoint) throw UsbError(UsbErrorKind::kIo, "simulated device: no IN endpoint");
    std::lock_guard<std::mutex> lock(dev_->mutex_);
    if (dev_->replies_.empty()) throw UsbError(UsbErrorKind::kTimeout, "simulated device: no response");
    auto r = std::move(dev_->replies_.front());
    dev_->replies_.pop_front();
    // A bulk IN longer than the buffer is an overflow on a real bus.
    if (r.size() > capacity) throw UsbError(UsbErrorKind::kIo, "simulated device: response overflows the buffer");
    std::memcpy(data, r.data(), r.size());
    return r.size();
  }

  std::size_t iso_packet_size(std::uint8_t) override {
    check();
    return dev_->iso_bytes_;
  }

  void start_iso(std::uint8_t endpoint, int, int, kinect::IsoPacketHandler on_packet) override {
    check();
    if (endpoint != kinect::kDepthIsoEndpoint) throw UsbError(UsbErrorKind::kIo, "simulated device: no iso endpoint");
    handler_ = std::move(on_packet);
    next_frame_ = std::chrono::steady_clock::now();
  }

  void stop_iso() override { handler_ = nullptr; }

  void handle_events(unsigned timeout_ms) override {
    check();
    bool stream;
    {
      std::lock_guard<std::mutex> lock(dev_->mutex_);
      stream = dev_->streaming_ && dev_->alt_ == 1;
    }
    if (!handler_ || !stream) {
      if (dev_->realtime_) std::this_thread::sleep_for(std::chrono::milliseconds(timeout_ms));
      return;
    }
    if (dev_->realtime_) {
      const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
      if (next_frame_ > deadline) {
        std::this_thread::sleep_until(deadline);
        return;
      }
      std::this_thread::sleep_until(next_frame_);
      next_frame_ += kFramePeriod;
      // Fell behind (slow rendering): the device does not wait, frames are lost.
      const auto now = std::chrono::steady_clock::now();
      if (next_frame_ < now) next_frame_ = now;
    }
    dev_->emit_frame(handler_);
  }

 private:
  void check() const {
    if (!dev_->plugged()) throw UsbError(UsbErrorKind::kDisconnected, "simulated Kinect v2 was unplugged");
  }
  std::shared_ptr<SimulatedKinect> dev_;
  kinect::IsoPacketHandler handler_;
  std::chrono::steady_clock::time_point next_frame_;
};

SimulatedKinect::SimulatedKinect(std::shared_ptr<const Renderer> renderer, SceneAt scene, bool realtime,
                                 std::size_t iso_packet_bytes)
    : renderer_(std::move(renderer)), scene_(std::move(scene)), realtime_(realtime), iso_bytes_(iso_packet_bytes) {
  if (!renderer_ || !scene_) throw std::invalid_argument("SimulatedKinect needs a renderer and a scene");
  const auto& cam = renderer_->device().camera;
  if (cam.width != kinect::kWidth || cam.height != kinect::kHeight) {
    throw std::invalid_argument("SimulatedKinect: the device profile's camera must be 512 x 424");
  }
  if (iso_bytes_ < 1 || iso_bytes_ > kinect::kSubPacketBytes || kinect::kSubPacketBytes % iso_bytes_ == 0) {
    throw std::invalid_argument("SimulatedKinect: iso packet size must be 1..298648 bytes and not divide 298648");
  }
  // The P0 tables the device reports: its own per-pixel phase and decode offsets.
  kinect::P0Tables t;
  for (int g = 0; g < 3; ++g) {
    const auto p0 = renderer_->p0_table(g);
    auto& raw = t.raw[static_cast<std::size_t>(g)];
    raw.resize(p0.size());
    for (std::size_t i = 0; i < p0.size(); ++i) raw[i] = kinect::p0_table_value(p0[i]);
  }
  p0_response_ = kinect::encode_p0_tables(t);
}

std::unique_ptr<kinect::UsbTransport> SimulatedKinect::connect() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!plugged_) throw UsbError(UsbErrorKind::kNoDevice, "no Kinect v2 found (the simulated one is unplugged)");
  if (held_) throw UsbError(UsbErrorKind::kBusy, "the simulated Kinect v2 is in use by another driver");
  held_ = true;
  replies_.clear();
  status_polls_ = 0;
  streaming_ = false;
  alt_ = 0;
  return std::make_unique<SimulatedKinectTransport>(shared_from_this());
}

void SimulatedKinect::set_faults(const KinectFaults& f) {
  std::lock_guard<std::mutex> lock(mutex_);
  faults_ = f;
  rng_.seed(f.seed);
}

void SimulatedKinect::unplug() {
  std::lock_guard<std::mutex> lock(mutex_);
  plugged_ = false;
  streaming_ = false;
}

void SimulatedKinect::replug() {
  std::lock_guard<std::mutex> lock(mutex_);
  plugged_ = true;
}

bool SimulatedKinect::plugged() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return plugged_;
}

KinectSimCounters SimulatedKinect::counters() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return counters_;
}

std::vector<kinect::DecodedCommand> SimulatedKinect::command_log() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return {command_log_.begin(), command_log_.end()};
}

std::shared_ptr<const Frame> SimulatedKinect::truth(std::uint32_t sequence) const {
  std::lock_guard<std::mutex> lock(mutex_);
  for (const auto& [seq, f] : truth_) {
    if (seq == sequence) return f;
  }
  return nullptr;
}

void SimulatedKinect::respond(const std::uint8_t* data, std::size_t size) {
  kinect::DecodedCommand c;
  try {
    c = kinect::decode_command(data, size);
  } catch (const FormatError& e) {
    throw UsbError(UsbErrorKind::kStall, std::string("simulated device stalls on a malformed command: ") + e.what());
  }
  std::vector<std::uint8_t> r;
  using kinect::CommandId;
  const auto param = [&](std::size_t k) { return k < c.params.size() ? c.params[k] : 0u; };
  switch (static_cast<CommandId>(c.id)) {
    case CommandId::kReadFirmwareVersions: {
      ByteWriter w;  // seven records {maj_min, revision, build, reserved}; record 3 names the firmware
      for (std::uint32_t k = 0; k < 7; ++k) {
        w.u32((2u << 16) | k);
        w.u32(100 + k);
        w.u32(2000 + k);
        w.u32(0);
      }
      r = w.take();
      break;
    }
    case CommandId::kReadHardwareInfo: r.assign(0x5C, 0); break;
    case CommandId::kReadDataPage:
      if (param(0) == kinect::kPageSerial) {
        for (char ch : std::string("SIM000000001")) {
          r.push_back(static_cast<std::uint8_t>(ch));
          r.push_back(0);
        }
        r.push_back(0);
        r.push_back(0);
      } else if (param(0) == kinect::kPageDepthParams) {
        const auto& cam = renderer_->device().camera;
        kinect::DepthParams p;
        p.fx = static_cast<float>(cam.fx);
        p.fy = static_cast<float>(cam.fy);
        p.cx = static_cast<float>(cam.cx);
        p.cy = static_cast<float>(cam.cy);
        r = kinect::encode_depth_params(p);
      } else if (param(0) == kinect::kPageP0Tables) {
        r = p0_response_;
      } else {
        r.assign(64, 0);  // colour parameters: not modelled
      }
      break;
    case CommandId::kReadStatus: {
      std::lock_guard<std::mutex> lock(mutex_);
      // Ready from the second poll on, as a device warming up.
      const std::uint32_t ready = status_polls_++ > 0 ? 1u : 0u;
      r = {static_cast<std::uint8_t>(ready), 0, 0, 0};
      break;
    }
    case CommandId::kSetStreaming: {
      std::lock_guard<std::mutex> lock(mutex_);
      streaming_ = param(0) == 1 && alt_ == 1;
      break;
    }
    case CommandId::kStop: {
      std::lock_guard<std::mutex> lock(mutex_);
      streaming_ = false;
      break;
    }
    default: break;
  }
  if (r.size() > c.max_response) r.resize(c.max_response);
  std::lock_guard<std::mutex> lock(mutex_);
  ++counters_.commands;
  command_log_.push_back(c);
  if (command_log_.size() > kCommandLogSize) command_log_.pop_front();
  if (faults_.lost_responses > 0) {
    --faults_.lost_responses;
    return;
  }
  if (c.max_response > 0) replies_.push_back(r);
  replies_.push_back(kinect::encode_completion(c.sequence));
}

void SimulatedKinect::deliver(const std::uint8_t* data, std::size_t size, const kinect::IsoPacketHandler& handler) {
  // Decide the packet's faults under the lock; hand packets on outside it.
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  bool drop = false, dup = false;
  std::vector<std::uint8_t> junk;
  std::size_t n = size;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const KinectFaults& f = faults_;
    drop = f.drop > 0.0 && u01(rng_) < f.drop;
    if (drop) {
      ++counters_.dropped;
      return;
    }
    if (f.garbage > 0.0 && u01(rng_) < f.garbage) {
      junk.resize(1 + rng_() % iso_bytes_);
      for (auto& b : junk) b = static_cast<std::uint8_t>(rng_());
      ++counters_.garbage;
      ++counters_.packets;
    }
    if (f.truncate > 0.0 && size > 1 && u01(rng_) < f.truncate) {
      n = 1 + rng_() % (size - 1);
      ++counters_.truncated;
    }
    dup = f.duplicate > 0.0 && u01(rng_) < f.duplicate;
    counters_.packets += dup ? 2 : 1;
    counters_.duplicated += dup ? 1 : 0;
  }
  if (!junk.empty()) handler(junk.data(), junk.size());
  handler(data, n);
  if (dup) handler(data, n);
}

void SimulatedKinect::emit_frame(const kinect::IsoPacketHandler& handler) {
  const std::uint64_t index = frame_index_++;
  KinectFaults f;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    f = faults_;
  }
  if (f.stall_at_frame >= 0 && index >= static_cast<std::uint64_t>(f.stall_at_frame) &&
      index < static_cast<std::uint64_t>(f.stall_at_frame) + static_cast<std::uint64_t>(f.stall_frames)) {
    std::lock_guard<std::mutex> lock(mutex_);
    ++counters_.stalled_frames;  // the endpoint sends nothing
    return;
  }
  auto frame = std::make_shared<Frame>(renderer_->render(scene_(index), index + 1));
  const auto seq = static_cast<std::uint32_t>(index);
  {
    // The truth is known before the first packet leaves: the driver hands
    // the frame on from inside the last packet's delivery.
    std::lock_guard<std::mutex> lock(mutex_);
    truth_.emplace_back(seq, frame);
    if (truth_.size() > kTruthKept) truth_.pop_front();
  }
  // Raw values to 11-bit codes, packed per sub-image; the tenth is unused.
  std::vector<std::uint16_t> codes(kinect::kPixels);
  std::vector<std::uint8_t> sub(kinect::kSubImageBytes);
  const bool unplug_now = f.unplug_at_frame >= 0 && index == static_cast<std::uint64_t>(f.unplug_at_frame);
  for (int s = 0; s < kinect::kSubImages; ++s) {
    if (s < kinect::kUsedSubImages) {
      const std::int16_t* raw = frame->raw.data() + static_cast<std::size_t>(s) * kinect::kPixels;
      const std::uint16_t* code = code_of_raw().data() + 32768;
      for (std::size_t i = 0; i < kinect::kPixels; ++i) codes[i] = code[raw[i]];
    } else {
      std::fill(codes.begin(), codes.end(), std::uint16_t{0});
    }
    kinect::pack_codes(codes.data(), sub.data());
    const auto sp = kinect::encode_sub_packet(sub.data(), seq, static_cast<std::uint32_t>(s),
                                              static_cast<std::uint32_t>(index * kTicksPerFrame));
    for (std::size_t off = 0; off < sp.size(); off += iso_bytes_) {
      if (unplug_now && s == kinect::kSubImages / 2) {
        unplug();
        throw UsbError(UsbErrorKind::kDisconnected, "simulated Kinect v2 was unplugged");
      }
      deliver(sp.data() + off, std::min(iso_bytes_, sp.size() - off), handler);
    }
  }
  std::lock_guard<std::mutex> lock(mutex_);
  ++counters_.frames;
}

}  // namespace tofmat::sim
