// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// What the handheld and sorting profiles share (firmware/daemon/src/region_matcher.cpp):
// decoding a pixel region, accumulating its Eq. (10) features into depth bins
// over frames, and Eq. (12) partial matching of the growing query, on the
// fixed-point path and the float reference; the label and depth events made
// from them; the ground truth of a region. Also the accumulation's life cycle
// as the handheld profile drives it: reset when the target leaves or jumps by
// more than jump_mm, and the min_valid_fraction that decides whether a target
// is there at all.
//
// Frames come from the phasor model (daemon_frames.hpp): a region shows a
// material of the real database exactly, so the right label and its distance
// (about 0) are known without the daemon.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "daemon_frames.hpp"
#include "test_util.hpp"
#include "tofmat/core/compact_table.hpp"
#include "tofmat/core/confidence.hpp"
#include "tofmat/core/session_classifier.hpp"
#include "tofmat/daemon/region_matcher.hpp"

namespace {

using namespace tofmat_test;
using tofmat::BinSpec;
using tofmat::ExemplarTable;
using tofmat::daemon::Backend;
using tofmat::daemon::FrameTruth;
using tofmat::daemon::ProfileConfig;
using tofmat::daemon::RawFrame;
using tofmat::daemon::RegionMatcher;
using tofmat::protocol::LabelEvent;

std::string backend_name(Backend b) { return b == Backend::kFixed ? "fixed" : "float"; }

class RegionMatcherBackends : public ::testing::TestWithParam<Backend> {};
INSTANTIATE_TEST_SUITE_P(Backends, RegionMatcherBackends, ::testing::Values(Backend::kFixed, Backend::kFloat),
                         [](const ::testing::TestParamInfo<Backend>& backend) { return backend_name(backend.param); });

std::uint32_t material_index(const ExemplarTable& t, const std::string& name) {
  return static_cast<std::uint32_t>(t.index_of(name));
}

// Frames of `material` filling the ROI at bins first, first + step, ... (count
// of them): a hand-held sweep away from the camera.
void sweep(RegionMatcher& m, const std::string& material, std::uint32_t first, std::uint32_t count,
           std::uint32_t step = 1, double noise = 0.0) {
  FrameMaker frames;
  for (std::uint32_t k = 0; k < count; ++k) {
    const RawFrame& f = frames.draw(k, {target_in_roi(material, first + k * step)}, noise);
    m.accumulate(m.decode(f, kCentreRoi));
  }
}

TEST_P(RegionMatcherBackends, DecodeCountsTheRegionsPixelsAndTheValidOnesAndTheirMedianDepth) {
  const auto table = real_table();
  const RegionMatcher m(table, {}, GetParam());
  const std::uint32_t bin = 100;
  const double depth = table->bins().centre_mm(bin);

  const auto full = m.decode(make_frame(1, {target_in_roi("pvc", bin)}), kCentreRoi);
  EXPECT_EQ(full.pixels, 48u * 48u);
  EXPECT_EQ(full.valid, 48u * 48u);
  EXPECT_NEAR(full.median_mm, depth, 0.5);
  EXPECT_EQ(full.region.x0, kCentreRoi.x0);
  EXPECT_EQ(full.region.y1, kCentreRoi.y1);

  // The target covers the ROI's left 20 columns; the rest sees nothing.
  const Patch left{{200, 150, 252, 260}, material_at_bin(*table, "pvc", bin)};
  const auto part = m.decode(make_frame(2, {left}), kCentreRoi);
  EXPECT_EQ(part.pixels, 48u * 48u);
  EXPECT_EQ(part.valid, 20u * 48u);
  EXPECT_NEAR(part.median_mm, depth, 0.5);

  const auto none = m.decode(make_frame(3, {}), kCentreRoi);
  EXPECT_EQ(none.pixels, 48u * 48u);
  EXPECT_EQ(none.valid, 0u);
  EXPECT_TRUE(std::isnan(none.median_mm));
}

TEST_P(RegionMatcherBackends, NothingToClassifyBeforeAnObservation) {
  RegionMatcher m(real_table(), {}, GetParam());
  EXPECT_FALSE(m.classify());
  EXPECT_EQ(m.bins_covered(), 0u);
  // A region with no valid pixel adds nothing either.
  m.accumulate(m.decode(make_frame(1, {}), kCentreRoi));
  EXPECT_FALSE(m.classify());
  EXPECT_EQ(m.bins_covered(), 0u);
}

TEST_P(RegionMatcherBackends, EachFrameAddsItsBinAndTheSweepMatchesItsMaterial) {
  const auto table = real_table();
  RegionMatcher m(table, {}, GetParam());
  const std::uint32_t first = 60, frames = 12;
  FrameMaker maker;
  for (std::uint32_t k = 0; k < frames; ++k) {
    m.accumulate(m.decode(maker.draw(k, {target_in_roi("copper", first + 2 * k)}), kCentreRoi));
    EXPECT_EQ(m.bins_covered(), k + 1) << "after frame " << k;
    const auto c = m.classify();
    ASSERT_TRUE(c);
    EXPECT_EQ(table->materials()[c->best().index], "copper") << "after frame " << k;
    EXPECT_EQ(c->best().valid, 2 * (k + 1)) << "both rows of every observed bin";
  }
  const auto c = m.classify();
  EXPECT_LT(c->best().distance, 0.05);  // the curve itself, up to the samples' rounding
  EXPECT_GT(c->ranking[1].distance, 10.0 * c->best().distance + 1.0);
  EXPECT_EQ(c->ranking.size(), table->n_materials());
  // The same frame again adds to its bin, not a new one.
  m.accumulate(m.decode(maker.draw(99, {target_in_roi("copper", first)}), kCentreRoi));
  EXPECT_EQ(m.bins_covered(), frames);
}

// A 12-frame sweep of cork whose 16 MHz group reads row0_mm high (row 0,
// d16 - d120) and 80 MHz group row1_mm high (row 1, d80 - d120), as another
// session's offsets would move them, accumulated into each matcher.
void offset_cork_sweep(double row0_mm, double row1_mm, std::initializer_list<RegionMatcher*> matchers) {
  FrameMaker maker;
  for (std::uint32_t k = 0; k < 12; ++k) {
    auto target = target_in_roi("cork", 40 + 8 * k);
    target.depths.mm[1] += row0_mm;
    target.depths.mm[0] += row1_mm;
    const RawFrame& f = maker.draw(k, {target});
    for (RegionMatcher* m : matchers) m->accumulate(m->decode(f, kCentreRoi));
  }
}

TEST_P(RegionMatcherBackends, TheSessionClassifierForgivesASessionsOffset) {
  // A sweep of cork whose 16 MHz row reads 3 mm high (another session's
  // offset, added to the query as the camera would): Eq. (12) takes it for
  // another material, the session classifier still says cork.
  const auto table = real_table();
  RegionMatcher eq12(table, {}, GetParam());
  RegionMatcher session(table, {}, GetParam(), tofmat::daemon::Method::kSession);
  offset_cork_sweep(3.0, 0.0, {&eq12, &session});
  const auto a = eq12.classify(), b = session.classify();
  ASSERT_TRUE(a && b);
  EXPECT_NE(table->materials()[a->best().index], "cork");
  EXPECT_EQ(table->materials()[b->best().index], "cork");
  EXPECT_EQ(b->ranking.size(), table->n_materials());
  EXPECT_EQ(b->best().valid, 24u);
  // The label event carries the score as its distance.
  const LabelEvent e = session.label_event(*b, 3);
  EXPECT_EQ(e.material, "cork");
  EXPECT_EQ(e.distance, b->best().distance);
  EXPECT_EQ(e.ranking.size(), 3u);
  // With its calibrated confidence and its fit; Eq. (12) has a confidence but no fit.
  ASSERT_TRUE(e.confidence && e.fit);
  EXPECT_GT(*e.confidence, 0.0);
  EXPECT_LE(*e.confidence, 1.0);
  EXPECT_EQ(*e.fit, b->best().fit);
  EXPECT_FALSE(session.unknown(*b));
  const LabelEvent f = eq12.label_event(*a, 3);
  EXPECT_TRUE(f.confidence && !f.fit);
}

TEST_P(RegionMatcherBackends, AVagueBestMatchGivesAFlatterConfidence) {
  // fakeleather's curve is the real table's roughest (its vagueness 3.5: its element variance over
  // the table's typical one). A noisy sweep of it is labelled fakeleather with the confidence
  // judge() gives with the session matcher's vagueness (the fit judged at the table's typical
  // noise): 0.70 against 0.998 at fakeleather's own noise.
  const auto table = real_table();
  const std::uint32_t fake = material_index(*table, "fakeleather");
  const auto vagueness = tofmat::SessionClassifier(table, tofmat::SessionPrior::tuned(*table)).vagueness();
  ASSERT_GT(vagueness[fake], 3.0);
  RegionMatcher session(table, {}, GetParam(), tofmat::daemon::Method::kSession);
  sweep(session, "fakeleather", 40, 30, 3, 100.0);  // (100 counts of sample noise: its fit about 4)
  const auto c = session.classify();
  ASSERT_TRUE(c);
  ASSERT_EQ(c->best().index, fake);
  const auto calibration = tofmat::Calibration::tuned("session", *table);
  const double with = judge(*c, table->n_rows(), calibration, vagueness).confidence();
  const double without = judge(*c, table->n_rows(), calibration).confidence();
  const LabelEvent e = session.label_event(*c, 3);
  ASSERT_TRUE(e.confidence);
  EXPECT_DOUBLE_EQ(*e.confidence, with);
  EXPECT_LT(with, without);
}

TEST_P(RegionMatcherBackends, ASweepNoMaterialExplainsIsUnknown) {
  // Cork read 40 mm high on the 16 MHz row and 40 mm low on the 80 MHz row,
  // far beyond any session's offset (sd 2.27 and 0.73 mm) and unlike every
  // material's curve: the session matcher names none; Eq. (12) still does.
  const auto table = real_table();
  RegionMatcher eq12(table, {}, GetParam());
  RegionMatcher session(table, {}, GetParam(), tofmat::daemon::Method::kSession, /*open_set=*/true);
  RegionMatcher closed(table, {}, GetParam(), tofmat::daemon::Method::kSession);  // open set off: the default
  offset_cork_sweep(40.0, -40.0, {&eq12, &session, &closed});
  const auto a = eq12.classify(), b = session.classify(), c = closed.classify();
  ASSERT_TRUE(a && b && c);
  EXPECT_FALSE(closed.unknown(*c));
  EXPECT_NE(closed.label_event(*c, 3).material, "");
  EXPECT_TRUE(session.unknown(*b));
  const LabelEvent e = session.label_event(*b, 3);
  EXPECT_EQ(e.material, "");
  EXPECT_EQ(e.index, -1);
  EXPECT_EQ(e.ranking.size(), 3u);  // the nearest ones, still
  EXPECT_FALSE(eq12.unknown(*a));
  EXPECT_NE(eq12.label_event(*a, 3).material, "");
}

TEST_P(RegionMatcherBackends, ASweepOfAnOrdinaryMaterialIsToldFromItsNeighbours) {
  // Cork, wood, mdf, pvc ... lie within a millimetre of each other: only the
  // accumulated curve separates them.
  const auto table = real_table();
  RegionMatcher m(table, {}, GetParam());
  sweep(m, "cork", 20, 24, 6, /*noise=*/3.0);
  const auto c = m.classify();
  ASSERT_TRUE(c);
  EXPECT_EQ(table->materials()[c->best().index], "cork");
  // The samples' noise spreads each frame's combined depth over neighbouring bins.
  EXPECT_GE(m.bins_covered(), 24u);
  EXPECT_LE(m.bins_covered(), 3 * 24u);
}

// Three materials on 60 bins of 10 mm: a and b are the same curve on bins
// 0..29 and 8 mm apart on 30..59; c is unobserved on 0..29 and 3 mm from b on
// 30..59. Partial matching must compare only the elements both sides hold.
std::shared_ptr<const ExemplarTable> partial_table() {
  const std::uint32_t n = 60;
  std::vector<float> v(3 * 2 * n, std::numeric_limits<float>::quiet_NaN());
  auto at = [&](std::size_t m, std::size_t r, std::size_t j) -> float& { return v[(m * 2 + r) * n + j]; };
  for (std::uint32_t j = 0; j < n; ++j) {
    const float f16 = 70.0f - 0.5f * static_cast<float>(j), f80 = -4.0f + 0.1f * static_cast<float>(j);
    const float apart = j < 30 ? 0.0f : 8.0f;
    at(0, 0, j) = f16;
    at(0, 1, j) = f80;
    at(1, 0, j) = f16 + apart;
    at(1, 1, j) = f80 + apart;
    if (j >= 30) {
      at(2, 0, j) = f16 + apart + 3.0f;
      at(2, 1, j) = f80 + apart + 3.0f;
    }
  }
  return std::make_shared<const ExemplarTable>(std::vector<std::string>{"a", "b", "c"}, tofmat::kinect2_database_rows(),
                                               BinSpec{600.0, 10.0, n}, v);
}

TEST_P(RegionMatcherBackends, PartialMatchingComparesOnlyTheElementsObserved) {
  const auto table = partial_table();
  RegionMatcher m(table, {}, GetParam());
  FrameMaker maker;
  auto observe = [&](const std::string& material, std::uint32_t bin) {
    const Patch p{{228, 184, 284, 240}, material_at_bin(*table, material, bin)};
    m.accumulate(m.decode(maker.draw(bin, {p}), kCentreRoi));
  };
  for (std::uint32_t bin = 10; bin < 15; ++bin) observe("a", bin);
  auto c = m.classify();
  ASSERT_TRUE(c);
  // a and b hold the same values there: a tie, won by the lower index; c has
  // nothing in common with the query and is left out.
  ASSERT_EQ(c->ranking.size(), 2u);
  EXPECT_EQ(c->ranking[0].index, 0u);
  EXPECT_EQ(c->ranking[1].index, 1u);
  EXPECT_NEAR(c->ranking[0].distance, 0.0, 0.05);
  EXPECT_NEAR(c->ranking[1].distance, 0.0, 0.05);
  EXPECT_EQ(c->ranking[0].valid, 10u);

  for (std::uint32_t bin = 40; bin < 45; ++bin) observe("b", bin);
  c = m.classify();
  ASSERT_TRUE(c);
  ASSERT_EQ(c->ranking.size(), 3u);
  std::map<std::uint32_t, tofmat::Match> by_index;
  for (const auto& r : c->ranking) by_index[r.index] = r;
  EXPECT_EQ(c->best().index, 1u);
  EXPECT_EQ(c->ranking[1].index, 2u);
  EXPECT_EQ(c->ranking[2].index, 0u);
  EXPECT_EQ(by_index[0].valid, 20u);
  EXPECT_EQ(by_index[1].valid, 20u);
  EXPECT_EQ(by_index[2].valid, 10u);                       // only the bins c holds
  EXPECT_NEAR(by_index[0].distance, 10 * 64.0 / 20, 0.5);  // 8 mm on half of a's elements
  EXPECT_NEAR(by_index[1].distance, 0.0, 0.05);
  EXPECT_NEAR(by_index[2].distance, 9.0, 0.5);  // 3 mm on each common element
}

TEST_P(RegionMatcherBackends, ResetForgetsEveryObservation) {
  const auto table = real_table();
  RegionMatcher m(table, {}, GetParam());
  sweep(m, "copper", 50, 10);
  ASSERT_EQ(m.bins_covered(), 10u);
  m.reset();
  EXPECT_EQ(m.bins_covered(), 0u);
  EXPECT_FALSE(m.classify());
  // What comes after a reset is matched on its own, not mixed with the old target.
  sweep(m, "acryl", 50, 10);
  const auto c = m.classify();
  ASSERT_TRUE(c);
  EXPECT_EQ(table->materials()[c->best().index], "acryl");
  EXPECT_LT(c->best().distance, 0.05);
}

// A twin (the sorting profile's per-frame matcher) has the same candidates
// and method but an accumulation of its own: neither sees the other's frames.
TEST_P(RegionMatcherBackends, ATwinMatchesLikeItsOriginalWithItsOwnFrames) {
  const auto table = real_table();
  const std::vector<std::uint32_t> candidates = {material_index(*table, "acryl"), material_index(*table, "copper"),
                                                 material_index(*table, "cork")};
  for (auto method : {tofmat::daemon::Method::kEq12, tofmat::daemon::Method::kSession}) {
    RegionMatcher m(table, candidates, GetParam(), method);
    sweep(m, "copper", 50, 10);
    RegionMatcher t = m.twin();
    EXPECT_EQ(t.bins_covered(), 0u);
    EXPECT_FALSE(t.classify());
    sweep(t, "acryl", 120, 6);
    ASSERT_TRUE(t.classify());
    ASSERT_TRUE(m.classify());
    EXPECT_EQ(table->materials()[t.classify()->best().index], "acryl");
    EXPECT_EQ(table->materials()[m.classify()->best().index], "copper");  // (its own ten frames, untouched)
    EXPECT_EQ(m.bins_covered(), 10u);
    EXPECT_EQ(t.classify()->ranking.size(), candidates.size());  // the same candidates
    // The same query gives the same ranking in both (one classifier).
    RegionMatcher fresh = m.twin();
    sweep(fresh, "acryl", 120, 6);
    EXPECT_EQ(fresh.classify()->best().distance, t.classify()->best().distance);
  }
}

TEST_P(RegionMatcherBackends, CandidateSubsetRanksOnlyTheCandidatesInTheFullTablesOrder) {
  const auto table = real_table();
  const std::vector<std::uint32_t> subset = {material_index(*table, "silicone"), material_index(*table, "pvc"),
                                             material_index(*table, "copper")};
  RegionMatcher all(table, {}, GetParam());
  RegionMatcher some(table, subset, GetParam());
  // Acryl is not a candidate: the answer is the nearest of the three.
  FrameMaker maker;
  for (std::uint32_t k = 0; k < 15; ++k) {
    // (The decode does not depend on the candidates: one serves both.)
    const auto d = all.decode(maker.draw(k, {target_in_roi("acryl", 40 + 5 * k)}), kCentreRoi);
    all.accumulate(d);
    some.accumulate(d);
  }
  const auto full = all.classify();
  const auto part = some.classify();
  ASSERT_TRUE(full && part);
  EXPECT_EQ(table->materials()[full->best().index], "acryl");
  ASSERT_EQ(part->ranking.size(), 3u);
  std::vector<std::uint32_t> expected;  // the full ranking restricted to the candidates
  for (const auto& r : full->ranking)
    if (std::find(subset.begin(), subset.end(), r.index) != subset.end()) expected.push_back(r.index);
  std::vector<std::uint32_t> got;
  for (const auto& r : part->ranking) got.push_back(r.index);
  EXPECT_EQ(got, expected);
  EXPECT_NE(part->best().index, material_index(*table, "acryl"));
  // Indices stay those of the full table (what label events report).
  const LabelEvent e = some.label_event(*part, 5);
  EXPECT_EQ(e.index, static_cast<std::int32_t>(part->best().index));
  EXPECT_EQ(e.material, table->materials()[part->best().index]);
  ASSERT_EQ(e.ranking.size(), 3u);
  for (std::size_t i = 0; i < 3; ++i) EXPECT_EQ(e.ranking[i].material, table->materials()[got[i]]);
}

TEST_P(RegionMatcherBackends, LabelEventCarriesTheBestMatchAndTheTopKOfTheRanking) {
  const auto table = real_table();
  RegionMatcher m(table, {}, GetParam());
  sweep(m, "whiteglass", 70, 6, 3);
  const auto c = m.classify();
  ASSERT_TRUE(c);
  const LabelEvent e = m.label_event(*c, 3);
  EXPECT_EQ(e.material, "whiteglass");
  EXPECT_EQ(e.index, table->index_of("whiteglass"));
  EXPECT_EQ(e.distance, c->best().distance);
  EXPECT_EQ(e.valid, 12u);
  EXPECT_EQ(e.bins_covered, 6u);
  ASSERT_EQ(e.ranking.size(), 3u);
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(e.ranking[i].material, table->materials()[c->ranking[i].index]);
    EXPECT_EQ(e.ranking[i].distance, c->ranking[i].distance);
  }
  EXPECT_EQ(m.label_event(*c, 64).ranking.size(), table->n_materials());  // no more than there are
  EXPECT_EQ(m.label_event(*c, 0).ranking.size(), 1u);                     // never an empty ranking
}

TEST(RegionMatcher, FixedAndFloatBackendsAgreeOnCleanData) {
  const auto table = real_table();
  RegionMatcher fixed(table, {}, Backend::kFixed), ref(table, {}, Backend::kFloat);
  FrameMaker maker;
  for (std::uint32_t k = 0; k < 20; ++k) {
    const RawFrame& f = maker.draw(k, {target_in_roi("pp", 30 + 6 * k)});
    fixed.accumulate(fixed.decode(f, kCentreRoi));
    ref.accumulate(ref.decode(f, kCentreRoi));
  }
  EXPECT_EQ(fixed.bins_covered(), ref.bins_covered());
  const auto a = fixed.classify(), b = ref.classify();
  ASSERT_TRUE(a && b);
  ASSERT_EQ(a->ranking.size(), b->ranking.size());
  EXPECT_EQ(a->best().index, b->best().index);
  EXPECT_EQ(table->materials()[b->best().index], "pp");
  // docs/numerics.md: the fixed query moves by at most half the compact
  // table's step per element (plus the decode's 0.004 mm feature budget), so
  // a distance d moves by at most 2 e sqrt(d) + e^2, and two materials can
  // swap places only where their float distances are closer than that.
  const double e = tofmat::CompactTable(*table).step_mm() / 2.0 + 0.01;
  std::map<std::uint32_t, std::size_t> fixed_rank;
  for (std::size_t i = 0; i < a->ranking.size(); ++i) fixed_rank[a->ranking[i].index] = i;
  for (std::size_t i = 0; i < b->ranking.size(); ++i) {
    const auto& r = b->ranking[i];
    const auto& q = a->ranking[fixed_rank.at(r.index)];
    const double tol = 2.0 * e * std::sqrt(r.distance) + e * e;
    EXPECT_EQ(q.valid, r.valid) << table->materials()[r.index];
    EXPECT_NEAR(q.distance, r.distance, tol) << table->materials()[r.index];
    for (std::size_t j = i + 1; j < b->ranking.size(); ++j) {
      const auto& s = b->ranking[j];
      if (s.distance - r.distance > 2.0 * (2.0 * e * std::sqrt(s.distance) + e * e)) {
        EXPECT_LT(fixed_rank.at(r.index), fixed_rank.at(s.index))
            << table->materials()[r.index] << " before " << table->materials()[s.index];
      }
    }
  }
}

TEST_P(RegionMatcherBackends, DepthEventsOnlyOfTheKindsWantedWithTheRegionsDepths) {
  const auto table = real_table();
  const RegionMatcher m(table, {}, GetParam());
  const std::uint32_t bin = 80;
  const GroupDepths depths = material_at_bin(*table, "pvc", bin);
  // The target covers the ROI's left 30 columns.
  const RawFrame f = make_frame(7, {Patch{{200, 150, 262, 260}, depths}});
  const auto d = m.decode(f, kCentreRoi);

  EventLog log;
  log.depth_kinds = {"120", "combined"};
  RegionMatcher::emit_depths(d, f, log.emitter());
  ASSERT_EQ(log.depths.size(), 2u);
  EXPECT_EQ(log.depths[0].kind, "120");
  EXPECT_EQ(log.depths[1].kind, "combined");
  for (const auto& e : log.depths) {
    EXPECT_EQ(e.frame, 7u);
    EXPECT_EQ(e.timestamp_ns, f.arrival_ns);
    EXPECT_EQ(e.x0, kCentreRoi.x0);
    EXPECT_EQ(e.y0, kCentreRoi.y0);
    EXPECT_EQ(e.width, 48);
    EXPECT_EQ(e.height, 48);
    ASSERT_EQ(e.depth_mm.size(), 48u * 48u);
    const double expected = e.kind == "120" ? depths.mm[2] : table->bins().centre_mm(bin);
    for (int y = 0; y < 48; ++y)
      for (int x = 0; x < 48; ++x) {
        const float v = e.depth_mm[static_cast<std::size_t>(y) * 48 + static_cast<std::size_t>(x)];
        if (x < 30) {
          ASSERT_NEAR(v, expected, 1.0) << e.kind << " at " << x << ", " << y;
        } else {
          ASSERT_TRUE(std::isnan(v)) << e.kind << " at " << x << ", " << y << " is " << v;
        }
      }
  }

  log.clear();
  log.depth_kinds = {"80", "16", "120", "combined"};
  RegionMatcher::emit_depths(d, f, log.emitter());
  EXPECT_EQ(log.depths.size(), 4u);

  log.clear();
  log.depth_kinds.clear();
  RegionMatcher::emit_depths(d, f, log.emitter());
  EXPECT_TRUE(log.depths.empty());
  tofmat::daemon::Emitter no_wants = log.emitter();
  no_wants.wants_depth = nullptr;  // nobody asked: nothing is made
  RegionMatcher::emit_depths(d, f, no_wants);
  EXPECT_TRUE(log.depths.empty());
}

// A truth image with the ROI's pixels given to targets in the shares asked.
std::shared_ptr<const FrameTruth> roi_truth(const std::vector<std::pair<std::int16_t, int>>& columns_of_target) {
  auto t = std::make_shared<FrameTruth>();
  t->materials = {"cork", "pvc"};
  t->target.assign(kPixels, -1);
  t->depth_mm.assign(kPixels, std::numeric_limits<float>::quiet_NaN());
  int x = kCentreRoi.x0;
  for (const auto& [target, columns] : columns_of_target) {
    for (int c = 0; c < columns; ++c, ++x)
      for (int y = kCentreRoi.y0; y < kCentreRoi.y1; ++y) {
        const std::size_t i = static_cast<std::size_t>(y) * kWidth + static_cast<std::size_t>(x);
        t->target[i] = target;
        t->depth_mm[i] = 700.0f + 100.0f * static_cast<float>(target) + static_cast<float>(y - kCentreRoi.y0);
      }
  }
  return t;
}

TEST(RegionTruth, TheMaterialFillingMostOfTheRegionAndItsMeanDepth) {
  RawFrame f = make_frame(1, {});
  EXPECT_FALSE(tofmat::daemon::region_truth(f, kCentreRoi)) << "a real camera's frame has no truth";

  f.truth = roi_truth({{1, 36}, {0, 12}});
  auto t = tofmat::daemon::region_truth(f, kCentreRoi);
  ASSERT_TRUE(t);
  EXPECT_EQ(t->material, "pvc");
  EXPECT_NEAR(t->depth_mm, 800.0 + 23.5, 1e-6);  // 800 mm plus the mean of rows 0..47

  // No target fills half the region: a truth that says "nothing".
  f.truth = roi_truth({{1, 20}, {0, 20}});
  t = tofmat::daemon::region_truth(f, kCentreRoi);
  ASSERT_TRUE(t);
  EXPECT_EQ(t->material, "");

  // Exactly half is enough; a target index beyond the truth's materials is nothing.
  f.truth = roi_truth({{0, 24}, {7, 24}});
  t = tofmat::daemon::region_truth(f, kCentreRoi);
  ASSERT_TRUE(t);
  EXPECT_EQ(t->material, "cork");
  EXPECT_NEAR(t->depth_mm, 700.0 + 23.5, 1e-6);
}

// The accumulation's life cycle as the handheld profile drives it.
std::vector<LabelEvent> handheld(const ProfileConfig& config, const std::vector<std::vector<Patch>>& frames) {
  auto profile = tofmat::daemon::make_profile(config, real_table());
  EventLog log;
  const auto emit = log.emitter();
  FrameMaker maker;
  for (std::size_t k = 0; k < frames.size(); ++k) profile->process(maker.draw(k, frames[k]), emit);
  return log.labels;
}

ProfileConfig handheld_config(Backend backend) {
  ProfileConfig c;
  c.name = "handheld";
  c.backend = backend;
  return c;
}

TEST_P(RegionMatcherBackends, HandheldStartsAfreshWhenTheTargetJumpsByMoreThanJumpMm) {
  // Bins are 3.015 mm: 20 bins are 60 mm (a sweep), 100 bins 300 mm (another target).
  std::vector<std::vector<Patch>> frames;
  for (std::uint32_t b : {40u, 60u, 80u, 180u, 185u}) frames.push_back({target_in_roi("silicone", b)});
  auto labels = handheld(handheld_config(GetParam()), frames);
  ASSERT_EQ(labels.size(), 5u);
  std::vector<std::uint32_t> covered;
  for (const auto& l : labels) {
    EXPECT_EQ(l.state, "tracking");
    covered.push_back(l.bins_covered);
  }
  EXPECT_EQ(covered, (std::vector<std::uint32_t>{1, 2, 3, 1, 2}));

  ProfileConfig lenient = handheld_config(GetParam());
  lenient.jump_mm = 400.0;
  labels = handheld(lenient, frames);
  covered.clear();
  for (const auto& l : labels) covered.push_back(l.bins_covered);
  EXPECT_EQ(covered, (std::vector<std::uint32_t>{1, 2, 3, 4, 5}));
}

TEST_P(RegionMatcherBackends, HandheldStartsAfreshAfterTheTargetLeaves) {
  const std::vector<std::vector<Patch>> frames = {
      {target_in_roi("pp", 50)}, {target_in_roi("pp", 55)}, {}, {target_in_roi("pp", 60)}, {target_in_roi("pp", 65)}};
  const auto labels = handheld(handheld_config(GetParam()), frames);
  ASSERT_EQ(labels.size(), 5u);
  EXPECT_EQ(labels[1].bins_covered, 2u);
  EXPECT_EQ(labels[2].state, "no_target");
  EXPECT_EQ(labels[2].frame, 2u);
  EXPECT_EQ(labels[3].state, "tracking");
  EXPECT_EQ(labels[3].bins_covered, 1u);
  EXPECT_EQ(labels[4].bins_covered, 2u);
}

TEST_P(RegionMatcherBackends, HandheldSeesATargetOnlyWhenItFillsMinValidFractionOfTheRoi) {
  const auto table = real_table();
  // Targets covering the ROI's left 24 (exactly half) or 23 columns.
  auto covering = [&](int columns) {
    return std::vector<Patch>{Patch{{150, 100, kCentreRoi.x0 + columns, 300}, material_at_bin(*table, "copper", 90)}};
  };
  ProfileConfig c = handheld_config(GetParam());
  c.min_valid_fraction = 0.5;
  auto labels = handheld(c, {covering(24), covering(24)});
  ASSERT_EQ(labels.size(), 2u) << "half the ROI is enough at 0.5";
  EXPECT_EQ(labels[1].state, "tracking");
  EXPECT_EQ(labels[1].valid, 2u);

  labels = handheld(c, {covering(23), covering(23)});
  EXPECT_TRUE(labels.empty()) << "a target never seen is never reported, not even as no_target";

  // Seen, then too small: it left.
  labels = handheld(c, {covering(48), covering(23), covering(10)});
  ASSERT_EQ(labels.size(), 2u);
  EXPECT_EQ(labels[0].state, "tracking");
  EXPECT_EQ(labels[1].state, "no_target");

  c.min_valid_fraction = 0.2;
  labels = handheld(c, {covering(10), covering(23)});
  ASSERT_EQ(labels.size(), 2u);
  EXPECT_EQ(labels[0].state, "tracking");
  EXPECT_EQ(labels[0].material, "copper");
}

}  // namespace
