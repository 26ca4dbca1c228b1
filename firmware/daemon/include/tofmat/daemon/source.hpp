// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Frame sources of tofmatd: `kinect` (the libusb driver), `sim[:SCENE]` (the
// simulated Kinect v2 on the same USB transport and driver) and
// `replay:FILE` (a recording made by `tofmat record`). A source runs on the
// daemon's USB/event thread; it survives the device going away: it reports
// the state, waits, and opens the device again.
#pragma once
#include <atomic>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tofmat/daemon/frame.hpp"

namespace tofmat::gpio {
class SimGpio;
}

namespace tofmat::daemon {

// kFailed: the source stopped on an error it cannot recover from (a corrupt
// recording); the daemon keeps serving status, without frames.
enum class DeviceState { kOpening, kStreaming, kDisconnected, kStopped, kFailed };
const char* device_state_name(DeviceState s);

struct SourceCallbacks {
  std::function<void(RawFrame&&)> frame;
  std::function<void(DeviceState, const std::string& message)> state;
  // Which pixels a camera source unpacks from the next packet: nothing
  // returned means none (the profile does not need the frame); no function
  // means the whole frame (recording).
  std::function<std::optional<PixelRegion>()> region;
  // A 9 x kPixels buffer for a frame's samples, recycled by the pipeline (no
  // function: a new one each frame).
  std::function<std::vector<std::int16_t>()> raw_buffer;
};

class Source {
 public:
  virtual ~Source() = default;
  virtual std::string describe() const = 0;
  // Runs until `stop` is set (or the source is exhausted: a replay's end).
  // Reports every state change; never throws for a device problem.
  virtual void run(const SourceCallbacks& callbacks, const std::atomic<bool>& stop) = 0;
  // Counters for status (frames, reconnects, ...).
  virtual nlohmann::json counters() const = 0;
  // True when the frames are not a camera's: the simulator, or a recording of
  // it. The daemon says so in every label and in status.
  virtual bool simulated() const = 0;
  // True when no frame may be dropped: the daemon then waits for the
  // pipeline instead of dropping the oldest frame (a replay with pace=0).
  virtual bool lossless() const { return false; }
  // A simulated belt only: the real material of the item whose leading edge
  // crossed the light barrier at `edge_ns` (CLOCK_MONOTONIC), so that a
  // sorting decision's truth travels with its item rather than being read off
  // whatever frame its burst ended on (on a loaded machine, often the gap
  // after it). Nothing for every other source.
  virtual std::optional<std::string> item_truth(std::uint64_t /*edge_ns*/) const { return std::nullopt; }
};

struct SourceOptions {
  std::string sim_data_dir;  // device profiles and material libraries of the simulator ("" = not installed)
  int retry_ms = 500;        // wait between attempts to open a device that is gone
  // The simulated chip a simulated belt (sim:belt) drives its light barrier
  // on (tofmatd --gpio sim); null: the belt drives no GPIO.
  std::shared_ptr<gpio::SimGpio> sim_gpio;
};

// "kinect[:SERIAL]", "sim[:SCENE[,key=value...]]", "replay:FILE[,loop=1][,pace=0]".
// Throws std::invalid_argument with what is wrong with the spec.
std::unique_ptr<Source> make_source(const std::string& spec, const SourceOptions& options);

}  // namespace tofmat::daemon
