// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The Kinect v2 driver: the open/start/stop/close sequences and command
// transactions of kinect2-protocol.md 1.3-1.7 over any UsbTransport, and the
// depth stream reassembled by DepthStreamParser. The caller's thread runs the
// transport's events with pump() (the daemon's USB thread); frames are handed
// to the frame handler from inside pump().
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "tofmat/kinect/command.hpp"
#include "tofmat/kinect/depth_stream_parser.hpp"
#include "tofmat/kinect/transport.hpp"

namespace tofmat::kinect {

struct DriverOptions {
  unsigned timeout_ms = kTimeoutMs;  // per transfer
  int retries = 2;                   // extra attempts of a command that timed out
  int status_polls = 50;             // ReadStatus polls before giving up (100 ms apart)
  unsigned status_poll_ms = 100;
  int iso_transfers = kIsoTransfers;
  int iso_packets = kIsoPacketsPerTransfer;
  // Set (the daemon stopping): no command is tried again, no more status
  // polls or late completions are waited for; the sequence ends with a
  // UsbError(kCancelled) after at most the transfer under way (timeout_ms).
  const std::atomic<bool>* cancel = nullptr;
};

// What the start-up sequence read from the device.
struct DeviceIdentity {
  std::string serial;
  std::string firmware;  // record 3 of ReadFirmwareVersions, "maj.min.rev.build"
  DepthParams depth;
  P0Tables p0;
};

struct DriverCounters {
  std::uint64_t commands = 0;
  std::uint64_t retries = 0;            // commands sent again after a timeout
  std::uint64_t stale_completions = 0;  // completions of earlier (timed-out) commands skipped
};

class Kinect2Device {
 public:
  using FrameHandler = std::function<void(const DepthPacket&)>;

  Kinect2Device(std::unique_ptr<UsbTransport> transport, DriverOptions options = {});
  ~Kinect2Device();  // closes (errors on the way out are swallowed: the device may be gone)
  Kinect2Device(const Kinect2Device&) = delete;
  Kinect2Device& operator=(const Kinect2Device&) = delete;

  // 1.3 (after the transport has opened, configured and claimed): isoch
  // delay, depth interface off, U1/U2, function suspend; checks the iso
  // packet size. Throws UsbError.
  void open();
  // 1.7 start: reads firmware, serial, depth parameters and P0 tables, waits
  // for the device to be ready, starts the depth stream.
  const DeviceIdentity& start(FrameHandler on_frame);
  // Runs transport events for up to timeout_ms; frames arrive in on_frame.
  // Throws UsbError(kDisconnected) on unplug.
  void pump(unsigned timeout_ms);
  void stop();
  void close();

  bool streaming() const { return streaming_; }
  const DeviceIdentity& identity() const { return identity_; }
  const DriverCounters& counters() const { return counters_; }
  DepthStreamCounters stream_counters() const;
  std::string describe() const { return transport_->describe(); }
  bool connected() const { return transport_->connected(); }

  // One command transaction (1.5): write, optional response, completion.
  // Retries a timed-out command with a new sequence number; skips stale
  // completions. Throws UsbError.
  std::vector<std::uint8_t> transact(const Command& command);

 private:
  void check_cancel() const;  // throws UsbError(kCancelled) once options_.cancel is set
  void wait_until_ready();
  std::unique_ptr<UsbTransport> transport_;
  DriverOptions options_;
  std::uint32_t next_sequence_ = 0;
  bool opened_ = false, streaming_ = false;
  DeviceIdentity identity_;
  DriverCounters counters_;
  std::unique_ptr<DepthStreamParser> parser_;
  std::vector<std::uint8_t> late_;  // completion reads (kMaxResponseBytes: late responses fit)
};

}  // namespace tofmat::kinect
