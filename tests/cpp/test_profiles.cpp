// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// tofmatd's scene profiles (firmware/daemon/src/profile.cpp, handheld_profile.cpp,
// segmentation_profile.cpp, sorting_profile.cpp): the configuration checks
// that refuse what would break the pipeline (validate, make_profile,
// candidate_indices, parse_backend), and what each profile emits for a
// sequence of frames: handheld `tracking` labels and one `no_target` when the
// target leaves; sorting nothing until a trigger, then one `final` label after
// its burst; segmentation a 512 x 424 label map of the candidates; depth
// events only of the kinds a subscriber wants.
//
// Frames: the phasor model of daemon_frames.hpp (regions showing materials of
// the real database exactly), and for the handheld profile also the simulator
// (firmware/sim) rendering a target that comes, moves and goes, with its truth.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "daemon_frames.hpp"
#include "test_util.hpp"
#include "tofmat/daemon/profile.hpp"
#include "tofmat/sim/renderer.hpp"
#include "tofmat/sim/scene.hpp"

namespace {

using namespace tofmat_test;
using tofmat::ExemplarTable;
using tofmat::PixelRegion;
using tofmat::daemon::Backend;
using tofmat::daemon::candidate_indices;
using tofmat::daemon::FrameTruth;
using tofmat::daemon::make_profile;
using tofmat::daemon::parse_backend;
using tofmat::daemon::ProfileConfig;
using tofmat::daemon::RawFrame;
using tofmat::daemon::validate;
using tofmat::protocol::kNoLabel;

// Eq. (12): these tests match the simulator's frames against the real
// database's curves, which the simulator follows to a few tenths of a mm,
// beyond the real curves' own noise: the session matcher's open set (the
// default) rightly calls many of them unknown (RegionMatcher's tests cover it).
ProfileConfig config_of(const std::string& name, Backend backend = Backend::kFixed) {
  ProfileConfig c;
  c.name = name;
  c.backend = backend;
  c.method = tofmat::daemon::Method::kEq12;
  return c;
}

// The message of validate()'s refusal of `c` (a test failure if it accepts it).
std::string refusal(const ProfileConfig& c, const ExemplarTable& table = *real_table()) {
  return error_of<std::invalid_argument>([&] { validate(c, table); });
}

// ---------------------------------------------------------------- validate

TEST(ProfileValidate, AcceptsTheDefaultsOfEveryProfile) {
  for (const char* name : {"handheld", "segmentation", "sorting"}) {
    EXPECT_NO_THROW(validate(config_of(name), *real_table())) << name;
    ProfileConfig c = config_of(name);
    c.candidates = {"pvc", "epvc", "paper"};
    EXPECT_NO_THROW(validate(c, *real_table())) << name;
  }
}

TEST(ProfileValidate, RefusesAnUnknownProfile) {
  for (const char* name : {"Handheld", "", "segment", "sorting "}) {
    const std::string e = refusal(config_of(name));
    EXPECT_CONTAINS(e, "unknown profile");
    EXPECT_CONTAINS(e, "\"" + std::string(name) + "\"");
  }
}

TEST(ProfileValidate, RefusesAnRoiOutsideTheFrameOrEmpty) {
  const std::vector<PixelRegion> bad = {
      {-1, 0, 48, 48},       // left of the frame
      {0, -1, 48, 48},       // above it
      {480, 0, 513, 48},     // one column beyond the right edge
      {0, 400, 48, 425},     // one row beyond the bottom
      {100, 100, 100, 148},  // no columns
      {100, 100, 148, 100},  // no rows
      {148, 100, 100, 148},  // inverted
  };
  for (const auto& roi : bad) {
    ProfileConfig c = config_of("handheld");
    c.roi = roi;
    const std::string e = refusal(c);
    EXPECT_CONTAINS(e, "ROI");
    EXPECT_CONTAINS(e, "512 x 424");
  }
  // The whole frame and a single pixel at its far corner are regions.
  ProfileConfig c = config_of("sorting");
  c.roi = {0, 0, kWidth, kHeight};
  EXPECT_NO_THROW(validate(c, *real_table()));
  c.roi = {kWidth - 1, kHeight - 1, kWidth, kHeight};
  EXPECT_NO_THROW(validate(c, *real_table()));
}

TEST(ProfileValidate, RefusesACandidateNotInTheTable) {
  ProfileConfig c = config_of("handheld");
  c.candidates = {"pvc", "unobtainium", "cork"};
  const std::string e = refusal(c);
  EXPECT_CONTAINS(e, "\"unobtainium\"");
  EXPECT_CONTAINS(e, "not in the table");
  c.candidates = {"PVC"};  // names are exact
  EXPECT_CONTAINS(refusal(c), "\"PVC\"");
}

TEST(ProfileValidate, RefusesOutOfRangeSettings) {
  ProfileConfig c = config_of("handheld");
  c.top_k = 0;
  EXPECT_CONTAINS(refusal(c), "top_k");
  c = config_of("sorting");
  c.burst = 0;
  EXPECT_CONTAINS(refusal(c), "burst");
  c.burst = 301;
  EXPECT_CONTAINS(refusal(c), "burst");
  c = config_of("segmentation");
  for (int smooth : {0, 2, 17}) {
    c.smooth = smooth;
    EXPECT_CONTAINS(refusal(c), "smooth");
  }
  c = config_of("handheld");
  for (double f : {0.0, -0.5, 1.01, std::numeric_limits<double>::quiet_NaN()}) {
    c.min_valid_fraction = f;
    EXPECT_CONTAINS(refusal(c), "min_valid_fraction");
  }
}

TEST(ProfileValidate, RefusesATableWhoseRowsAreNotTheKinectFeatures) {
  // The decode makes d16 - d120 and d80 - d120; a table of other rows cannot be matched.
  const std::uint32_t bins = 10;
  const ExemplarTable swapped({"a"}, {{80, 120}, {16, 120}}, tofmat::BinSpec{600.0, 60.0, bins},
                              std::vector<float>(2 * bins, 1.0f));
  EXPECT_CONTAINS(refusal(config_of("handheld"), swapped), "rows");
  const ExemplarTable one_row({"a"}, {{16, 120}}, tofmat::BinSpec{600.0, 60.0, bins}, std::vector<float>(bins, 1.0f));
  EXPECT_CONTAINS(refusal(config_of("sorting"), one_row), "rows");
}

TEST(ProfileMake, RefusesWhatValidateRefusesAndMakesEveryProfile) {
  ProfileConfig c = config_of("nope");
  EXPECT_THROW(make_profile(c, real_table()), std::invalid_argument);
  c = config_of("segmentation");
  c.roi = {0, 0, kWidth + 1, kHeight};
  EXPECT_THROW(make_profile(c, real_table()), std::invalid_argument);
  c = config_of("sorting");
  c.candidates = {"nope"};
  EXPECT_THROW(make_profile(c, real_table()), std::invalid_argument);
  for (const char* name : {"handheld", "segmentation", "sorting"})
    for (Backend b : {Backend::kFixed, Backend::kFloat})
      EXPECT_TRUE(make_profile(config_of(name, b), real_table())) << name;
}

TEST(ProfileCandidates, NamesBecomeTableIndicesInTheOrderGiven) {
  const auto& t = *real_table();
  EXPECT_TRUE(candidate_indices(t, {}).empty()) << "empty means every material";
  const auto idx = candidate_indices(t, {"wood", "acryl", "pvc"});
  ASSERT_EQ(idx.size(), 3u);
  EXPECT_EQ(t.materials()[idx[0]], "wood");
  EXPECT_EQ(t.materials()[idx[1]], "acryl");
  EXPECT_EQ(t.materials()[idx[2]], "pvc");
  EXPECT_EQ(idx[1], 0u);  // the table is sorted by name
  EXPECT_CONTAINS(error_of<std::invalid_argument>([&] { candidate_indices(t, {"wood", "glass"}); }), "\"glass\"");
}

TEST(ProfileBackend, ParsesTheTwoNamesOnly) {
  EXPECT_EQ(parse_backend("fixed"), Backend::kFixed);
  EXPECT_EQ(parse_backend("float"), Backend::kFloat);
  EXPECT_CONTAINS(error_of<std::invalid_argument>([] { parse_backend("neon"); }), "\"neon\"");
  EXPECT_THROW(parse_backend("Fixed"), std::invalid_argument);
}

// ---------------------------------------------------------------- handheld

class HandheldBackends : public ::testing::TestWithParam<Backend> {};
INSTANTIATE_TEST_SUITE_P(Backends, HandheldBackends, ::testing::Values(Backend::kFixed, Backend::kFloat),
                         [](const ::testing::TestParamInfo<Backend>& backend) {
                           return std::string(backend.param == Backend::kFixed ? "fixed" : "float");
                         });

TEST_P(HandheldBackends, LabelsEveryFrameWhileTrackingAndOnceWhenTheTargetLeaves) {
  auto profile = make_profile(config_of("handheld", GetParam()), real_table());
  EventLog log;
  const auto emit = log.emitter();
  FrameMaker frames;
  std::uint64_t seq = 100;
  for (std::uint32_t bin = 40; bin < 100; bin += 10)
    profile->process(frames.draw(seq++, {target_in_roi("acryl", bin)}), emit);
  ASSERT_EQ(log.labels.size(), 6u);
  for (std::size_t k = 0; k < 6; ++k) {
    const auto& l = log.labels[k];
    EXPECT_EQ(l.state, "tracking");
    EXPECT_EQ(l.profile, "handheld");
    EXPECT_EQ(l.frame, 100 + k);
    EXPECT_EQ(l.timestamp_ns, arrival_of(100 + k));
    EXPECT_EQ(l.bins_covered, k + 1);
    EXPECT_EQ(l.ranking.size(), 5u);  // top_k
    EXPECT_FALSE(l.trigger);
    EXPECT_FALSE(l.truth) << "a frame without truth (a real camera) gives a label without truth";
  }
  EXPECT_EQ(log.labels.back().material, "acryl");
  EXPECT_EQ(log.labels.back().index, real_table()->index_of("acryl"));

  // Gone for three frames: one no_target, then silence.
  for (int k = 0; k < 3; ++k) profile->process(frames.draw(seq++, {}), emit);
  ASSERT_EQ(log.labels.size(), 7u);
  EXPECT_EQ(log.labels[6].state, "no_target");
  EXPECT_EQ(log.labels[6].material, "");
  EXPECT_TRUE(log.labels[6].ranking.empty());
  EXPECT_EQ(log.labels[6].frame, 106u);
  EXPECT_TRUE(log.depths.empty()) << "no depth kind was wanted";
}

TEST_P(HandheldBackends, ResetCommandStartsTheAccumulationAfresh) {
  auto profile = make_profile(config_of("handheld", GetParam()), real_table());
  EventLog log;
  const auto emit = log.emitter();
  FrameMaker frames;
  profile->process(frames.draw(1, {target_in_roi("pp", 50)}), emit);
  profile->process(frames.draw(2, {target_in_roi("pp", 55)}), emit);
  profile->reset();
  profile->process(frames.draw(3, {target_in_roi("pp", 60)}), emit);
  ASSERT_EQ(log.labels.size(), 3u);
  EXPECT_EQ(log.labels[1].bins_covered, 2u);
  EXPECT_EQ(log.labels[2].bins_covered, 1u);
  EXPECT_EQ(log.labels[2].state, "tracking");
}

TEST_P(HandheldBackends, SendsDepthImagesOfTheRoiOnlyOfTheKindsWanted) {
  ProfileConfig c = config_of("handheld", GetParam());
  c.roi = {100, 50, 164, 82};  // 64 x 32 away from the centre
  auto profile = make_profile(c, real_table());
  EventLog log;
  log.depth_kinds = {"80", "16"};
  FrameMaker frames;
  const GroupDepths depths = material_at_bin(*real_table(), "pvc", 120);
  profile->process(frames.draw(1, {Patch{{90, 40, 180, 90}, depths}}), log.emitter());
  ASSERT_EQ(log.depths.size(), 2u);
  for (std::size_t k = 0; k < 2; ++k) {
    const auto& d = log.depths[k];
    EXPECT_EQ(d.kind, k == 0 ? "80" : "16");
    EXPECT_EQ(d.frame, 1u);
    EXPECT_EQ(d.x0, 100);
    EXPECT_EQ(d.y0, 50);
    EXPECT_EQ(d.width, 64);
    EXPECT_EQ(d.height, 32);
    ASSERT_EQ(d.depth_mm.size(), 64u * 32u);
    const double expected = depths.mm[k == 0 ? 0 : 1];
    for (float v : d.depth_mm) ASSERT_NEAR(v, expected, 1.5) << d.kind;
  }
  EXPECT_EQ(log.labels.size(), 1u);
  log.clear();
  log.depth_kinds.clear();
  profile->process(frames.draw(2, {Patch{{90, 40, 180, 90}, depths}}), log.emitter());
  EXPECT_TRUE(log.depths.empty());
  EXPECT_EQ(log.labels.size(), 1u);
}

// The simulator's ideal Kinect v2 with camera-like noise, looking at a white
// board (its features are not the database's: only the profile's states and
// the truth are checked here, not the material).
std::shared_ptr<const tofmat::sim::Renderer> board_renderer() {
  auto device = tofmat::sim::DeviceProfile::ideal_kinect2();
  device.noise.read_noise = 3.0;
  device.noise.shot_gain = 0.03;
  device.noise.ambient = 100.0;
  device.pixel_phase.mean_rad = {0.4, -0.3, 1.1};
  device.pixel_phase.radial_rad = {0.05, 0.02, 0.08};
  tofmat::sim::MaterialLibrary library;
  library.name = "boards";
  tofmat::sim::Material white;
  white.name = "white";
  white.albedo = 0.9;
  library.materials = {white};
  return std::make_shared<const tofmat::sim::Renderer>(device, library, 1);
}

// The renderer's P0 tables, as the simulated device reports them to the driver.
std::shared_ptr<const tofmat::daemon::Calibration> calibration_of(const tofmat::sim::Renderer& r) {
  std::vector<float> p0;
  for (int g = 0; g < 3; ++g) {
    const auto t = r.p0_table(g);
    p0.insert(p0.end(), t.begin(), t.end());
  }
  return std::make_shared<const tofmat::daemon::Calibration>(p0);
}

// A frame of the scene with its truth; only the ROI's pixels are rendered
// (the profile decodes them alone), the rest sees nothing.
RawFrame sim_frame(const tofmat::sim::Renderer& r, std::shared_ptr<const tofmat::daemon::Calibration> calibration,
                   const tofmat::sim::Scene& scene, std::uint64_t sequence) {
  const tofmat::sim::PixelRect around{kCentreRoi.x0, kCentreRoi.y0, kCentreRoi.x1, kCentreRoi.y1};
  const auto rendered = r.render_region(scene, sequence, /*noise=*/true, around);
  RawFrame f = make_frame(sequence, {}, 0.0, std::move(calibration));
  auto truth = std::make_shared<FrameTruth>();
  for (const auto& t : scene.targets) truth->materials.push_back(t.material);
  truth->target.assign(kPixels, -1);
  truth->depth_mm.assign(kPixels, std::numeric_limits<float>::quiet_NaN());
  const std::size_t w = static_cast<std::size_t>(rendered.width), h = static_cast<std::size_t>(rendered.height);
  for (std::size_t y = 0; y < h; ++y)
    for (std::size_t x = 0; x < w; ++x) {
      const std::size_t i =
          (y + static_cast<std::size_t>(around.y0)) * kWidth + x + static_cast<std::size_t>(around.x0);
      for (std::size_t s = 0; s < 9; ++s) f.raw[s * kPixels + i] = rendered.raw[(s * h + y) * w + x];
      truth->target[i] = rendered.target[y * w + x];
      truth->depth_mm[i] = rendered.depth_mm[y * w + x];
    }
  f.truth = truth;
  return f;
}

TEST(HandheldOnTheSimulator, TracksABoardThatComesMovesAndGoes) {
  const auto renderer = board_renderer();
  const auto calibration = calibration_of(*renderer);
  auto profile = make_profile(config_of("handheld"), real_table());
  EventLog log;
  const auto emit = log.emitter();
  std::uint64_t seq = 0;
  auto show = [&](const tofmat::sim::Scene& scene) {
    profile->process(sim_frame(*renderer, calibration, scene, seq++), emit);
  };

  for (int k = 0; k < 5; ++k) show(tofmat::sim::Scene::centred_target("white", 750.0 + 25.0 * k, 0.0, 120));
  ASSERT_EQ(log.labels.size(), 5u);
  std::uint32_t covered = 0;
  for (int k = 0; k < 5; ++k) {
    const auto& l = log.labels[static_cast<std::size_t>(k)];
    EXPECT_EQ(l.state, "tracking");
    EXPECT_EQ(l.frame, static_cast<std::uint64_t>(k));
    EXPECT_GT(l.bins_covered, covered) << "each frame's depth adds its bins";
    covered = l.bins_covered;
    ASSERT_TRUE(l.truth);
    EXPECT_EQ(l.truth->material, "white");
    EXPECT_NEAR(l.truth->depth_mm, 750.0 + 25.0 * k, 5.0);
    EXPECT_FALSE(l.material.empty());
    EXPECT_EQ(l.ranking.size(), 5u);
  }

  // Nobody in front of the camera (no wall either: nothing returns).
  for (int k = 0; k < 3; ++k) show(tofmat::sim::Scene{});
  ASSERT_EQ(log.labels.size(), 6u);
  EXPECT_EQ(log.labels[5].state, "no_target");
  EXPECT_EQ(log.labels[5].frame, 5u);
  ASSERT_TRUE(log.labels[5].truth);
  EXPECT_EQ(log.labels[5].truth->material, "");

  // Back, far away: a fresh accumulation.
  show(tofmat::sim::Scene::centred_target("white", 1100.0, 0.0, 120));
  ASSERT_EQ(log.labels.size(), 7u);
  EXPECT_EQ(log.labels[6].state, "tracking");
  // One frame's worth of bins (its pixels' ranges and noise spread it over a
  // few), not the five frames' before it.
  EXPECT_LE(2 * log.labels[6].bins_covered, covered) << log.labels[6].bins_covered << " of " << covered;
}

// ---------------------------------------------------------------- sorting

class SortingBackends : public HandheldBackends {};
INSTANTIATE_TEST_SUITE_P(Backends, SortingBackends, ::testing::Values(Backend::kFixed, Backend::kFloat),
                         [](const ::testing::TestParamInfo<Backend>& backend) {
                           return std::string(backend.param == Backend::kFixed ? "fixed" : "float");
                         });

// An item on the belt under the ROI, at the bin of the belt's distance.
Patch item(const std::string& material) { return target_in_roi(material, 110); }

TEST_P(SortingBackends, NothingBeforeATriggerThenOneFinalLabelAfterItsBurst) {
  ProfileConfig c = config_of("sorting", GetParam());
  c.burst = 3;
  auto profile = make_profile(c, real_table());
  EventLog log;
  log.depth_kinds = {"80", "16", "120", "combined"};
  const auto emit = log.emitter();
  FrameMaker frames;
  std::uint64_t seq = 0;
  for (int k = 0; k < 4; ++k) profile->process(frames.draw(seq++, {item("copper")}, 3.0), emit);
  EXPECT_TRUE(log.labels.empty()) << "a label without a trigger";
  EXPECT_TRUE(log.depths.empty()) << "frames between bursts are not even decoded";

  EXPECT_EQ(profile->trigger(4), 1u);
  for (int k = 0; k < 3; ++k) profile->process(frames.draw(seq++, {item("copper")}, 3.0), emit);
  EXPECT_TRUE(log.labels.empty()) << "labelled before the burst's last frame";
  profile->process(frames.draw(seq++, {item("copper")}, 3.0), emit);
  ASSERT_EQ(log.labels.size(), 1u);
  const auto& l = log.labels[0];
  EXPECT_EQ(l.state, "final");
  EXPECT_EQ(l.profile, "sorting");
  ASSERT_TRUE(l.trigger);
  EXPECT_EQ(*l.trigger, 1u);
  EXPECT_EQ(l.material, "copper");
  EXPECT_EQ(l.frame, 7u);  // the burst's last frame
  EXPECT_EQ(log.depths.size(), 4u * 4u) << "four kinds for each of the burst's frames";

  // After the burst: nothing again.
  for (int k = 0; k < 3; ++k) profile->process(frames.draw(seq++, {item("copper")}, 3.0), emit);
  EXPECT_EQ(log.labels.size(), 1u);

  // A burst of 0 frames means the configured burst (3); a new trigger, a new number.
  EXPECT_EQ(profile->trigger(0), 2u);
  for (int k = 0; k < 3; ++k) profile->process(frames.draw(seq++, {item("acryl")}, 3.0), emit);
  ASSERT_EQ(log.labels.size(), 2u);
  EXPECT_EQ(*log.labels[1].trigger, 2u);
  EXPECT_EQ(log.labels[1].material, "acryl") << "the previous item's frames were forgotten";
}

TEST_P(SortingBackends, ABurstOverAnEmptyBeltSaysNoTarget) {
  auto profile = make_profile(config_of("sorting", GetParam()), real_table());
  EventLog log;
  const auto emit = log.emitter();
  FrameMaker frames;
  EXPECT_EQ(profile->trigger(2), 1u);
  profile->process(frames.draw(0, {}), emit);
  profile->process(frames.draw(1, {}), emit);
  ASSERT_EQ(log.labels.size(), 1u);
  EXPECT_EQ(log.labels[0].state, "no_target");
  EXPECT_EQ(log.labels[0].material, "");
  ASSERT_TRUE(log.labels[0].trigger);
  EXPECT_EQ(*log.labels[0].trigger, 1u);
}

TEST_P(SortingBackends, OnlyTheBurstsFramesThatShowTheItemCount) {
  auto profile = make_profile(config_of("sorting", GetParam()), real_table());
  EventLog log;
  const auto emit = log.emitter();
  FrameMaker frames;
  profile->trigger(4);
  // The item enters late and leaves early: two of the four frames see it.
  profile->process(frames.draw(0, {}), emit);
  profile->process(frames.draw(1, {item("silicone")}), emit);
  profile->process(frames.draw(2, {item("silicone")}), emit);
  profile->process(frames.draw(3, {}), emit);
  ASSERT_EQ(log.labels.size(), 1u);
  EXPECT_EQ(log.labels[0].state, "final");
  EXPECT_EQ(log.labels[0].material, "silicone");
}

// The belt packed tight: the burst's last frame catches the next item in
// the ROI (issue 17). Only the frames that agree with the burst's majority
// are classified together; a burst with no majority is "mixed".
TEST_P(SortingBackends, AFrameShowingAnotherItemIsLeftOutAndNoMajorityIsMixed) {
  ProfileConfig c = config_of("sorting", GetParam());
  auto profile = make_profile(c, real_table());
  EventLog log;
  const auto emit = log.emitter();
  FrameMaker frames;
  // The next item across the ROI's downstream three quarters.
  Patch next = item("acryl");
  next.region.x0 = kCentreRoi.x0 + (kCentreRoi.x1 - kCentreRoi.x0) / 4;
  profile->trigger(4);
  for (std::uint64_t k = 0; k < 3; ++k) profile->process(frames.draw(k, {item("copper")}, 3.0), emit);
  profile->process(frames.draw(3, {item("copper"), next}, 3.0), emit);
  ASSERT_EQ(log.labels.size(), 1u);
  EXPECT_EQ(log.labels[0].state, "final");
  EXPECT_EQ(log.labels[0].material, "copper");
  // The same three clean frames alone: the same label, to the last digit
  // (the mixed frame added nothing).
  auto clean = make_profile(c, real_table());
  clean->trigger(3);
  for (std::uint64_t k = 0; k < 3; ++k) clean->process(frames.draw(k, {item("copper")}, 3.0), emit);
  ASSERT_EQ(log.labels.size(), 2u);
  EXPECT_EQ(log.labels[1].distance, log.labels[0].distance);
  EXPECT_EQ(log.labels[1].valid, log.labels[0].valid);

  // Two frames of each: no majority.
  profile->trigger(4);
  for (std::uint64_t k = 10; k < 12; ++k) profile->process(frames.draw(k, {item("copper")}, 3.0), emit);
  for (std::uint64_t k = 12; k < 14; ++k) profile->process(frames.draw(k, {item("acryl")}, 3.0), emit);
  ASSERT_EQ(log.labels.size(), 3u);
  EXPECT_EQ(log.labels[2].state, "mixed");
  EXPECT_FALSE(log.labels[2].material.empty()) << "what the frames together say, for the record";
}

TEST_P(SortingBackends, ResetDisarmsATrigger) {
  ProfileConfig c = config_of("sorting", GetParam());
  c.burst = 2;
  auto profile = make_profile(c, real_table());
  EventLog log;
  const auto emit = log.emitter();
  FrameMaker frames;
  profile->trigger(0);
  profile->process(frames.draw(0, {item("pp")}), emit);
  profile->reset();
  for (std::uint64_t k = 1; k < 5; ++k) profile->process(frames.draw(k, {item("pp")}), emit);
  EXPECT_TRUE(log.labels.empty());
}

TEST(ProfileTrigger, OnlyTheSortingProfileTakesTriggers) {
  for (const char* name : {"handheld", "segmentation"}) {
    auto profile = make_profile(config_of(name), real_table());
    EXPECT_THROW(profile->trigger(4), std::logic_error) << name;
  }
  EXPECT_NO_THROW(make_profile(config_of("sorting"), real_table())->trigger(4));
}

// ---------------------------------------------------------------- segmentation

// Six rectangles in a 3 x 2 grid (the simulator's `regions` scene layout,
// smaller), each of one candidate at its own depth, on nothing.
struct RegionsScene {
  std::vector<std::string> materials;
  std::vector<Patch> patches;
};

RegionsScene regions_scene(const ExemplarTable& table) {
  RegionsScene s;
  s.materials = {"silicone", "copper", "cork", "acryl", "pp", "whiteglass"};
  // Bins where each lies at least 6 mm from every other candidate (the
  // per-pixel match has one bin's two values to go by).
  const std::uint32_t bins[6] = {150, 40, 10, 90, 70, 180};
  for (std::size_t i = 0; i < 6; ++i) {
    const int col = static_cast<int>(i % 3), row = static_cast<int>(i / 3);
    const int x0 = 16 + col * 164, y0 = 32 + row * 188;
    Patch p{{x0, y0, x0 + 128, y0 + 144}, material_at_bin(table, s.materials[i], bins[i])};
    p.amplitude = 3000.0;  // close, bright targets
    p.offset = 500.0;
    s.patches.push_back(p);
  }
  return s;
}

std::shared_ptr<const FrameTruth> regions_truth(const RegionsScene& s) {
  auto t = std::make_shared<FrameTruth>();
  t->materials = s.materials;
  t->target.assign(kPixels, -1);
  t->depth_mm.assign(kPixels, std::numeric_limits<float>::quiet_NaN());
  for (std::size_t k = 0; k < s.patches.size(); ++k) {
    const auto& r = s.patches[k].region;
    for (int y = r.y0; y < r.y1; ++y)
      for (int x = r.x0; x < r.x1; ++x)
        t->target[static_cast<std::size_t>(y) * kWidth + static_cast<std::size_t>(x)] = static_cast<std::int16_t>(k);
  }
  return t;
}

// Whether pixel (x, y) lies in `r` at least `margin` pixels from its edges.
bool inside(const PixelRegion& r, int x, int y, int margin) {
  return x >= r.x0 + margin && x < r.x1 - margin && y >= r.y0 + margin && y < r.y1 - margin;
}

class SegmentationSmoothing : public ::testing::TestWithParam<int> {};
INSTANTIATE_TEST_SUITE_P(Smooth, SegmentationSmoothing, ::testing::Values(9, 1),
                         [](const ::testing::TestParamInfo<int>& smooth) {
                           return "smooth" + std::to_string(smooth.param);
                         });

TEST_P(SegmentationSmoothing, LabelMapOfTheWholeFrameWithEachRegionsMaterial) {
  const auto table = real_table();
  const RegionsScene scene = regions_scene(*table);
  ProfileConfig c = config_of("segmentation");
  c.smooth = GetParam();
  // Given out of table order (and with one that is not in the scene): the map's
  // index is the table's order of the candidates.
  c.candidates = {"whiteglass", "pp", "acryl", "alumi", "cork", "copper", "silicone"};
  auto profile = make_profile(c, table);
  EventLog log;
  // Smoothing averages away the samples' noise; without it the frame is clean.
  const double noise = GetParam() > 1 ? 3.0 : 0.0;
  RawFrame f = make_frame(42, scene.patches, noise);
  f.truth = regions_truth(scene);
  // A few dead pixels (no signal) scattered inside every region: they have no
  // label of their own, and the majority filter gives them their neighbours'.
  std::set<std::size_t> dead;
  for (const auto& p : scene.patches)
    for (int k = 0; k < 6; ++k) {
      const int x = p.region.x0 + 20 + 19 * k, y = p.region.y0 + 15 + 23 * k;
      dead.insert(static_cast<std::size_t>(y) * kWidth + static_cast<std::size_t>(x));
    }
  for (const std::size_t i : dead)
    for (std::size_t s = 0; s < 9; ++s) f.raw[s * kPixels + i] = 0;
  profile->process(f, log.emitter());

  ASSERT_EQ(log.maps.size(), 1u);
  EXPECT_TRUE(log.labels.empty());
  const auto& m = log.maps[0];
  EXPECT_EQ(m.frame, 42u);
  EXPECT_EQ(m.timestamp_ns, f.arrival_ns);
  EXPECT_EQ(m.width, 512);
  EXPECT_EQ(m.height, 424);
  ASSERT_EQ(m.labels.size(), kPixels);
  EXPECT_EQ(m.materials,
            (std::vector<std::string>{"acryl", "alumi", "copper", "cork", "pp", "silicone", "whiteglass"}));

  // Inside each region (away from the filters' reach over its edge) every
  // pixel has the region's material (the dead ones too once filtered); far
  // from every region, none.
  const bool filtered = GetParam() > 1;
  const int margin = GetParam() / 2;
  std::size_t right = 0, target_pixels = 0;
  for (int y = 0; y < kHeight; ++y)
    for (int x = 0; x < kWidth; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * kWidth + static_cast<std::size_t>(x);
      const std::uint8_t label = m.labels[i];
      bool near_region = false;
      for (std::size_t k = 0; k < scene.patches.size(); ++k) {
        const auto& r = scene.patches[k].region;
        if (inside(r, x, y, 0)) {
          ++target_pixels;
          if (label != kNoLabel && m.materials[label] == scene.materials[k]) ++right;
        }
        if (!filtered && dead.count(i)) {
          ASSERT_EQ(label, kNoLabel) << "a dead pixel labelled without the filter, at " << x << ", " << y;
        } else if (inside(r, x, y, margin)) {
          ASSERT_NE(label, kNoLabel) << "at " << x << ", " << y;
          ASSERT_EQ(m.materials[label], scene.materials[k]) << "at " << x << ", " << y;
        }
        near_region =
            near_region ||
            inside(PixelRegion{r.x0 - margin - 1, r.y0 - margin - 1, r.x1 + margin + 1, r.y1 + margin + 1}, x, y, 0);
      }
      if (!near_region) {
        ASSERT_EQ(label, kNoLabel) << "nothing is there, at " << x << ", " << y;
      }
    }
  // The truth's accuracy is the share of target pixels labelled with their material.
  ASSERT_TRUE(m.truth_accuracy);
  EXPECT_DOUBLE_EQ(*m.truth_accuracy, static_cast<double>(right) / static_cast<double>(target_pixels));
  EXPECT_GT(*m.truth_accuracy, 0.95);
}

TEST(Segmentation, TheSameLabelMapWhateverTheThreads) {
  // Bands of rows on 1, 2, 3 and 7 threads (7 does not divide 424): every
  // step's windows reach across the bands' edges, so any seam would show.
  const auto table = real_table();
  const RegionsScene scene = regions_scene(*table);
  RawFrame f = make_frame(5, scene.patches, 3.0);
  std::vector<std::vector<std::uint8_t>> maps;
  for (int threads : {1, 2, 3, 7}) {
    ProfileConfig c = config_of("segmentation");
    c.candidates = scene.materials;
    c.threads = threads;
    auto profile = make_profile(c, table);
    EventLog log;
    profile->process(f, log.emitter());
    profile->process(f, log.emitter());  // (the second frame reuses every buffer)
    ASSERT_EQ(log.maps.size(), 2u);
    EXPECT_EQ(log.maps[1].labels, log.maps[0].labels) << threads << " threads";
    maps.push_back(log.maps[0].labels);
  }
  for (std::size_t k = 1; k < maps.size(); ++k) EXPECT_EQ(maps[k], maps[0]) << "split " << k;
}

TEST(Segmentation, RefusesThreadsOutOfRange) {
  const auto table = real_table();
  ProfileConfig c = config_of("segmentation");
  for (int threads : {-1, 65}) {
    c.threads = threads;
    EXPECT_THROW(make_profile(c, table), std::invalid_argument) << threads;
  }
}

TEST(Segmentation, NoTruthAccuracyWithoutTruthAndTheFullFrameAsDepthImage) {
  const auto table = real_table();
  const RegionsScene scene = regions_scene(*table);
  ProfileConfig c = config_of("segmentation");
  c.candidates = {"copper", "cork"};
  auto profile = make_profile(c, table);
  EventLog log;
  log.depth_kinds = {"combined"};
  const RawFrame f = make_frame(3, scene.patches);
  profile->process(f, log.emitter());
  ASSERT_EQ(log.maps.size(), 1u);
  EXPECT_FALSE(log.maps[0].truth_accuracy);
  EXPECT_EQ(log.maps[0].materials, (std::vector<std::string>{"copper", "cork"}));
  ASSERT_EQ(log.depths.size(), 1u);
  const auto& d = log.depths[0];
  EXPECT_EQ(d.kind, "combined");
  EXPECT_EQ(d.x0, 0);
  EXPECT_EQ(d.y0, 0);
  EXPECT_EQ(d.width, kWidth);
  EXPECT_EQ(d.height, kHeight);
  ASSERT_EQ(d.depth_mm.size(), kPixels);
  // Region 1 (copper) sits at bin 40; the background has no depth.
  const auto& r = scene.patches[1].region;
  const std::size_t centre =
      static_cast<std::size_t>((r.y0 + r.y1) / 2) * kWidth + static_cast<std::size_t>((r.x0 + r.x1) / 2);
  EXPECT_NEAR(d.depth_mm[centre], table->bins().centre_mm(40), 0.5);
  EXPECT_TRUE(std::isnan(d.depth_mm[0]));

  // A second frame reuses the profile's buffers: the same input, the same output.
  log.depth_kinds.clear();
  profile->process(f, log.emitter());
  ASSERT_EQ(log.maps.size(), 2u);
  EXPECT_EQ(log.maps[1].labels, log.maps[0].labels);
  EXPECT_EQ(log.depths.size(), 1u) << "no depth image once nobody wants one";
}

}  // namespace
