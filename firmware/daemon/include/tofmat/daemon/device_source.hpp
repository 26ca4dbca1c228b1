// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// A Kinect v2 behind any USB transport, through the driver: the real camera
// (libusb) and the simulated one share this code, so the daemon's path from
// USB bytes to labels is the same for both.
#pragma once
#include <mutex>

#include "tofmat/daemon/source.hpp"
#include "tofmat/kinect/transport.hpp"

namespace tofmat::daemon {

class DeviceSource : public Source {
 public:
  using OpenTransport = std::function<std::unique_ptr<kinect::UsbTransport>()>;
  // Ground truth of a frame sent, for a simulated device (may be empty).
  using TruthOf = std::function<std::shared_ptr<const FrameTruth>(std::uint32_t sequence)>;
  // `simulated`: the transport is the simulated Kinect (frames are marked so).
  DeviceSource(std::string description, OpenTransport open, TruthOf truth, int retry_ms, bool simulated);
  std::string describe() const override { return description_; }
  bool simulated() const override { return simulated_; }
  void run(const SourceCallbacks& callbacks, const std::atomic<bool>& stop) override;
  nlohmann::json counters() const override;

 private:
  void stream(const SourceCallbacks& callbacks, const std::atomic<bool>& stop);
  std::string description_;
  OpenTransport open_;
  TruthOf truth_;
  int retry_ms_;
  bool simulated_;
  mutable std::mutex mutex_;
  std::uint64_t frames_ = 0, opens_ = 0, disconnects_ = 0, driver_skipped_ = 0;
  std::string last_error_;
};

}  // namespace tofmat::daemon
