// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The fixed-point path of Eq. (12): the compact table, the squared-sum kernel
// (scalar against a plain reference everywhere; NEON against scalar bit for
// bit where the build is aarch64, run under qemu-aarch64), and the fixed
// classifier against the float reference on the real database.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <iostream>
#include <limits>
#include <memory>
#include <random>
#include <vector>

#include "test_util.hpp"
#include "tofmat/core/classifier.hpp"
#include "tofmat/core/compact_table.hpp"
#include "tofmat/core/fixed_classifier.hpp"
#include "tofmat/core/fixed_distance.hpp"
#include "tofmat/core/table_file.hpp"

namespace {

using namespace tofmat;
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// A kernel input: values and validity per element (unpacked), plus the packed
// form the kernel takes.
struct KernelCase {
  std::vector<std::int16_t> q, e;
  std::vector<bool> qv, ev;
  bool e_all_valid = false;
  std::vector<std::uint8_t> qmask, emask;
  void pack() {
    qmask.assign(q.size() / 8, 0);
    emask.assign(q.size() / 8, 0);
    for (std::size_t i = 0; i < q.size(); ++i) {
      if (qv[i]) qmask[i / 8] = static_cast<std::uint8_t>(qmask[i / 8] | (1u << (i % 8)));
      if (ev[i]) emask[i / 8] = static_cast<std::uint8_t>(emask[i / 8] | (1u << (i % 8)));
    }
  }
  const std::uint8_t* em() const { return e_all_valid ? nullptr : emask.data(); }
  std::size_t blocks() const { return q.size() / 8; }
};

// The plain definition, element by element in 64-bit integers.
SquaredSum reference(const KernelCase& k) {
  SquaredSum s;
  for (std::size_t i = 0; i < k.q.size(); ++i) {
    if (!k.qv[i] || !(k.e_all_valid || k.ev[i])) continue;
    const std::int64_t d = static_cast<std::int64_t>(k.q[i]) - k.e[i];
    s.sum += static_cast<std::uint64_t>(d * d);
    ++s.count;
  }
  return s;
}

KernelCase random_case(std::mt19937& rng, std::size_t blocks, double p_valid, std::int16_t range) {
  KernelCase k;
  std::uniform_int_distribution<int> v(-range, range);
  std::bernoulli_distribution valid(p_valid);
  for (std::size_t i = 0; i < blocks * 8; ++i) {
    k.q.push_back(static_cast<std::int16_t>(v(rng)));
    k.e.push_back(static_cast<std::int16_t>(v(rng)));
    k.qv.push_back(valid(rng));
    k.ev.push_back(valid(rng));
  }
  k.pack();
  return k;
}

// Random and edge inputs: saturated opposite values (the largest square),
// nothing valid, one valid element, all valid, an all-valid exemplar, the
// longest vectors a table can have (16 rows x 65,535 bins).
std::vector<KernelCase> kernel_cases() {
  std::mt19937 rng(5);
  std::vector<KernelCase> out;
  for (std::size_t blocks : {1u, 2u, 7u, 50u, 333u}) {
    for (double p : {0.0, 0.1, 0.5, 1.0}) out.push_back(random_case(rng, blocks, p, 32767));
  }
  KernelCase sat;
  for (int i = 0; i < 64; ++i) {
    sat.q.push_back(i % 2 ? 32767 : -32767);
    sat.e.push_back(i % 2 ? -32767 : 32767);
    sat.qv.push_back(true);
    sat.ev.push_back(true);
  }
  sat.pack();
  out.push_back(sat);
  KernelCase one = random_case(rng, 4, 0.0, 32767);
  one.qv[13] = one.ev[13] = true;
  one.pack();
  out.push_back(one);
  KernelCase all_valid_e = random_case(rng, 9, 0.6, 1000);
  all_valid_e.e_all_valid = true;
  out.push_back(all_valid_e);
  KernelCase longest = random_case(rng, 16u * 65535u / 8u, 0.9, 32767);
  for (std::size_t i = 0; i < longest.q.size(); i += 3) {  // many saturated pairs: the sum's worst case
    longest.q[i] = 32767;
    longest.e[i] = -32767;
  }
  out.push_back(longest);
  return out;
}

TEST(FixedKernel, ScalarEqualsThePlainDefinition) {
  for (const auto& k : kernel_cases()) {
    const SquaredSum want = reference(k);
    const SquaredSum got = squared_sum_scalar(k.q.data(), k.qmask.data(), k.e.data(), k.em(), k.blocks());
    ASSERT_EQ(got.sum, want.sum) << k.blocks() << " blocks";
    ASSERT_EQ(got.count, want.count) << k.blocks() << " blocks";
  }
  // The largest square: 65534^2 per element, no wrap.
  KernelCase sat = kernel_cases()[20];
  EXPECT_EQ(squared_sum_scalar(sat.q.data(), sat.qmask.data(), sat.e.data(), sat.em(), sat.blocks()).sum,
            64ull * 65534ull * 65534ull);
}

#if defined(__aarch64__)
TEST(FixedKernel, NeonIsBitExactWithScalar) {
  EXPECT_STREQ(squared_sum_kernel(), "neon");
  for (const auto& k : kernel_cases()) {
    const SquaredSum s = squared_sum_scalar(k.q.data(), k.qmask.data(), k.e.data(), k.em(), k.blocks());
    const SquaredSum n = squared_sum_neon(k.q.data(), k.qmask.data(), k.e.data(), k.em(), k.blocks());
    ASSERT_EQ(n.sum, s.sum) << k.blocks() << " blocks";
    ASSERT_EQ(n.count, s.count) << k.blocks() << " blocks";
  }
  std::mt19937 rng(11);  // and many short random ones, every mask pattern likely
  for (int i = 0; i < 20000; ++i) {
    KernelCase k = random_case(rng, 1 + static_cast<std::size_t>(i % 5), (i % 11) / 10.0, 32767);
    k.e_all_valid = i % 7 == 0;
    ASSERT_EQ(squared_sum_neon(k.q.data(), k.qmask.data(), k.e.data(), k.em(), k.blocks()),
              squared_sum_scalar(k.q.data(), k.qmask.data(), k.e.data(), k.em(), k.blocks()))
        << i;
  }
}
#else
TEST(FixedKernel, ThisBuildUsesTheScalarKernel) { EXPECT_STREQ(squared_sum_kernel(), "scalar"); }
#endif

std::shared_ptr<const ExemplarTable> real_table() {
  return std::make_shared<const ExemplarTable>(ExemplarTable::from_npy_dir(tofmat_test::db_dir(), 600.0, 1200.0));
}

// The real table after its .tmx round trip: the values both classifiers see.
std::shared_ptr<const ExemplarTable> real_tmx() {
  const auto bytes = encode_table(*real_table());
  return std::make_shared<const ExemplarTable>(decode_table(bytes.data(), bytes.size()));
}

TEST(CompactTable, RealDatabaseFitsIn24KiBAndHoldsTheFilesValues) {
  ASSERT_DB_PRESENT();
  const auto t = real_tmx();
  const CompactTable c(*t);
  std::cout << "[ measured ] compact table of the real database: " << c.memory_bytes() << " bytes\n";
  EXPECT_LE(c.memory_bytes(), 24u * 1024u);
  EXPECT_EQ(c.step_mm(), t->quant_step_mm());
  EXPECT_EQ(c.padded_bins() % kCompactBlock, 0u);
  std::size_t with_gaps = 0;
  for (std::size_t k = 0; k < c.n_candidates(); ++k) {
    const float* src = t->material_values(k);
    const std::uint8_t* m = c.validity(k);
    with_gaps += m != nullptr;
    EXPECT_EQ(m == nullptr, t->valid_count(k) == t->elements_per_material()) << t->materials()[k];
    for (std::uint32_t r = 0; r < c.n_rows(); ++r) {
      for (std::uint32_t b = 0; b < c.n_bins(); ++b) {
        const float v = src[r * c.n_bins() + b];
        const std::size_t i = r * c.padded_bins() + b;
        if (m) {
          ASSERT_EQ(((m[i / 8] >> (i % 8)) & 1) != 0, !std::isnan(v)) << k << " " << i;
        }
        if (!std::isnan(v)) {
          ASSERT_EQ(c.values(k)[i] * c.step_mm(), static_cast<double>(v)) << k << " " << i;
        }
      }
    }
  }
  EXPECT_EQ(with_gaps, 3u);  // paper, plaster, fakeapple miss bins (the database's README)
}

TEST(CompactTable, CandidateSubsetIsAppliedWhenBuilt) {
  ASSERT_DB_PRESENT();
  const auto t = real_tmx();
  const CompactTable all(*t), two(*t, {5, 2, 5});
  EXPECT_EQ(two.candidates(), (std::vector<std::uint32_t>{2, 5}));
  EXPECT_LT(two.memory_bytes() * 10, all.memory_bytes());
  EXPECT_TRUE(std::equal(two.values(1), two.values(1) + two.padded_elements(), all.values(5)));
  EXPECT_THROW(CompactTable(*t, {29}), std::invalid_argument);
}

// The hand-held sweep queries of `make bench`: windows of consecutive bins of
// both rows with N(0, 0.3 mm) noise. The fixed path must give the float
// path's label except where the float ranking is closer than the query's
// quantisation can move it: each element moves by at most half a step, so a
// distance moves by at most step * mean|q - e| + step^2 / 4.
TEST(FixedClassifierRealDatabase, SameLabelsAsFloatExceptWithinTheQuantisationBound) {
  ASSERT_DB_PRESENT();
  const auto t = real_tmx();
  const FloatClassifier fl(t);
  const FixedClassifier fx(t);
  const double step = t->quant_step_mm();
  std::mt19937 rng(1);
  std::normal_distribution<double> noise(0.0, 0.3);
  std::size_t queries = 0, disagree = 0;
  double worst_distance_gap = 0.0;
  for (std::uint32_t window : {1u, 3u, 10u, 30u, 100u}) {
    std::uniform_int_distribution<std::uint32_t> start(0, t->n_bins() - window);
    for (std::uint32_t m = 0; m < t->n_materials(); ++m) {
      for (int k = 0; k < 40; ++k) {
        std::vector<float> q(t->elements_per_material(), kNaN);
        const std::uint32_t s = start(rng);
        for (std::uint32_t r = 0; r < t->n_rows(); ++r) {
          for (std::uint32_t b = s; b < s + window; ++b) {
            const float v = t->material_values(m)[r * t->n_bins() + b];
            if (!std::isnan(v)) q[r * t->n_bins() + b] = static_cast<float>(v + noise(rng));
          }
        }
        if (std::all_of(q.begin(), q.end(), [](float v) { return std::isnan(v); })) continue;
        ++queries;
        const auto a = fl.classify(q.data(), q.size());
        const auto b = fx.classify(q.data(), q.size());
        ASSERT_EQ(a.ranking.size(), b.ranking.size());
        // Each candidate's distance within the bound (found by index).
        for (const auto& mb : b.ranking) {
          const auto ma =
              std::find_if(a.ranking.begin(), a.ranking.end(), [&](const Match& x) { return x.index == mb.index; });
          ASSERT_NE(ma, a.ranking.end());
          ASSERT_EQ(ma->valid, mb.valid);
          const double bound = step * std::sqrt(ma->distance) + step * step / 4.0;  // mean|d| <= rms
          ASSERT_LE(std::fabs(ma->distance - mb.distance), bound + 1e-9) << "material " << mb.index;
          worst_distance_gap = std::max(worst_distance_gap, std::fabs(ma->distance - mb.distance));
        }
        if (a.best().index != b.best().index) {
          ++disagree;
          const double margin = a.ranking[1].distance - a.ranking[0].distance;
          const double bound = 2.0 * (step * std::sqrt(a.ranking[1].distance) + step * step / 4.0);
          EXPECT_LE(margin, bound) << "window " << window << " material " << m;
        }
      }
    }
  }
  std::cout << "[ measured ] fixed vs float on " << queries << " real-database queries: " << disagree
            << " different labels; largest distance difference " << worst_distance_gap << " mm^2\n";
  EXPECT_GE(queries, 5u * 29u * 40u - 10u);  // (a 1-bin window on a missing bin has nothing to classify)
  EXPECT_LE(disagree * 1000, queries);       // at most 0.1 %
}

TEST(FixedClassifier, ErrorsAsTheFloatPath) {
  ASSERT_DB_PRESENT();
  const auto t = real_tmx();
  const FixedClassifier fx(t);
  std::vector<float> q(t->elements_per_material(), kNaN);
  EXPECT_THROW(fx.classify(q.data(), q.size() - 1), std::invalid_argument);
  EXPECT_THROW(fx.classify(q.data(), q.size()), std::invalid_argument);  // nothing valid
  q[0] = std::numeric_limits<float>::infinity();
  EXPECT_THROW(fx.classify(q.data(), q.size()), std::invalid_argument);
  // Valid only where the one candidate misses its bins: no candidate to judge.
  const auto paper = static_cast<std::uint32_t>(t->index_of("paper"));
  const FixedClassifier only_paper(t, {paper});
  std::vector<float> gap(t->elements_per_material(), kNaN);
  for (std::size_t i = 0; i < gap.size(); ++i) {
    if (std::isnan(t->material_values(paper)[i])) gap[i] = 1.0f;
  }
  ASSERT_TRUE(std::any_of(gap.begin(), gap.end(), [](float v) { return !std::isnan(v); }));
  EXPECT_THROW(only_paper.classify(gap.data(), gap.size()), std::invalid_argument);
}

TEST(FixedClassifier, TiesGoToTheLowerIndexAndOutOfRangeValuesSaturate) {
  // Two identical materials and a third: a query on them ties exactly.
  std::vector<float> v{1.0f, 2.0f, 1.0f, 2.0f, 5.0f, kNaN};
  const auto t = std::make_shared<const ExemplarTable>(std::vector<std::string>{"a", "b", "c"},
                                                       std::vector<RowSpec>{{16, 120}}, BinSpec{600.0, 3.0, 2}, v);
  const FixedClassifier fx(t);
  const float q[2] = {1.0f, 2.5f};
  const auto c = fx.classify(q, 2);
  ASSERT_EQ(c.ranking.size(), 3u);
  EXPECT_EQ(c.ranking[0].index, 0u);
  EXPECT_EQ(c.ranking[1].index, 1u);
  EXPECT_EQ(c.ranking[0].distance, c.ranking[1].distance);
  EXPECT_DOUBLE_EQ(c.ranking[0].distance, 0.125);  // (0 + 0.5^2) / 2
  EXPECT_EQ(c.ranking[2].valid, 1u);
  // A value far beyond 32767 steps saturates instead of wrapping: still ranked.
  const float far[2] = {1e9f, kNaN};
  const auto f = fx.classify(far, 2);
  EXPECT_EQ(f.best().index, 2u);  // c (5 mm) is the nearest to a huge value
  EXPECT_GT(f.best().distance, 0.0);
}

}  // namespace

namespace {

// The batch kernel (every candidate at once, one row range) equals the
// single-candidate kernel called per candidate and row, and the scalar and
// best kernels rank alike (NEON on aarch64).
TEST(FixedKernel, BatchOverCandidatesEqualsSingleCalls) {
  ASSERT_DB_PRESENT();
  const auto t = real_tmx();
  const FixedClassifier best(t, {}, FixedKernel::kBest), scalar(t, {}, FixedKernel::kScalar);
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 0.3);
  for (std::uint32_t window : {1u, 2u, 9u, 17u, 200u}) {
    for (int k = 0; k < 20; ++k) {
      std::vector<float> q(t->elements_per_material(), kNaN);
      const std::uint32_t m = static_cast<std::uint32_t>(rng() % t->n_materials());
      const std::uint32_t s = static_cast<std::uint32_t>(rng() % (t->n_bins() - window + 1));
      for (std::uint32_t r = 0; r < t->n_rows(); ++r) {
        for (std::uint32_t b = s; b < s + window; ++b) {
          const float v = t->material_values(m)[r * t->n_bins() + b];
          if (!std::isnan(v)) q[r * t->n_bins() + b] = static_cast<float>(v + noise(rng));
        }
      }
      if (std::all_of(q.begin(), q.end(), [](float v) { return std::isnan(v); })) continue;
      const auto p = scalar.prepare(q.data(), q.size());
      const auto sums = scalar.squared_sums(p);
      const auto sums_best = best.squared_sums(p);
      const CompactTable& c = scalar.compact();
      const std::size_t row_blocks = c.padded_bins() / kCompactBlock;
      for (std::size_t cand = 0; cand < c.n_candidates(); ++cand) {
        SquaredSum want;
        for (std::uint32_t r = 0; r < c.n_rows(); ++r) {
          if (p.first[r] >= p.last[r]) continue;
          const std::size_t b0 = r * row_blocks + p.first[r];
          const std::uint8_t* em = c.validity(cand);
          const auto one = squared_sum_scalar(p.q.data() + b0 * 8, p.mask.data() + b0, c.values(cand) + b0 * 8,
                                              em ? em + b0 : nullptr, p.last[r] - p.first[r]);
          want.sum += one.sum;
          want.count += one.count;
        }
        ASSERT_EQ(sums[cand], want) << "window " << window << " candidate " << cand;
        ASSERT_EQ(sums_best[cand], want) << "window " << window << " candidate " << cand;
      }
      const auto a = scalar.classify(q.data(), q.size()), b = best.classify(q.data(), q.size());
      ASSERT_EQ(a.ranking.size(), b.ranking.size());
      for (std::size_t i = 0; i < a.ranking.size(); ++i) {
        ASSERT_EQ(a.ranking[i].index, b.ranking[i].index);
        ASSERT_EQ(a.ranking[i].distance, b.ranking[i].distance);
      }
    }
  }
}

}  // namespace

namespace {

// Random tables of 1 to 64 candidates (values over the whole int16 range,
// some candidates with missing elements), random partial queries.
std::shared_ptr<const ExemplarTable> random_table(std::size_t K, std::uint32_t bins, std::mt19937& rng) {
  std::uniform_real_distribution<float> value(-2000.0f, 2000.0f);
  std::vector<std::string> names;
  std::vector<float> v;
  for (std::size_t k = 0; k < K; ++k) {
    names.push_back("m" + std::to_string(k));
    const bool gaps = rng() % 3 == 0;
    for (std::uint32_t e = 0; e < 2 * bins; ++e) v.push_back(gaps && rng() % 5 == 0 ? kNaN : value(rng));
  }
  return std::make_shared<const ExemplarTable>(names, kinect2_database_rows(), BinSpec{600.0, 3.0, bins}, v, 0.0625);
}

// The element-major copy holds the compact table's values and validity
// (checked on every build; its NEON kernel runs on aarch64).
TEST(ElementMajorTable, HoldsTheCompactTablesValuesAndValidity) {
  std::mt19937 rng(21);
  for (std::size_t K : {1u, 9u, 33u}) {
    const auto t = random_table(K, 37, rng);
    const CompactTable c(*t);
    const ElementMajorTable em(c);
    ASSERT_EQ(em.slots % 8, 0u);
    ASSERT_GE(em.slots, K);
    for (std::size_t e = 0; e < c.padded_elements(); ++e) {
      for (std::size_t k = 0; k < K; ++k) {
        ASSERT_EQ(em.values[e * em.slots + k], c.values(k)[e]);
        const std::uint8_t* m = c.validity(k);
        const bool valid = m == nullptr || ((m[e / 8] >> (e % 8)) & 1) != 0;
        if (em.gap_row[e] < 0) {
          ASSERT_TRUE(valid) << "element " << e << " has no validity lanes but candidate " << k << " misses it";
        } else {
          ASSERT_EQ(em.gap_lanes[static_cast<std::size_t>(em.gap_row[e]) * em.slots + k], valid ? 0xFFFF : 0);
        }
      }
    }
    for (std::size_t k : em.gapped) ASSERT_NE(c.validity(k), nullptr);
  }
}

// Both classifiers' sums (on aarch64 the best one is the element-major NEON
// kernel) equal the single-candidate scalar definition called per candidate
// and row, with gaps, candidate subsets, and queries from one element to
// every element.
TEST(FixedKernel, BestSquaredSumsEqualScalarOnRandomTables) {
  std::mt19937 rng(22);
  std::uniform_real_distribution<float> value(-2100.0f, 2100.0f);  // beyond the int16 range: saturation too
  for (std::size_t K : {1u, 5u, 8u, 9u, 29u, 33u, 64u}) {
    const std::uint32_t bins = 37;
    const auto t = random_table(K, bins, rng);
    std::vector<std::uint32_t> subset;
    for (std::uint32_t k = 0; k < K; k += 2) subset.push_back(k);
    for (const auto& cands : {std::vector<std::uint32_t>{}, subset}) {
      const FixedClassifier best(t, cands, FixedKernel::kBest), scalar(t, cands, FixedKernel::kScalar);
      for (int trial = 0; trial < 60; ++trial) {
        std::vector<float> q(t->elements_per_material(), kNaN);
        const std::uint32_t len = 1 + static_cast<std::uint32_t>(rng() % (trial % 3 == 0 ? bins : 4));
        const std::uint32_t s = static_cast<std::uint32_t>(rng() % (bins - len + 1));
        for (std::uint32_t r = 0; r < 2; ++r) {
          if (trial % 5 == 1 && r == 1) continue;  // one row only
          for (std::uint32_t b = s; b < s + len; ++b) {
            if (rng() % 7 != 0) q[r * bins + b] = value(rng);
          }
        }
        if (std::all_of(q.begin(), q.end(), [](float v) { return std::isnan(v); })) q[s] = 1.0f;
        const auto p = scalar.prepare(q.data(), q.size());
        const auto a = scalar.squared_sums(p), b = best.squared_sums(p);
        const CompactTable& c = scalar.compact();
        const std::size_t row_blocks = c.padded_bins() / kCompactBlock;
        ASSERT_EQ(a.size(), c.n_candidates());
        ASSERT_EQ(b.size(), c.n_candidates());
        for (std::size_t k = 0; k < a.size(); ++k) {
          SquaredSum want;
          for (std::uint32_t r = 0; r < c.n_rows(); ++r) {
            if (p.first[r] >= p.last[r]) continue;
            const std::size_t b0 = r * row_blocks + p.first[r];
            const std::uint8_t* em = c.validity(k);
            const SquaredSum one = squared_sum_scalar(p.q.data() + b0 * 8, p.mask.data() + b0, c.values(k) + b0 * 8,
                                                      em ? em + b0 : nullptr, p.last[r] - p.first[r]);
            want.sum += one.sum;
            want.count += one.count;
          }
          ASSERT_EQ(a[k], want) << "K " << K << " candidate " << k;
          ASSERT_EQ(b[k], want) << "K " << K << " candidate " << k;
        }
      }
    }
  }
}

}  // namespace
