// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// tofmatd's processing stage (firmware/daemon/src/pipeline.cpp): frames from
// the bounded queue through the active profile on the processing thread
// (run()), and the commands from clients on other threads. A command the
// pipeline refuses (std::invalid_argument, or std::logic_error for a trigger
// outside sorting) changes nothing, not even the accumulation under way; an
// accepted one takes effect from the next frame; status() counts frames
// processed, dropped and failed; run() returns soon after stop is set; frames
// pushed faster than they are processed lose the oldest, counted.
//
// The pipeline runs on its own thread as in the daemon. Waits are bounded
// (kPatience) only so that a broken pipeline fails instead of hanging;
// nothing here asserts how fast anything is.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "daemon_frames.hpp"
#include "test_util.hpp"
#include "tofmat/daemon/pipeline.hpp"

namespace {

using namespace tofmat_test;
using namespace std::chrono_literals;
using tofmat::ExemplarTable;
using tofmat::PixelRegion;
using tofmat::daemon::Emitter;
using tofmat::daemon::Pipeline;
using tofmat::daemon::ProfileConfig;
using tofmat::daemon::RawFrame;
using tofmat::protocol::DepthEvent;
using tofmat::protocol::LabelEvent;
using tofmat::protocol::LabelMapEvent;

constexpr auto kPatience = 10s;  // how long anything may take before it counts as not happening
const std::string kTablePath = "/tables/tanaka2017_kinect2_db";

// What the pipeline emitted, from its thread, with waits for the test's.
class Events {
 public:
  // Called on the processing thread before a label is recorded (may throw or block).
  std::function<void(const LabelEvent&)> before_label;

  Emitter emitter() {
    Emitter e;
    e.label = [this](const LabelEvent& l) {
      if (before_label) before_label(l);
      add([&] { labels_.push_back(l); });
    };
    e.label_map = [this](const LabelMapEvent& m) { add([&] { maps_.push_back(m); }); };
    e.wants_depth = [this](const std::string& kind) {
      std::lock_guard<std::mutex> lock(mutex_);
      return std::find(depth_kinds_.begin(), depth_kinds_.end(), kind) != depth_kinds_.end();
    };
    e.depth = [this](const DepthEvent& d) { add([&] { depths_.push_back(d); }); };
    return e;
  }
  void want_depth(std::vector<std::string> kinds) {
    std::lock_guard<std::mutex> lock(mutex_);
    depth_kinds_ = std::move(kinds);
  }

  // Waits until at least n labels (label maps, depth images) have come.
  bool wait_labels(std::size_t n) {
    return wait([&] { return labels_.size() >= n; });
  }
  bool wait_maps(std::size_t n) {
    return wait([&] { return maps_.size() >= n; });
  }
  bool wait_depths(std::size_t n) {
    return wait([&] { return depths_.size() >= n; });
  }

  std::vector<LabelEvent> labels() const { return copy(labels_); }
  std::vector<LabelMapEvent> maps() const { return copy(maps_); }
  std::vector<DepthEvent> depths() const { return copy(depths_); }

 private:
  template <typename F>
  void add(F&& f) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      f();
    }
    changed_.notify_all();
  }
  bool wait(const std::function<bool()>& done) {
    std::unique_lock<std::mutex> lock(mutex_);
    return changed_.wait_for(lock, kPatience, done);
  }
  template <typename T>
  std::vector<T> copy(const std::vector<T>& v) const {
    std::lock_guard<std::mutex> lock(mutex_);
    return v;
  }

  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::vector<LabelEvent> labels_;
  std::vector<LabelMapEvent> maps_;
  std::vector<DepthEvent> depths_;
  std::vector<std::string> depth_kinds_;
};

// run() on its own thread for the scope's life.
class Running {
 public:
  explicit Running(Pipeline& p) : done_(std::async(std::launch::async, [&p, this] { p.run(stop_); })) {}
  ~Running() { stop(); }
  // Stops the loop; false if run() did not return within kPatience.
  bool stop() {
    stop_ = true;
    if (!done_.valid()) return true;
    const bool returned = done_.wait_for(kPatience) == std::future_status::ready;
    if (returned) done_.get();
    return returned;
  }

 private:
  std::atomic<bool> stop_{false};
  std::future<void> done_;
};

ProfileConfig handheld_with(std::vector<std::string> candidates) {
  ProfileConfig c;
  c.name = "handheld";
  c.candidates = std::move(candidates);
  return c;
}

// The real table's materials `names` only (same bins, rows and values): a
// second table to load.
std::shared_ptr<const ExemplarTable> subset_table(const std::vector<std::string>& names) {
  const auto& t = *real_table();
  std::vector<float> values;
  for (const auto& n : names) {
    const float* v = t.material_values(static_cast<std::size_t>(t.index_of(n)));
    values.insert(values.end(), v, v + t.elements_per_material());
  }
  return std::make_shared<const ExemplarTable>(names, t.rows(), t.bins(), values);
}

std::vector<std::string> ranked(const LabelEvent& l) {
  std::vector<std::string> out;
  for (const auto& r : l.ranking) out.push_back(r.material);
  std::sort(out.begin(), out.end());
  return out;
}

TEST(Pipeline, RefusesABadConfigurationAtConstruction) {
  ProfileConfig c;
  c.name = "nope";
  EXPECT_THROW(Pipeline(real_table(), kTablePath, c), std::invalid_argument);
  c = handheld_with({"copper", "kryptonite"});
  EXPECT_THROW(Pipeline(real_table(), kTablePath, c), std::invalid_argument);
}

TEST(Pipeline, RefusedCommandsChangeNothingNotEvenTheAccumulation) {
  Pipeline p(real_table(), kTablePath, handheld_with({"copper", "acryl", "pp"}));
  Events events;
  p.set_emitter(events.emitter());
  Running running(p);
  p.push(make_frame(1, {target_in_roi("copper", 50)}));
  ASSERT_TRUE(events.wait_labels(1));
  const auto before = p.status();
  const auto table_before = p.table();

  EXPECT_THROW(p.set_profile("juggling"), std::invalid_argument);
  EXPECT_THROW(p.set_roi(PixelRegion{0, 0, kWidth + 1, 10}), std::invalid_argument);
  EXPECT_THROW(p.set_roi(PixelRegion{10, 10, 10, 20}), std::invalid_argument);
  EXPECT_THROW(p.set_candidates({"copper", "kryptonite"}), std::invalid_argument);
  // A table without a current candidate, and one with other rows.
  EXPECT_THROW(p.set_table(subset_table({"copper", "pp"}), "/tables/no-acryl.tmx"), std::invalid_argument);
  const auto& t = *real_table();
  EXPECT_THROW(p.set_table(std::make_shared<const ExemplarTable>(
                               t.materials(), std::vector<tofmat::RowSpec>{{80, 120}, {16, 120}}, t.bins(), t.values()),
                           "/tables/swapped.tmx"),
               std::invalid_argument);
  EXPECT_THROW(p.trigger(3), std::logic_error) << "handheld takes no trigger";

  EXPECT_TRUE(p.table() == table_before);
  EXPECT_EQ(p.table_path(), kTablePath);
  auto after = p.status();
  EXPECT_EQ(after, before);
  EXPECT_EQ(p.config().candidates, (std::vector<std::string>{"copper", "acryl", "pp"}));

  // The same profile goes on: the next frame adds to the same accumulation.
  p.push(make_frame(2, {target_in_roi("copper", 60)}));
  ASSERT_TRUE(events.wait_labels(2));
  const auto l = events.labels().back();
  EXPECT_EQ(l.state, "tracking");
  EXPECT_EQ(l.bins_covered, 2u) << "a refused command restarted the accumulation";
  EXPECT_EQ(ranked(l), (std::vector<std::string>{"acryl", "copper", "pp"}));
  EXPECT_EQ(l.material, "copper");
}

TEST(Pipeline, AcceptedCommandsTakeEffectFromTheNextFrame) {
  Pipeline p(real_table(), kTablePath, handheld_with({}));
  Events events;
  p.set_emitter(events.emitter());
  Running running(p);
  std::uint64_t seq = 0;
  std::size_t labels = 0;
  auto push_and_wait_label = [&](const std::vector<Patch>& patches) {
    p.push(make_frame(seq++, patches));
    ++labels;
    return events.wait_labels(labels);
  };

  ASSERT_TRUE(push_and_wait_label({target_in_roi("acryl", 50)}));
  EXPECT_EQ(events.labels().back().ranking.size(), 5u);  // top 5 of all 29

  p.set_candidates({"pvc", "copper"});
  ASSERT_TRUE(push_and_wait_label({target_in_roi("acryl", 55)}));
  EXPECT_EQ(ranked(events.labels().back()), (std::vector<std::string>{"copper", "pvc"}));
  EXPECT_EQ(p.status()["candidates"], (std::vector<std::string>{"pvc", "copper"}));

  // A region off the centre: the depth images show where the profile looks now.
  const PixelRegion corner{16, 16, 48, 40};
  p.set_roi(corner);
  events.want_depth({"combined"});
  ASSERT_TRUE(push_and_wait_label({Patch{{0, 0, 64, 64}, material_at_bin(*real_table(), "copper", 70)}}));
  ASSERT_TRUE(events.wait_depths(1));
  const auto d = events.depths().back();
  EXPECT_EQ(d.x0, corner.x0);
  EXPECT_EQ(d.y0, corner.y0);
  EXPECT_EQ(d.width, 32);
  EXPECT_EQ(d.height, 24);
  EXPECT_EQ(events.labels().back().material, "copper");
  events.want_depth({});
  p.set_roi(kCentreRoi);

  p.set_profile("segmentation");
  p.push(make_frame(seq++, {target_in_roi("copper", 70)}));
  ASSERT_TRUE(events.wait_maps(1));
  const auto map = events.maps().back();
  EXPECT_EQ(map.materials, (std::vector<std::string>{"copper", "pvc"}));  // the candidates stay
  EXPECT_EQ(map.labels.size(), kPixels);

  p.set_profile("sorting");
  EXPECT_EQ(p.trigger(1), 1u);
  ASSERT_TRUE(push_and_wait_label({target_in_roi("copper", 70)}));
  EXPECT_EQ(events.labels().back().state, "final");
  EXPECT_EQ(events.maps().size(), 1u) << "a label map after the profile changed";

  // Another table (holding the candidates): labels name its materials.
  p.set_profile("handheld");
  const auto smaller = subset_table({"copper", "pvc", "wood"});
  p.set_table(smaller, "/tables/three.tmx");
  p.set_candidates({});
  EXPECT_TRUE(p.table() == smaller);
  EXPECT_EQ(p.table_path(), "/tables/three.tmx");
  ASSERT_TRUE(push_and_wait_label({target_in_roi("copper", 80)}));
  const auto l = events.labels().back();
  EXPECT_EQ(ranked(l), (std::vector<std::string>{"copper", "pvc", "wood"}));
  EXPECT_EQ(l.material, "copper");
  EXPECT_EQ(l.index, 0) << "an index into the new table";
  const auto s = p.status();
  EXPECT_EQ(s["table"]["path"], "/tables/three.tmx");
  EXPECT_EQ(s["table"]["materials"], (std::vector<std::string>{"copper", "pvc", "wood"}));
  EXPECT_EQ(s["profile"], "handheld");
}

TEST(Pipeline, ResetStartsTheAccumulationAfresh) {
  Pipeline p(real_table(), kTablePath, handheld_with({}));
  Events events;
  p.set_emitter(events.emitter());
  Running running(p);
  p.push(make_frame(0, {target_in_roi("pp", 40)}));
  ASSERT_TRUE(events.wait_labels(1));
  p.push(make_frame(1, {target_in_roi("pp", 50)}));
  ASSERT_TRUE(events.wait_labels(2));
  p.reset();
  p.push(make_frame(2, {target_in_roi("pp", 60)}));
  ASSERT_TRUE(events.wait_labels(3));
  const auto labels = events.labels();
  EXPECT_EQ(labels[1].bins_covered, 2u);
  EXPECT_EQ(labels[2].bins_covered, 1u);
}

TEST(Pipeline, StatusReportsTheConfigurationAndCountsFrames) {
  ProfileConfig c = handheld_with({"copper", "cork"});
  c.backend = tofmat::daemon::Backend::kFloat;
  c.roi = {230, 180, 290, 240};
  Pipeline p(real_table(), kTablePath, c, /*queue_frames=*/32);
  Events events;
  p.set_emitter(events.emitter());

  auto s = p.status();
  EXPECT_EQ(s["profile"], "handheld");
  EXPECT_EQ(s["backend"], "float");
  EXPECT_EQ(s["roi"], (std::vector<int>{230, 180, 290, 240}));
  EXPECT_EQ(s["candidates"], (std::vector<std::string>{"copper", "cork"}));
  EXPECT_EQ(s["table"]["path"], kTablePath);
  EXPECT_EQ(s["table"]["materials"], real_table()->materials());
  EXPECT_EQ(s["table"]["bins"], 200);
  EXPECT_EQ(s["table"]["bin_start_mm"], 600.0);
  EXPECT_DOUBLE_EQ(s["table"]["bin_width_mm"].get<double>(), 600.0 / 199.0);
  EXPECT_EQ(s["frames_processed"], 0);
  EXPECT_EQ(s["frames_dropped"], 0);
  EXPECT_EQ(s["processing_errors"], 0);
  EXPECT_EQ(s["last_error"], "");
  EXPECT_EQ(s["fps"], 0.0);

  // 15 frames that arrived 100 ms apart: the last second holds the last 11.
  for (std::uint64_t k = 0; k < 15; ++k) {
    const auto depths = material_at_bin(*real_table(), "cork", 40 + 5 * static_cast<std::uint32_t>(k));
    RawFrame f = make_frame(k, {Patch{{226, 176, 294, 244}, depths}});
    f.arrival_ns = 5'000'000'000ull + k * 100'000'000ull;
    p.push(std::move(f));
  }
  {
    Running running(p);
    ASSERT_TRUE(events.wait_labels(15));
  }
  s = p.status();
  EXPECT_EQ(s["frames_processed"], 15);
  EXPECT_EQ(s["frames_dropped"], 0);
  EXPECT_EQ(s["processing_errors"], 0);
  EXPECT_EQ(s["fps"], 11.0);
  EXPECT_GT(s["process_ms"].get<double>(), 0.0);
  EXPECT_EQ(events.labels().back().material, "cork");
}

TEST(Pipeline, AFrameThatFailsCostsItselfOnlyAndIsCounted) {
  Pipeline p(real_table(), kTablePath, handheld_with({}));
  Events events;
  events.before_label = [](const LabelEvent& l) {
    if (l.frame == 2) throw std::runtime_error("the subscriber went away");
  };
  p.set_emitter(events.emitter());
  Running running(p);
  for (std::uint64_t k = 1; k <= 3; ++k) {
    p.push(make_frame(k, {target_in_roi("pp", 60 + static_cast<std::uint32_t>(k))}));
    // One at a time: a queue of two must not drop any.
    if (k != 2) {
      ASSERT_TRUE(events.wait_labels(k == 1 ? 1 : 2));
    } else {
      const auto deadline = std::chrono::steady_clock::now() + kPatience;
      while (p.status()["processing_errors"] == 0 && std::chrono::steady_clock::now() < deadline)
        std::this_thread::sleep_for(5ms);
    }
  }
  const auto s = p.status();
  EXPECT_EQ(s["frames_processed"], 2);
  EXPECT_EQ(s["processing_errors"], 1);
  EXPECT_EQ(s["last_error"], "the subscriber went away");
  const auto labels = events.labels();
  ASSERT_EQ(labels.size(), 2u);
  EXPECT_EQ(labels[0].frame, 1u);
  EXPECT_EQ(labels[1].frame, 3u);
}

TEST(Pipeline, MalformedFramesAreSkippedAndTheNextOneIsProcessed) {
  Pipeline p(real_table(), kTablePath, handheld_with({}), 8);
  Events events;
  p.set_emitter(events.emitter());
  RawFrame no_calibration = make_frame(1, {target_in_roi("pp", 60)});
  no_calibration.calibration = nullptr;
  RawFrame short_raw = make_frame(2, {target_in_roi("pp", 60)});
  short_raw.raw.resize(8 * kPixels);
  p.push(std::move(no_calibration));
  p.push(std::move(short_raw));
  p.push(make_frame(3, {target_in_roi("pp", 60)}));
  Running running(p);
  ASSERT_TRUE(events.wait_labels(1));
  EXPECT_TRUE(running.stop());
  const auto labels = events.labels();
  ASSERT_EQ(labels.size(), 1u);
  EXPECT_EQ(labels[0].frame, 3u);
  EXPECT_EQ(p.status()["frames_processed"], 1);
}

TEST(Pipeline, RunReturnsSoonAfterStopIsSet) {
  Pipeline p(real_table(), kTablePath, handheld_with({}));
  Events events;
  p.set_emitter(events.emitter());
  {
    // Idle (waiting on an empty queue) when stop comes.
    Running running(p);
    std::this_thread::sleep_for(30ms);
    EXPECT_TRUE(running.stop()) << "run() did not return after stop";
  }
  {
    // Busy: a stream of frames is arriving.
    Running running(p);
    for (std::uint64_t k = 0; k < 3; ++k) p.push(make_frame(k, {target_in_roi("pp", 60)}));
    EXPECT_TRUE(running.stop()) << "run() did not return after stop";
  }
  // Stop already set: run() returns at once, leaving what is queued.
  const std::size_t processed = p.status()["frames_processed"].get<std::size_t>();
  p.push(make_frame(10, {target_in_roi("pp", 60)}));
  const std::atomic<bool> stopped{true};
  auto returned = std::async(std::launch::async, [&] { p.run(stopped); });
  ASSERT_EQ(returned.wait_for(kPatience), std::future_status::ready);
  EXPECT_EQ(p.status()["frames_processed"].get<std::size_t>(), processed);
}

TEST(Pipeline, FramesQueuedBeyondItsCapacityLoseTheOldest) {
  Pipeline p(real_table(), kTablePath, handheld_with({}), /*queue_frames=*/2);
  Events events;
  p.set_emitter(events.emitter());
  for (std::uint64_t k = 1; k <= 6; ++k) p.push(make_frame(k, {target_in_roi("pp", 60)}));
  EXPECT_EQ(p.status()["frames_dropped"], 4);
  Running running(p);
  ASSERT_TRUE(events.wait_labels(2));
  EXPECT_TRUE(running.stop());
  const auto labels = events.labels();
  ASSERT_EQ(labels.size(), 2u);
  EXPECT_EQ(labels[0].frame, 5u);
  EXPECT_EQ(labels[1].frame, 6u);
  EXPECT_EQ(p.status()["frames_processed"], 2);
}

TEST(Pipeline, FramesArrivingWhileOneIsProcessedLoseTheOldest) {
  Pipeline p(real_table(), kTablePath, handheld_with({}), /*queue_frames=*/3);
  Events events;
  // Frame 1's processing is held up until the test has pushed six more.
  std::promise<void> entered, release;
  auto released = release.get_future().share();
  events.before_label = [&entered, released](const LabelEvent& l) {
    if (l.frame != 1) return;
    entered.set_value();
    released.wait_for(kPatience);
  };
  p.set_emitter(events.emitter());
  Running running(p);
  p.push(make_frame(1, {target_in_roi("pp", 60)}));
  ASSERT_EQ(entered.get_future().wait_for(kPatience), std::future_status::ready);
  for (std::uint64_t k = 2; k <= 7; ++k) p.push(make_frame(k, {target_in_roi("pp", 60)}));
  release.set_value();
  ASSERT_TRUE(events.wait_labels(4));
  EXPECT_TRUE(running.stop());
  std::vector<std::uint64_t> frames;
  for (const auto& l : events.labels()) frames.push_back(l.frame);
  EXPECT_EQ(frames, (std::vector<std::uint64_t>{1, 5, 6, 7}));
  const auto s = p.status();
  EXPECT_EQ(s["frames_dropped"], 3);
  EXPECT_EQ(s["frames_processed"], 4);
}

TEST(Pipeline, CommandsFromTwoThreadsAtOnceAreBothApplied) {
  // The daemon handles clients' commands on its server thread while its main
  // thread reloads the table on SIGHUP (daemon.cpp): both reach the pipeline
  // at once, and neither may silently undo the other.
  ProfileConfig c;
  c.name = "segmentation";
  Pipeline p(real_table(), kTablePath, c);
  const auto three = subset_table({"copper", "pvc", "wood"});
  for (int round = 0; round < 30 && !HasFailure(); ++round) {
    const PixelRegion roi{10 + round, 10, 60 + round, 60};
    const auto table = round % 2 ? real_table() : three;
    const std::string path = round % 2 ? kTablePath : "/tables/three.tmx";
    std::promise<void> go;
    const auto start = go.get_future().share();
    auto reload = std::async(std::launch::async, [&] {
      start.wait();
      p.set_table(table, path);
    });
    auto command = std::async(std::launch::async, [&] {
      start.wait();
      p.set_roi(roi);
    });
    go.set_value();
    reload.get();
    command.get();
    EXPECT_TRUE(p.table() == table) << "round " << round << ": the table reload was undone";
    EXPECT_EQ(p.table_path(), path) << "round " << round;
    EXPECT_EQ(p.config().roi.x0, roi.x0) << "round " << round << ": the ROI command was undone";
  }
}

}  // namespace

// The corrected depth (stream depth:corrected): each pixel's combined depth
// less its labelled material's distortion (here a constant 3 mm x (table index
// + 1), so the expected value is plain), NaN where a pixel has no label.
TEST(Pipeline, CorrectedDepthSubtractsEachPixelsLabelledMaterial) {
  const auto& real = *real_table();
  tofmat::DepthDistortion d{tofmat::BinSpec{0.0, 10.0, 1000}, {}};
  for (std::size_t m = 0; m < real.n_materials(); ++m) d.mm.insert(d.mm.end(), 1000, 3.0f * static_cast<float>(m + 1));
  const auto table = std::make_shared<const ExemplarTable>(real.with_distortion(d));
  const auto shift = [&](const std::string& name) { return 3.0f * static_cast<float>(table->index_of(name) + 1); };
  Pipeline p(table, kTablePath, handheld_with({"copper", "pvc", "cork"}));
  Events events;
  events.want_depth({"combined", "corrected"});
  p.set_emitter(events.emitter());
  Running running(p);
  p.push(make_frame(1, {target_in_roi("copper", 60)}));
  ASSERT_TRUE(events.wait_labels(1));
  ASSERT_TRUE(events.wait_depths(2));
  const std::string material = events.labels().back().material;
  ASSERT_FALSE(material.empty());
  auto depths = events.depths();
  ASSERT_EQ(depths[0].kind, "combined");
  ASSERT_EQ(depths[1].kind, "corrected");
  ASSERT_EQ(depths[1].depth_mm.size(), depths[0].depth_mm.size());
  std::size_t checked = 0;
  for (std::size_t i = 0; i < depths[0].depth_mm.size(); ++i) {
    const float comb = depths[0].depth_mm[i], corr = depths[1].depth_mm[i];
    ASSERT_EQ(std::isnan(comb), std::isnan(corr)) << i;
    if (std::isnan(comb)) continue;
    EXPECT_NEAR(corr, comb - shift(material), 1e-3) << i;
    ++checked;
  }
  EXPECT_GT(checked, depths[0].depth_mm.size() / 2);

  // Segmentation: each pixel for its own label, none where it has none.
  p.set_profile("segmentation");
  p.push(make_frame(2, {Patch{{0, 0, 256, 424}, material_at_bin(real, "copper", 60)},
                        Patch{{256, 0, 512, 424}, material_at_bin(real, "cork", 60)}}));
  ASSERT_TRUE(events.wait_maps(1));
  ASSERT_TRUE(events.wait_depths(4));
  const auto map = events.maps().back();
  depths = events.depths();
  const auto& comb = depths[2];
  const auto& corr = depths[3];
  ASSERT_EQ(corr.kind, "corrected");
  ASSERT_EQ(corr.depth_mm.size(), map.labels.size());
  std::size_t labelled = 0, unlabelled = 0;
  for (std::size_t i = 0; i < map.labels.size(); ++i) {
    const std::uint8_t k = map.labels[i];
    if (k == tofmat::protocol::kNoLabel || std::isnan(comb.depth_mm[i])) {
      EXPECT_TRUE(std::isnan(corr.depth_mm[i])) << i;
      ++unlabelled;
      continue;
    }
    EXPECT_NEAR(corr.depth_mm[i], comb.depth_mm[i] - shift(map.materials[k]), 1e-3) << i;
    ++labelled;
  }
  EXPECT_GT(labelled, map.labels.size() / 2);
}
