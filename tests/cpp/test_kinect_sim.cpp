// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// End to end: the simulated Kinect v2 (firmware/sim/kinect_device) -> USB
// transport -> driver (firmware/kinect/device) -> stream parser -> 11-bit
// unpack -> float decode, with and without every kind of fault.
#include <gtest/gtest.h>

#include <atomic>

#include <cmath>
#include <cstring>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "tofmat/core/decode.hpp"
#include "tofmat/core/frame_decode.hpp"
#include "tofmat/kinect/device.hpp"
#include "tofmat/kinect/raw_unpack.hpp"
#include "tofmat/sim/kinect_device.hpp"

namespace {

using namespace tofmat;
using namespace tofmat::sim;
using kinect::Kinect2Device;
using kinect::UsbError;
using kinect::UsbErrorKind;

constexpr double kCDevOverTrue = 300.0 / 299.792458;

MaterialLibrary library() {
  MaterialLibrary lib;
  lib.name = "lib";
  Material white;
  white.name = "white";
  white.albedo = 0.9;
  Material wax;
  wax.name = "wax";
  wax.kind = ResponseKind::kExponential;
  wax.albedo = 0.6;
  wax.subsurface = 0.6;
  wax.tau_ps = 300.0;
  lib.materials = {white, wax};
  return lib;
}

std::shared_ptr<const Renderer> renderer() {
  DeviceProfile d = DeviceProfile::ideal_kinect2();
  d.noise.read_noise = 3.0;
  d.noise.shot_gain = 0.03;
  d.noise.ambient = 100.0;
  d.pixel_phase.mean_rad = {0.4, -0.3, 1.1};
  d.pixel_phase.radial_rad = {0.05, 0.02, 0.08};
  d.pixel_phase.scatter_rad = 0.01;
  d.groups[0].decode_offset_rad = 0.02;
  return std::make_shared<const Renderer>(d, library());
}

// The white target at (x0, y0)-(x1, y1) and the wax one right of it, on a white wall.
Scene two_targets(double white_mm, double wax_mm, double wax_yaw_deg, int x0, int y0, int x1, int y1, int wax_x0,
                  int wax_x1, double wall_mm) {
  Scene s;
  Target a;
  a.material = "white";
  a.depth_mm = white_mm;
  a.x0 = x0;
  a.y0 = y0;
  a.x1 = x1;
  a.y1 = y1;
  Target b = a;
  b.material = "wax";
  b.depth_mm = wax_mm;
  b.yaw_deg = wax_yaw_deg;
  b.x0 = wax_x0;
  b.x1 = wax_x1;
  s.targets = {a, b};
  s.background_material = "white";
  s.background_depth_mm = wall_mm;
  return s;
}

// Two targets at different depths on a wall, moving 10 mm per frame.
Scene scene_at(std::uint64_t k) {
  const double step = 10.0 * static_cast<double>(k);
  return two_targets(700.0 + step, 1100.0 - step, 20.0, 100, 100, 240, 300, 280, 420, 2500.0);
}

struct Received {
  std::uint32_t sequence;
  std::vector<std::int16_t> raw;  // 9 x pixels
};

struct Rig {
  explicit Rig(SimulatedKinect::SceneAt scene = scene_at)
      : sim(std::make_shared<SimulatedKinect>(renderer(), std::move(scene))) {}
  std::shared_ptr<SimulatedKinect> sim;
  std::unique_ptr<Kinect2Device> dev;
  std::vector<Received> frames;

  void start(kinect::DriverOptions o = {}) {
    o.status_poll_ms = 1;
    dev = std::make_unique<Kinect2Device>(sim->connect(), o);
    dev->open();
    dev->start([this](const kinect::DepthPacket& p) {
      Received r{p.sequence, std::vector<std::int16_t>(9 * kinect::kPixels)};
      kinect::unpack_depth_packet(p.data, r.raw.data());
      frames.push_back(std::move(r));
    });
  }
  void pump(int n) {
    for (int k = 0; k < n; ++k) dev->pump(10);
  }
};

// The device path delivers the renderer's raw values exactly (columns 0 and
// 511 read 0 on the real device too).
void expect_exact(const Received& r, const Frame& truth) {
  for (std::size_t s = 0; s < 9; ++s) {
    for (std::size_t i = 0; i < kinect::kPixels; ++i) {
      const std::size_t x = i % kinect::kWidth;
      const std::int16_t want =
          (x == 0 || x == kinect::kWidth - 1) ? std::int16_t{0} : truth.raw[s * kinect::kPixels + i];
      ASSERT_EQ(r.raw[s * kinect::kPixels + i], want) << "frame " << r.sequence << " sub-image " << s << " pixel " << i;
    }
  }
}

TEST(KinectSim, StartUpReadsTheDevicesIdentityAndTables) {
  Rig rig;
  rig.start();
  const auto& id = rig.dev->identity();
  EXPECT_EQ(id.serial, "SIM000000001");
  EXPECT_EQ(id.firmware, "2.3.103.2003");
  EXPECT_FLOAT_EQ(id.depth.fx, 365.0f);
  EXPECT_FLOAT_EQ(id.depth.cy, 212.0f);
  // The P0 tables carry -(pixel phase + decode offset) within half a table step.
  const auto p0 = id.p0.p0_rad();
  for (int g = 0; g < 3; ++g) {
    const auto want = rig.sim->renderer().p0_table(g);
    for (std::size_t i = 0; i < want.size(); i += 1013) {
      const double diff =
          std::remainder(static_cast<double>(p0[static_cast<std::size_t>(g) * want.size() + i]) - want[i], 2.0 * M_PI);
      ASSERT_LT(std::fabs(diff), 0.5 * kinect::kP0RadPerUnit + 1e-6) << g << " " << i;
    }
  }
  EXPECT_TRUE(rig.dev->streaming());
  EXPECT_TRUE(rig.dev->connected());
  EXPECT_EQ(rig.dev->counters().retries, 0u);
}

TEST(KinectSim, EndToEndDepthsMatchTheSimulationWithinTheNoiseBudget) {
  Rig rig;
  rig.start();
  rig.pump(4);
  ASSERT_EQ(rig.frames.size(), 4u);
  const auto p0 = rig.dev->identity().p0.p0_rad();
  for (const auto& r : rig.frames) {
    const auto truth = rig.sim->truth(r.sequence);
    ASSERT_TRUE(truth);
    expect_exact(r, *truth);
    const auto d = decode_frame(r.raw.data(), kinect::kPixels, p0);
    // Per target: mean combined depth against the true range, and the
    // per-frequency spread (noise) within the budget of this noise model.
    std::map<int, std::pair<double, int>> err;
    for (std::size_t i = 0; i < kinect::kPixels; ++i) {
      const int t = truth->target[i];
      if (t < 0 || d.flags[i]) continue;
      const double want = truth->range_mm[i] * kCDevOverTrue;
      auto& e = err[t];
      e.first += d.combined_mm[i] - want;
      ++e.second;
      if (t == 0) {
        ASSERT_LT(std::fabs(d.combined_mm[i] - want), 10.0) << i;  // opaque: noise only (~1 mm sd)
      }
    }
    ASSERT_EQ(err.size(), 2u);
    // The profile's 80 MHz decode offset (a P0 calibration residual of 0.02
    // rad) moves d80 by 0.02 / 2 pi * 1875 mm, the combined depth by 80/216 of it.
    const double offset = 80.0 / 216.0 * 0.02 / (2.0 * M_PI) * 1875.0;
    EXPECT_NEAR(err[0].first / err[0].second, offset, 0.2) << "opaque target, frame " << r.sequence;
    // The subsurface target is pushed back by its response (the paper's effect): 10..60 mm.
    const double wax_shift = err[1].first / err[1].second;
    EXPECT_GT(wax_shift, 10.0);
    EXPECT_LT(wax_shift, 60.0);
  }
  const auto c = rig.dev->stream_counters();
  EXPECT_EQ(c.frames, 4u);
  EXPECT_EQ(c.broken_sub_images + c.bad_footers + c.incomplete_frames, 0u);
}

// Each fault kind: the stream goes on, every frame passed on is exact, the
// counters say what happened.
void run_with(const KinectFaults& f, const char* what) {
  Rig rig;
  rig.sim->set_faults(f);
  rig.start();
  rig.pump(12);
  const auto sc = rig.sim->counters();
  const auto dc = rig.dev->stream_counters();
  EXPECT_GE(rig.frames.size(), 3u) << what << ": frames resume";
  EXPECT_LT(rig.frames.size(), 12u) << what << ": some frames must have been hit";
  for (const auto& r : rig.frames) {
    const auto truth = rig.sim->truth(r.sequence);
    ASSERT_TRUE(truth) << what;
    expect_exact(r, *truth);
  }
  EXPECT_EQ(dc.frames, rig.frames.size()) << what;
  EXPECT_GT(dc.broken_sub_images + dc.incomplete_frames, 0u) << what;
  EXPECT_EQ(sc.frames, 12u) << what;
}

TEST(KinectSimFaults, DroppedPackets) {
  KinectFaults f;
  f.drop = 0.003;
  run_with(f, "drop");
}

TEST(KinectSimFaults, DuplicatedPackets) {
  KinectFaults f;
  f.duplicate = 0.003;
  run_with(f, "duplicate");
}

TEST(KinectSimFaults, TruncatedPackets) {
  KinectFaults f;
  f.truncate = 0.003;
  run_with(f, "truncate");
}

TEST(KinectSimFaults, GarbagePackets) {
  KinectFaults f;
  f.garbage = 0.003;
  run_with(f, "garbage");
}

TEST(KinectSimFaults, StalledEndpointLosesFramesThenResumes) {
  Rig rig;
  KinectFaults f;
  f.stall_at_frame = 2;
  f.stall_frames = 3;
  rig.sim->set_faults(f);
  rig.start();
  rig.pump(8);
  std::vector<std::uint32_t> seqs;
  for (const auto& r : rig.frames) seqs.push_back(r.sequence);
  EXPECT_EQ(seqs, (std::vector<std::uint32_t>{0, 1, 5, 6, 7}));
  EXPECT_EQ(rig.sim->counters().stalled_frames, 3u);
  EXPECT_EQ(rig.dev->stream_counters().skipped_frames, 3u);  // the driver's own account of the stall
}

TEST(KinectSimFaults, UnplugMidStreamIsReportedAndReplugResumes) {
  Rig rig;
  KinectFaults f;
  f.unplug_at_frame = 3;
  rig.sim->set_faults(f);
  rig.start();
  try {
    rig.pump(10);
    FAIL() << "unplug not reported";
  } catch (const UsbError& e) {
    EXPECT_EQ(e.kind(), UsbErrorKind::kDisconnected);
  }
  EXPECT_EQ(rig.frames.size(), 3u);  // the half-sent frame 3 is never passed on
  EXPECT_FALSE(rig.sim->plugged());
  EXPECT_FALSE(rig.dev->connected());
  rig.dev.reset();  // closing a gone device must not throw
  try {
    rig.sim->connect();
    FAIL() << "connected to an unplugged device";
  } catch (const UsbError& e) {
    EXPECT_EQ(e.kind(), UsbErrorKind::kNoDevice);
  }
  rig.sim->set_faults({});
  rig.sim->replug();
  rig.frames.clear();
  rig.start();
  rig.pump(3);
  ASSERT_EQ(rig.frames.size(), 3u);
  for (const auto& r : rig.frames) expect_exact(r, *rig.sim->truth(r.sequence));
}

TEST(KinectSimCommands, LostResponseIsRetriedWithANewSequence) {
  Rig rig;
  KinectFaults f;
  f.lost_responses = 2;
  rig.sim->set_faults(f);
  rig.start();
  EXPECT_EQ(rig.dev->counters().retries, 2u);
  rig.pump(1);
  EXPECT_EQ(rig.frames.size(), 1u);
  // The first command (ReadFirmwareVersions) went out three times, each with
  // the next sequence number; numbering then goes on without a gap (1.5).
  const auto log = rig.sim->command_log();
  ASSERT_GE(log.size(), 4u);
  for (std::size_t k = 0; k < 3; ++k) {
    EXPECT_EQ(log[k].id, static_cast<std::uint32_t>(kinect::CommandId::kReadFirmwareVersions)) << k;
  }
  for (std::size_t k = 0; k < log.size(); ++k) EXPECT_EQ(log[k].sequence, k) << k;
}

TEST(KinectSimCommands, DeviceThatNeverAnswersTimesOut) {
  Rig rig;
  KinectFaults f;
  f.lost_responses = 100;
  rig.sim->set_faults(f);
  try {
    rig.start();
    FAIL() << "start succeeded without answers";
  } catch (const UsbError& e) {
    EXPECT_EQ(e.kind(), UsbErrorKind::kTimeout);
  }
}

TEST(KinectSimCommands, AStoppingCallerIsNotHeldUpByRetries) {
  // DriverOptions::cancel set (the daemon stopping): the command that timed
  // out is not tried again, and the sequence ends as cancelled. (The flag is
  // declared first: the devices read it as they close, when the rigs end.)
  std::atomic<bool> stopping{true};
  Rig rig;
  KinectFaults f;
  f.lost_responses = 100;
  rig.sim->set_faults(f);
  kinect::DriverOptions o;
  o.cancel = &stopping;
  try {
    rig.start(o);
    FAIL() << "start succeeded without answers";
  } catch (const UsbError& e) {
    EXPECT_EQ(e.kind(), UsbErrorKind::kCancelled);
    EXPECT_STREQ(kinect::usb_error_kind_name(e.kind()), "cancelled");
  }
  EXPECT_EQ(rig.dev->counters().retries, 0u);
  EXPECT_EQ(rig.sim->command_log().size(), 1u);
  // Not stopping: the same device is tried three times, then times out.
  stopping = false;
  Rig again;
  again.sim->set_faults(f);
  try {
    again.start(o);
    FAIL() << "start succeeded without answers";
  } catch (const UsbError& e) {
    EXPECT_EQ(e.kind(), UsbErrorKind::kTimeout);
  }
  EXPECT_EQ(again.dev->counters().retries, 2u);
}

TEST(KinectSimCommands, SecondDriverFindsTheDeviceBusy) {
  Rig rig;
  rig.start();
  try {
    rig.sim->connect();
    FAIL() << "two drivers on one device";
  } catch (const UsbError& e) {
    EXPECT_EQ(e.kind(), UsbErrorKind::kBusy);
  }
  rig.dev.reset();
  EXPECT_NO_THROW(rig.sim->connect());
}

}  // namespace

namespace {

// A command as kinect2-protocol.md 1.7 writes it: id and parameters.
struct Sent {
  std::uint32_t id;
  std::vector<std::uint32_t> params;
  bool operator==(const Sent& o) const { return id == o.id && params == o.params; }
};
std::ostream& operator<<(std::ostream& os, const Sent& s) {
  os << "0x" << std::hex << s.id << std::dec << "[";
  for (auto p : s.params) os << " " << p;
  return os << " ]";
}
std::vector<Sent> sent_since(const SimulatedKinect& sim, std::size_t from) {
  std::vector<Sent> out;
  const auto log = sim.command_log();
  for (std::size_t k = from; k < log.size(); ++k) out.push_back({log[k].id, log[k].params});
  return out;
}

}  // namespace

// The start, stop and close sequences of kinect2-protocol.md 1.7, command by
// command, as the device receives them; after stop no frame arrives.
TEST(KinectSimCommands, StartStopAndCloseSendTheDocumentedSequences) {
  Rig rig;
  rig.start();
  const auto start = sent_since(*rig.sim, 0);
  const std::vector<Sent> want_head{{0x02, {}},
                                    {0x14, {}},
                                    {0x22, {1}},
                                    {0x22, {3}},
                                    {0x22, {2}},
                                    {0x22, {4}},
                                    {0x4B, {1, 0x00640064, 0, 0}},
                                    {0x4B, {0, 0, 0, 0}}};
  ASSERT_GT(start.size(), want_head.size() + 4);
  EXPECT_EQ(std::vector<Sent>(start.begin(), start.begin() + 8), want_head);
  // Status polls until ready (the simulated device is ready at the second), then the stream start.
  const std::vector<Sent> want_tail{
      {0x16, {0x090000}}, {0x16, {0x090000}}, {0x09, {}}, {0x16, {0x090000}}, {0x2B, {1}}};
  EXPECT_EQ(std::vector<Sent>(start.begin() + 8, start.end()), want_tail);
  rig.pump(2);
  ASSERT_EQ(rig.frames.size(), 2u);

  rig.dev->stop();
  EXPECT_FALSE(rig.dev->streaming());
  const auto stop = sent_since(*rig.sim, start.size());
  const std::vector<Sent> want_stop{
      {0x4B, {1, 0x00640064, 0, 0}}, {0x4B, {0, 0, 0, 0}}, {0x0A, {}},           {0x2B, {0}},
      {0x4B, {1, 0, 0, 0}},          {0x4B, {0, 0, 0, 0}}, {0x4B, {1, 0, 0, 0}}, {0x4B, {0, 0, 0, 0}}};
  EXPECT_EQ(stop, want_stop);
  rig.pump(3);
  EXPECT_EQ(rig.frames.size(), 2u) << "frames after stop";
  rig.dev->stop();  // a second stop does nothing
  EXPECT_EQ(sent_since(*rig.sim, start.size()).size(), want_stop.size());

  rig.dev->close();
  const auto close = sent_since(*rig.sim, start.size() + stop.size());
  const std::vector<Sent> want_close{{0x4B, {1, 0x00640064, 0, 0}}, {0x4B, {0, 0, 0, 0}}, {0x00, {}}};
  EXPECT_EQ(close, want_close);
  // Close while streaming stops first, then shuts down.
  Rig streaming;
  streaming.start();
  const std::size_t n = streaming.sim->command_log().size();
  streaming.dev->close();
  const auto stop_close = sent_since(*streaming.sim, n);
  ASSERT_EQ(stop_close.size(), want_stop.size() + want_close.size());
  EXPECT_EQ(stop_close.back(), (Sent{0x00, {}}));
  EXPECT_EQ(stop_close[2], (Sent{0x0A, {}}));
}

namespace {

// Frame k: the two materials side by side at depth kDepths[k] (a stage moved
// between frames), on a wall 1 m further back.
constexpr double kDepths[] = {600.0, 900.0, 1249.0, 2000.0, 3500.0};
Scene stage_at(std::uint64_t k) {
  const double d = kDepths[k % 5];
  return two_targets(d, d, 0.0, 120, 120, 240, 300, 280, 400, d + 1000.0);
}

}  // namespace

// The whole path gives back the simulated per-frequency depths: each frame
// through the device, the driver, the parser, the unpack and the decode,
// against the decode of the same scene rendered without noise (the material's
// and the harmonics' distortion is the simulation's, not an error).
TEST(KinectSim, EndToEndPerFrequencyDepthsForSeveralMaterialsAndDepths) {
  Rig rig(stage_at);
  rig.start();
  rig.pump(5);
  ASSERT_EQ(rig.frames.size(), 5u);
  const auto& sim = rig.sim;
  const auto& frames = rig.frames;
  const auto p0 = rig.dev->identity().p0.p0_rad();
  const double wavelength[3] = {1875.0, 9375.0, 1250.0};  // c / (2 f) with the device's c = 300 mm/ns
  for (const auto& r : frames) {
    const auto truth = sim->truth(r.sequence);
    ASSERT_TRUE(truth);
    const auto clean_frame = sim->renderer().render(stage_at(r.sequence), 0, false);
    const auto got = decode_frame(r.raw.data(), kinect::kPixels, p0);
    const auto want = decode_frame(clean_frame.raw.data(), kinect::kPixels, p0);
    for (int t = 0; t < 2; ++t) {
      for (std::size_t g = 0; g < 3; ++g) {
        std::vector<double> err;
        for (std::size_t i = 0; i < kinect::kPixels; ++i) {
          if (truth->target[i] != t || got.flags[i] || want.flags[i]) continue;
          err.push_back(std::remainder(static_cast<double>(got.depth_mm[g][i]) - want.depth_mm[g][i], wavelength[g]));
        }
        ASSERT_GT(err.size(), 10000u) << "frame " << r.sequence << " target " << t;
        double mean = 0.0, sq = 0.0, worst = 0.0;
        for (double e : err) {
          mean += e;
          sq += e * e;
          worst = std::max(worst, std::fabs(e));
        }
        mean /= static_cast<double>(err.size());
        const double sd = std::sqrt(sq / static_cast<double>(err.size()) - mean * mean);
        // Unbiased (the device path adds nothing: mean within 5 standard
        // errors; measured |mean| <= 0.17 mm with sd 0.5..37 mm), Gaussian
        // tails (worst <= 4.9 sd measured over 21,600 pixels; 6 sd allowed), and
        // the noise far below a wrap (sd 0.5..37 mm against 1250..9375 mm).
        const std::string where = "depth " + std::to_string(kDepths[r.sequence % 5]) + " target " + std::to_string(t) +
                                  " group " + std::to_string(g);
        EXPECT_LT(std::fabs(mean), 0.02 + 5.0 * sd / std::sqrt(static_cast<double>(err.size()))) << where;
        EXPECT_LT(worst, 6.0 * sd) << where;
        EXPECT_LT(sd, 0.01 * wavelength[g]) << where;
      }
    }
  }
}
