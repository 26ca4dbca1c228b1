// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// A camera source unpacks only the pixels the pipeline asks for
// (SourceCallbacks::region, Pipeline::wanted_region): a region of interest
// and nothing else, nothing at all when the profile needs no frame (sorting
// between bursts), the whole frame when nobody asks (recording). The
// pipeline publishes what its profile reads, and a frame unpacked for
// another region (a switch in flight) is skipped and counted, never decoded.
// The simulated Kinect stands in for the camera on the same driver.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

#include "test_util.hpp"
#include "tofmat/core/exemplar_table.hpp"
#include "tofmat/daemon/pipeline.hpp"
#include "tofmat/daemon/sim_source.hpp"

namespace {

using tofmat::PixelRegion;
using namespace tofmat::daemon;

constexpr std::int16_t kSentinel = -32768;  // no 11-bit code maps to it

// The first `n` frames of a static simulated scene, unpacked as `region` says.
std::vector<RawFrame> frames_from_sim(std::size_t n, std::function<std::optional<PixelRegion>()> region) {
  SimSpec spec = parse_sim_spec("static,material=cork,depth=900,realtime=0");
  SourceOptions options;
  options.sim_data_dir = TOFMAT_SIM_DATA_DIR;
  auto source = make_sim_source(spec, options);
  std::vector<RawFrame> out;
  std::mutex mutex;
  std::atomic<bool> stop{false};
  SourceCallbacks cb;
  cb.region = std::move(region);
  cb.raw_buffer = [] { return std::vector<std::int16_t>(9 * kPixels, kSentinel); };
  cb.state = [](DeviceState, const std::string&) {};
  cb.frame = [&](RawFrame&& f) {
    std::lock_guard<std::mutex> lock(mutex);
    if (out.size() < n) out.push_back(std::move(f));
    if (out.size() >= n) stop = true;
  };
  std::thread t([&] { source->run(cb, stop); });
  t.join();
  return out;
}

std::size_t written(const RawFrame& f, const PixelRegion& r, bool inside) {
  std::size_t n = 0;
  for (int s = 0; s < 9; ++s)
    for (int y = 0; y < kHeight; ++y)
      for (int x = 0; x < kWidth; ++x) {
        const bool in = x >= r.x0 && x < r.x1 && y >= r.y0 && y < r.y1;
        if (in == inside && f.raw[static_cast<std::size_t>(s) * kPixels + static_cast<std::size_t>(y) * kWidth +
                                  static_cast<std::size_t>(x)] != kSentinel)
          ++n;
      }
  return n;
}

TEST(SourceRegions, OnlyTheAskedRegionIsUnpacked) {
  const PixelRegion roi{232, 188, 280, 236};
  const auto frames = frames_from_sim(2, [&] { return std::optional<PixelRegion>(roi); });
  ASSERT_EQ(frames.size(), 2u);
  for (const auto& f : frames) {
    ASSERT_EQ(f.raw.size(), 9 * kPixels);
    EXPECT_EQ(f.region.x0, roi.x0);
    EXPECT_EQ(f.region.y1, roi.y1);
    EXPECT_EQ(written(f, roi, /*inside=*/true), 9u * 48 * 48);  // every sample of the region
    EXPECT_EQ(written(f, roi, /*inside=*/false), 0u);           // and nothing else
    EXPECT_TRUE(f.simulated);
  }
}

TEST(SourceRegions, NothingIsUnpackedWhenNothingIsWanted) {
  const auto frames = frames_from_sim(2, [] { return std::optional<PixelRegion>(); });
  ASSERT_EQ(frames.size(), 2u);
  for (const auto& f : frames) {
    EXPECT_TRUE(f.raw.empty());
    EXPECT_TRUE(region_empty(f.region));
    EXPECT_NE(f.calibration, nullptr);  // the frame still arrives: it is counted and paced
  }
}

TEST(SourceRegions, WithoutAskingTheWholeFrameIsUnpacked) {
  const auto frames = frames_from_sim(1, nullptr);
  ASSERT_EQ(frames.size(), 1u);
  const PixelRegion whole{0, 0, kWidth, kHeight};
  EXPECT_TRUE(region_covers(frames[0].region, whole));
  // Columns 0 and 511 always read code 0, which maps to a value, not the sentinel.
  EXPECT_EQ(std::count(frames[0].raw.begin(), frames[0].raw.end(), kSentinel), 0);
}

TEST(SourceRegions, FramesCarryTheCamerasIntrinsics) {
  // The driver reads the depth-parameters page at start; the simulated camera
  // answers with its pinhole camera (no distortion).
  const auto frames = frames_from_sim(2, nullptr);
  ASSERT_EQ(frames.size(), 2u);
  ASSERT_TRUE(frames[0].calibration && frames[0].calibration->intrinsics);
  const auto& k = *frames[0].calibration->intrinsics;
  EXPECT_EQ(k.fx, 365.0f);
  EXPECT_EQ(k.fy, 365.0f);
  EXPECT_EQ(k.cx, 256.0f);
  EXPECT_EQ(k.cy, 212.0f);
  EXPECT_EQ(k.k1, 0.0f);
  EXPECT_EQ(k.p2, 0.0f);
  EXPECT_EQ(frames[1].calibration, frames[0].calibration);  // one per device start
}

TEST(SourceRegions, ThePipelineAsksForWhatItsProfileReads) {
  auto table = std::make_shared<const tofmat::ExemplarTable>(tofmat::ExemplarTable::from_npy_dir(
      tofmat_test::db_dir().string(), tofmat::kDatabaseBinStartMm, tofmat::kDatabaseBinStopMm));
  ProfileConfig c;
  c.name = "handheld";
  Pipeline p(table, "db", c);
  auto w = p.wanted_region();
  ASSERT_TRUE(w.has_value());
  EXPECT_EQ(w->x0, c.roi.x0);
  EXPECT_EQ(w->x1, c.roi.x1);

  p.set_profile("sorting");
  EXPECT_FALSE(p.wanted_region().has_value());  // between bursts: not one pixel
  p.trigger(3);
  w = p.wanted_region();
  ASSERT_TRUE(w.has_value());
  EXPECT_EQ(w->y0, c.roi.y0);

  p.set_profile("segmentation");
  w = p.wanted_region();
  ASSERT_TRUE(w.has_value());
  EXPECT_TRUE(region_covers(*w, PixelRegion{0, 0, kWidth, kHeight}));

  // A frame unpacked for the ROI is not decoded by the full-frame profile: skipped and counted.
  const auto frames = frames_from_sim(1, [&] { return std::optional<PixelRegion>(c.roi); });
  ASSERT_EQ(frames.size(), 1u);
  RawFrame f = frames[0];
  std::atomic<bool> stop{false};
  std::thread t([&] { p.run(stop); });
  p.push(std::move(f));
  for (int i = 0; i < 200 && p.status()["frames_skipped"].get<int>() == 0; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  stop = true;
  t.join();
  EXPECT_EQ(p.status()["frames_skipped"].get<int>(), 1);
  EXPECT_EQ(p.status()["frames_processed"].get<int>(), 0);
  // Its buffer went back for the source to reuse.
  EXPECT_EQ(p.raw_buffer().size(), 9 * kPixels);
}

}  // namespace
