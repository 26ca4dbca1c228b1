// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The session matcher's reweighting pass (firmware/core/src/fixed_session_kernel.hpp,
// internal): the scalar kernel against its definition written out here in
// 128-bit integers, and on aarch64 the NEON kernel against
// the scalar one bit for bit, over every number of terms, element counts
// with and without an odd tail, and the extremes of every input's range;
// then whole classifications with either kernel.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "fixed_session_kernel.hpp"
#include "test_util.hpp"
#include "tofmat/core/fixed_session_classifier.hpp"

namespace {

using namespace tofmat;
using namespace tofmat::session_detail;

// 128-bit integers (a GCC and Clang extension) hold the definition's sums without bounds.
__extension__ typedef __int128 i128;
__extension__ typedef unsigned __int128 u128;

// Elements with their storage.
struct Case {
  std::vector<std::int32_t> e;
  std::vector<std::int32_t> a[kSessionMaxTerms];  // Q14
  std::vector<std::int32_t> f[kSessionMaxTerms];  // Q31
  bool constant = false;
  std::int32_t B[kSessionMaxTerms] = {};
  std::int32_t threshold = 0;
  std::size_t n = 0;  // the arrays hold session_padded(n): the padding is junk the kernels must ignore
  SessionElements view() const {
    SessionElements x;
    x.e = e.data();
    for (int t = 0; t < kSessionMaxTerms; ++t) {
      x.a[t] = a[t].data();
      x.f[t] = f[t].data();
    }
    x.constant = constant;
    x.n = n;
    return x;
  }
};

// The pass as fixed_session_kernel.hpp defines it, element by element, in
// 128-bit integers (the fit's products rounded half up, as (2 B f + 2^31) >> 32 does).
SessionPassSums definition(const Case& c, int k, bool next) {
  SessionPassSums s;
  const float tw = static_cast<float>(c.threshold) * 32768.0f;
  u128 squares = 0;
  for (std::size_t i = 0; i < c.n; ++i) {
    i128 fit = 0;
    for (int t = 0; t < k; ++t) {
      if (c.constant && t == 0) {
        fit += c.B[0];
      } else {
        const i128 p = static_cast<i128>(c.B[t]) * c.f[t][i];  // round(p / 2^31), ties up
        fit += (p + (i128{1} << 30)) >> 31;
      }
    }
    i128 r = static_cast<i128>(c.e[i]) * 256 - fit;
    if (r < 0) r = -r;
    const auto mag = static_cast<std::int64_t>(r);
    if (mag > c.threshold) {
      s.beyond += mag;
      ++s.n_beyond;
      if (next) {
        const float q = tw / static_cast<float>(mag);
        const auto w = static_cast<std::int64_t>(std::nearbyint(q));
        const std::int64_t d = 32768 - w;
        for (int u = 0; u < k; ++u) {
          s.shortfall.h[u] += d * c.e[i] * c.a[u][i];
          for (int t = 0; t <= u; ++t) s.shortfall.G[u][t] += d * c.a[u][i] * c.a[t][i];
        }
      }
    } else {
      squares += static_cast<u128>(mag) * static_cast<u128>(mag);
    }
  }
  s.squares = squares > std::numeric_limits<std::uint64_t>::max() ? std::numeric_limits<std::uint64_t>::max()
                                                                  : static_cast<std::uint64_t>(squares);
  return s;
}

void expect_same(const SessionPassSums& a, const SessionPassSums& b, const std::string& what) {
  EXPECT_EQ(a.squares, b.squares) << what;
  EXPECT_EQ(a.beyond, b.beyond) << what;
  EXPECT_EQ(a.n_beyond, b.n_beyond) << what;
  EXPECT_TRUE(a.shortfall == b.shortfall) << what;
}

// n elements: random values, every fourth case at the ends of their ranges.
Case make_case(std::size_t n, std::mt19937_64& rng, int flavour) {
  constexpr std::int32_t kF = 2147483647;  // the Q31 basis's bound
  std::uniform_int_distribution<std::int32_t> e_any(-65534, 65534), small(-400, 400), a_any(-16384, 16384),
      f_any(-kF, kF), b_any(-kMaxCoefficient, kMaxCoefficient), b_small(-(1 << 16), 1 << 16), t_any(0, kNoThreshold);
  Case c;
  c.constant = rng() % 2 == 0;
  for (std::size_t i = 0; i < n; ++i) {
    c.e.push_back(flavour == 3 ? (i % 2 ? 65534 : -65534) : flavour == 0 ? small(rng) : e_any(rng));
    for (int t = 0; t < kSessionMaxTerms; ++t) {
      c.a[t].push_back(flavour == 3 ? (i % 3 ? 16384 : -16384) : a_any(rng));
      c.f[t].push_back(flavour == 3 ? (i % 3 ? kF : -kF) : f_any(rng));
    }
  }
  c.n = n;
  for (std::size_t i = n; i < session_padded(n); ++i) {  // junk: extreme values, which would count if read
    c.e.push_back(-65534);
    for (int t = 0; t < kSessionMaxTerms; ++t) {
      c.a[t].push_back(16384);
      c.f[t].push_back(kF);
    }
  }
  for (int t = 0; t < kSessionMaxTerms; ++t) {
    c.B[t] = flavour == 3 ? (t % 2 ? kMaxCoefficient : -kMaxCoefficient) : flavour == 0 ? b_small(rng) : b_any(rng);
  }
  // Thresholds: none, zero, a typical one (3 sd of 64 steps in Q8), and any.
  const std::int32_t thresholds[4] = {kNoThreshold, 0, 3 * 64 * 256, t_any(rng)};
  c.threshold = thresholds[static_cast<std::size_t>(rng() % 4)];
  return c;
}

TEST(FixedSessionKernel, TheScalarPassIsItsDefinition) {
  std::mt19937_64 rng(5);
  int checked = 0;
  for (const std::size_t n : {0u, 1u, 2u, 3u, 7u, 64u, 65u, 1001u}) {
    for (int flavour = 0; flavour < 4; ++flavour) {
      for (int rep = 0; rep < 6; ++rep) {
        const Case c = make_case(n, rng, flavour);
        for (int k = 0; k <= kSessionMaxTerms; ++k) {
          for (const bool next : {false, true}) {
            const bool use_next = next && k > 0;
            expect_same(session_pass_scalar(c.view(), k, c.B, c.threshold, use_next), definition(c, k, use_next),
                        "n " + std::to_string(n) + " flavour " + std::to_string(flavour) + " k " + std::to_string(k));
            ++checked;
          }
        }
      }
    }
  }
  EXPECT_EQ(checked, 8 * 4 * 6 * 4 * 2);
}

TEST(FixedSessionKernel, TheScalarMomentsAreTheirDefinition) {
  std::mt19937_64 rng(9);
  for (const std::size_t n : {0u, 1u, 5u, 1001u}) {
    for (int flavour = 0; flavour < 4; ++flavour) {
      const Case c = make_case(n, rng, flavour);
      std::int64_t h[kSessionMaxTerms] = {-1, -1, -1};
      session_moments_scalar(c.view(), kSessionMaxTerms, h);
      for (int t = 0; t < kSessionMaxTerms; ++t) {
        i128 sum = 0;
        for (std::size_t i = 0; i < n; ++i) sum += static_cast<i128>(c.e[i]) * c.a[t][i];
        EXPECT_EQ(h[t], static_cast<std::int64_t>(sum)) << "n " << n << " term " << t;
      }
    }
  }
}

TEST(FixedSessionKernel, SaturatedSquaresStayAtTheMaximum) {
  // Residuals of 2^24 + 3 x 2^28 (the largest): squares near 2^59.6 each, 2^64 passed within 20 elements.
  Case c;
  c.n = 64;
  c.e.assign(64, 65534);
  for (auto& a : c.a) a.assign(64, 16384);
  for (auto& f : c.f) f.assign(64, -2147483647);
  c.constant = true;
  c.B[0] = -kMaxCoefficient;
  c.B[1] = c.B[2] = kMaxCoefficient;
  c.threshold = kNoThreshold;
  const SessionPassSums s = session_pass_scalar(c.view(), 3, c.B, c.threshold, false);
  EXPECT_EQ(s.squares, std::numeric_limits<std::uint64_t>::max());
  EXPECT_EQ(s.n_beyond, 0);
  expect_same(s, definition(c, 3, false), "saturated");
}

#if defined(__aarch64__)
TEST(FixedSessionKernel, NeonIsTheScalarPassToTheBit) {
  std::mt19937_64 rng(7);
  for (const std::size_t n : {0u, 1u, 2u, 3u, 4u, 5u, 63u, 64u, 65u, 4097u}) {
    for (int flavour = 0; flavour < 4; ++flavour) {
      for (int rep = 0; rep < 8; ++rep) {
        const Case c = make_case(n, rng, flavour);
        for (int k = 0; k <= kSessionMaxTerms; ++k) {
          for (const bool next : {false, true}) {
            const bool use_next = next && k > 0;
            expect_same(session_pass_neon(c.view(), k, c.B, c.threshold, use_next),
                        session_pass_scalar(c.view(), k, c.B, c.threshold, use_next),
                        "n " + std::to_string(n) + " flavour " + std::to_string(flavour) + " k " + std::to_string(k));
          }
        }
      }
    }
  }
}

TEST(FixedSessionKernel, NeonMomentsAreTheScalarOnes) {
  std::mt19937_64 rng(13);
  for (const std::size_t n : {0u, 1u, 3u, 4u, 5u, 7u, 8u, 4097u}) {
    for (int flavour = 0; flavour < 4; ++flavour) {
      const Case c = make_case(n, rng, flavour);
      for (int k = 0; k <= kSessionMaxTerms; ++k) {
        std::int64_t a[kSessionMaxTerms] = {}, b[kSessionMaxTerms] = {};
        session_moments_neon(c.view(), k, a);
        session_moments_scalar(c.view(), k, b);
        for (int t = 0; t < kSessionMaxTerms; ++t) EXPECT_EQ(a[t], b[t]) << "n " << n << " k " << k;
      }
    }
  }
}

TEST(FixedSessionKernel, ClassificationsAreTheSameWithEitherKernel) {
  ASSERT_DB_PRESENT();
  const auto table =
      std::make_shared<const ExemplarTable>(ExemplarTable::from_npy_dir(tofmat_test::db_dir(), 600.0, 1200.0));
  SessionPrior hard = SessionPrior::tuned(*table);
  hard.huber_k = 1.0;
  hard.iterations = 8;
  for (const SessionPrior& prior : {SessionPrior::tuned(*table), hard}) {
    const FixedSessionClassifier neon(table, prior, {}, {}, FixedKernel::kBest);
    const FixedSessionClassifier scalar(table, prior, {}, {}, FixedKernel::kScalar);
    std::mt19937 rng(3);
    std::normal_distribution<double> unit(0.0, 1.0);
    for (const std::uint32_t length : {1u, 2u, 3u, 10u, 31u, 100u, 200u}) {
      for (std::size_t m = 0; m < table->n_materials(); m += 3) {
        std::vector<float> q(table->elements_per_material(), std::nanf(""));
        const std::uint32_t start = static_cast<std::uint32_t>(rng() % (table->n_bins() - length + 1));
        for (std::uint32_t r = 0; r < table->n_rows(); ++r)
          for (std::uint32_t b = start; b < start + length; ++b) {
            const float v = table->material_values(m)[r * table->n_bins() + b];
            if (!std::isnan(v)) q[r * table->n_bins() + b] = static_cast<float>(v + 2.0 * unit(rng) + 0.5 * unit(rng));
          }
        if (std::all_of(q.begin(), q.end(), [](float v) { return std::isnan(v); })) continue;
        const Classification a = neon.classify(q.data(), q.size()), b = scalar.classify(q.data(), q.size());
        ASSERT_EQ(a.ranking.size(), b.ranking.size());
        for (std::size_t i = 0; i < a.ranking.size(); ++i) {
          EXPECT_EQ(a.ranking[i].index, b.ranking[i].index);
          EXPECT_EQ(a.ranking[i].distance, b.ranking[i].distance);  // to the bit
          EXPECT_EQ(a.ranking[i].valid, b.ranking[i].valid);
        }
      }
    }
  }
}
#endif

}  // namespace
