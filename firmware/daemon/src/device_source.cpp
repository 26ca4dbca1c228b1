// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// DeviceSource: opens the Kinect v2 through the driver, streams its frames, and reopens it after it goes away.
#include "tofmat/daemon/device_source.hpp"

#include <chrono>
#include <thread>

#include "tofmat/daemon/log.hpp"
#include "tofmat/kinect/device.hpp"
#include "tofmat/kinect/raw_unpack.hpp"
#include "tofmat/protocol/socket.hpp"

namespace tofmat::daemon {

const char* device_state_name(DeviceState s) {
  switch (s) {
    case DeviceState::kOpening: return "opening";
    case DeviceState::kStreaming: return "streaming";
    case DeviceState::kDisconnected: return "disconnected";
    case DeviceState::kStopped: return "stopped";
    case DeviceState::kFailed: return "failed";
  }
  return "unknown";
}

DeviceSource::DeviceSource(std::string description, OpenTransport open, TruthOf truth, int retry_ms, bool simulated)
    : description_(std::move(description)),
      open_(std::move(open)),
      truth_(std::move(truth)),
      retry_ms_(retry_ms),
      simulated_(simulated) {}

void DeviceSource::stream(const SourceCallbacks& callbacks, const std::atomic<bool>& stop) {
  callbacks.state(DeviceState::kOpening, "opening " + description_);
  // (A stop is not held up by retries, status polls or late completions.)
  kinect::DriverOptions driver;
  driver.cancel = &stop;
  kinect::Kinect2Device device(open_(), driver);
  device.open();
  std::shared_ptr<const Calibration> calibration;
  const auto& identity = device.start([&](const kinect::DepthPacket& packet) {
    RawFrame f;
    f.sequence = packet.sequence;
    f.arrival_ns = protocol::monotonic_ns();
    // Only the pixels the profile reads (docs/daemon.md): a region of
    // interest, the whole frame, or nothing at all between sorting bursts.
    const std::optional<PixelRegion> wanted =
        callbacks.region ? callbacks.region() : std::optional<PixelRegion>(PixelRegion{0, 0, kWidth, kHeight});
    if (wanted && !region_empty(*wanted)) {
      f.raw = callbacks.raw_buffer ? callbacks.raw_buffer() : std::vector<std::int16_t>(9 * kPixels);
      f.raw.resize(9 * kPixels);
      kinect::unpack_depth_packet_region(packet.data, f.raw.data(), *wanted);
      f.region = *wanted;
    } else {
      f.region = PixelRegion{0, 0, 0, 0};
    }
    f.calibration = calibration;
    f.simulated = simulated_;
    if (truth_) f.truth = truth_(packet.sequence);
    {
      std::lock_guard<std::mutex> lock(mutex_);
      ++frames_;
    }
    callbacks.frame(std::move(f));
  });
  // Frames arrive only from pump(): the calibration is in place before the first.
  calibration = std::make_shared<const Calibration>(identity.p0.p0_rad(), identity.depth);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ++opens_;
  }
  callbacks.state(DeviceState::kStreaming, "streaming from " + device.describe() + " (serial " + identity.serial +
                                               ", firmware " + identity.firmware + ")");
  while (!stop.load()) {
    device.pump(100);
    std::lock_guard<std::mutex> lock(mutex_);
    driver_skipped_ = device.stream_counters().incomplete_frames;
  }
  device.stop();
  device.close();
}

void DeviceSource::run(const SourceCallbacks& callbacks, const std::atomic<bool>& stop) {
  std::string reported;
  while (!stop.load()) {
    try {
      stream(callbacks, stop);
    } catch (const kinect::UsbError& e) {
      if (stop.load()) break;  // (cancelled, or failed on the way out: not a device problem)
      const std::string message = std::string(kinect::usb_error_kind_name(e.kind())) + ": " + e.what();
      {
        std::lock_guard<std::mutex> lock(mutex_);
        last_error_ = message;
        if (e.kind() == kinect::UsbErrorKind::kDisconnected) ++disconnects_;
      }
      // Say it once per distinct problem (a missing camera is retried quietly).
      if (message != reported) {
        logger(LogCategory::kKinect).warn("{}: {}; retrying every {} ms", description_, message, retry_ms_);
        reported = message;
      }
      callbacks.state(DeviceState::kDisconnected, message);
      const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(retry_ms_);
      while (!stop.load() && std::chrono::steady_clock::now() < until)
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
      continue;
    }
    reported.clear();
  }
  callbacks.state(DeviceState::kStopped, "stopped");
}

nlohmann::json DeviceSource::counters() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return {{"frames", frames_},
          {"opens", opens_},
          {"disconnects", disconnects_},
          {"incomplete_frames", driver_skipped_},
          {"last_error", last_error_}};
}

}  // namespace tofmat::daemon
