// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// A simulated Kinect v2 on the USB transport the driver talks to: it answers
// the command protocol (firmware versions, serial, depth intrinsics from the
// device profile's camera, P0 tables of the renderer's per-pixel phase) and,
// once streaming, renders frames with the simulator and emits them as the
// device does: nine sub-images packed in the 11-bit layout plus the unused
// tenth, each with its footer, cut into isochronous packets. Faults can be
// injected on the way: dropped, duplicated, truncated and garbage packets, a
// stalled endpoint, unplug mid-stream and replug.
#pragma once

#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <random>
#include <vector>

#include "tofmat/kinect/command.hpp"
#include "tofmat/kinect/transport.hpp"
#include "tofmat/sim/renderer.hpp"

namespace tofmat::sim {

struct KinectFaults {
  // Probabilities per iso packet (independent draws, seeded).
  double drop = 0.0, duplicate = 0.0, truncate = 0.0, garbage = 0.0;
  std::uint64_t seed = 1;
  // Frame index at which the endpoint stalls for stall_frames frames (-1: never).
  std::int64_t stall_at_frame = -1;
  int stall_frames = 0;
  // Frame index in the middle of which the device is unplugged (-1: never).
  std::int64_t unplug_at_frame = -1;
  // The next n command responses are never sent (the driver times out).
  int lost_responses = 0;
};

struct KinectSimCounters {
  std::uint64_t frames = 0;   // rendered and sent
  std::uint64_t packets = 0;  // iso packets handed to the driver
  std::uint64_t dropped = 0, duplicated = 0, truncated = 0, garbage = 0, stalled_frames = 0;
  std::uint64_t commands = 0;
};

class SimulatedKinect : public std::enable_shared_from_this<SimulatedKinect> {
 public:
  using SceneAt = std::function<Scene(std::uint64_t frame_index)>;

  // realtime: frames at 30 per second (handle_events waits for the next
  // one); otherwise one frame per handle_events call, as fast as rendering.
  SimulatedKinect(std::shared_ptr<const Renderer> renderer, SceneAt scene, bool realtime = false,
                  std::size_t iso_packet_bytes = 0x8400);

  // A transport to the device, like opening it on the bus. Throws
  // UsbError(kNoDevice) while unplugged, kBusy while another transport holds it.
  std::unique_ptr<kinect::UsbTransport> connect();

  void set_faults(const KinectFaults& f);
  void unplug();
  void replug();
  bool plugged() const;

  KinectSimCounters counters() const;
  // The commands received, oldest first (the last kCommandLogSize are kept):
  // what a test compares with the protocol's start, stop and close sequences.
  static constexpr std::size_t kCommandLogSize = 256;
  std::vector<kinect::DecodedCommand> command_log() const;
  // Ground truth of a frame sent (the last 16 are kept): nullptr if unknown.
  std::shared_ptr<const Frame> truth(std::uint32_t sequence) const;
  const Renderer& renderer() const { return *renderer_; }

 private:
  friend class SimulatedKinectTransport;
  void respond(const std::uint8_t* data, std::size_t size);  // command -> queued replies
  void emit_frame(const kinect::IsoPacketHandler& handler);
  void deliver(const std::uint8_t* data, std::size_t size, const kinect::IsoPacketHandler& handler);

  std::shared_ptr<const Renderer> renderer_;
  SceneAt scene_;
  bool realtime_;
  std::size_t iso_bytes_;
  mutable std::mutex mutex_;
  bool plugged_ = true, held_ = false;
  int status_polls_ = 0;
  std::deque<std::vector<std::uint8_t>> replies_;
  std::deque<kinect::DecodedCommand> command_log_;
  KinectFaults faults_;
  std::mt19937_64 rng_;
  KinectSimCounters counters_;
  std::uint64_t frame_index_ = 0;
  std::vector<std::uint8_t> p0_response_;
  std::deque<std::pair<std::uint32_t, std::shared_ptr<const Frame>>> truth_;
  bool streaming_ = false;  // SetStreaming(1) received and the depth interface at alt 1
  int alt_ = 0;
};

}  // namespace tofmat::sim
