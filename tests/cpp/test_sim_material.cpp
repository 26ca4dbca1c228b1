// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Material responses in closed form (docs/simulator-model.md section 1;
// firmware/sim material.hpp): the kernels against long double evaluations of
// the textbook formulas, their limits, the Fresnel share, the slab transit
// time, and Material::validate.
#include <gtest/gtest.h>

#include <cmath>
#include <complex>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "tofmat/sim/material.hpp"

namespace {

using tofmat::sim::exponential_kernel;
using tofmat::sim::gamma_kernel;
using tofmat::sim::Material;
using tofmat::sim::material_response;
using tofmat::sim::ResponseKind;
using tofmat::sim::slab_kernel;
using cd = std::complex<double>;
using cld = std::complex<long double>;

constexpr double kPi = 3.14159265358979323846;
constexpr double kTwoPi = 2.0 * kPi;
constexpr double kCTrueMmPerS = 299.792458e9;

bool finite(cd z) { return std::isfinite(z.real()) && std::isfinite(z.imag()); }

double rel_err(cd got, cld want) {
  const cld g(got.real(), got.imag());
  return static_cast<double>(std::abs(g - want) / std::abs(want));
}

// Textbook forms in long double (64-bit mantissa, ~1e-19).
cld exp_textbook(long double x) { return 1.0L / cld(1.0L, x); }
cld gamma_textbook(long double x, long double k) { return std::pow(cld(1.0L, x / k), -k); }
// 1 - exp(-z): for |z| < 0.05 its Taylor series (the long double textbook
// form would lose digits there), else directly.
cld one_minus_exp_neg(cld z) {
  if (std::abs(z) >= 0.05L) return 1.0L - std::exp(-z);
  cld term = z, sum = 0.0L;
  for (int n = 1; n < 30; ++n) {
    sum += term;
    term *= -z / static_cast<long double>(n + 1);
  }
  return sum;
}
// The slab, z = T (1/tau + i omega). The arguments T/tau and omega T are taken
// as the doubles the implementation forms (one rounding each): the phase
// omega T can be 1e4 rad, and its unavoidable input rounding (1e4 * 1.1e-16)
// is conditioning of the problem, not an error of the evaluation.
cld slab_textbook(double omega, double tau, double transit, double backing) {
  const cld z(static_cast<long double>(transit / tau), static_cast<long double>(omega * transit));
  const cld e = std::exp(-z);
  return one_minus_exp_neg(z) / cld(1.0L, static_cast<long double>(omega * tau)) +
         static_cast<long double>(backing) * e;
}

std::vector<double> log_grid(double lo_exp, double hi_exp, double per_decade) {
  std::vector<double> out;
  for (int k = 0; lo_exp + static_cast<double>(k) / per_decade <= hi_exp + 1e-9; ++k)
    out.push_back(std::pow(10.0, lo_exp + static_cast<double>(k) / per_decade));
  return out;
}

// ---------------------------------------------------------------------------
// Kernels against long double
// ---------------------------------------------------------------------------

// omega tau from 1e-8 to 1e6 (the documented range), tau 1 ps .. 100 ns.
// Bound 1e-14: 1/(1 + i x) is a handful of roundings, each <= 1.1e-16 relative.
TEST(Kernels, ExponentialMatchesLongDouble) {
  double worst = 0.0;
  for (double tau : {1e-12, 1e-10, 1e-7}) {
    for (double x : log_grid(-8, 6, 8)) {
      const double omega = x / tau;
      const cd k = exponential_kernel(omega, tau);
      ASSERT_TRUE(finite(k)) << x;
      const double e = rel_err(k, exp_textbook(static_cast<long double>(omega) * tau));
      worst = std::max(worst, e);
      EXPECT_LE(e, 1e-14) << "omega tau " << x << " tau " << tau;
    }
  }
  RecordProperty("worst_rel_err", std::to_string(worst));
}

// Bound 1e-12, with the conditioning stated: exp(-k (0.5 log1p(y^2) + i atan y))
// errs by ~eps (k |log|1+iy|| + k atan|y|): at k = 20, omega tau = 1e6 that is
// ~20 * 12 * 1.1e-16 = 3e-14; at k = 1000 (the largest valid) ~1.6e-13.
// Values below 1e-290 (the true value underflows double) only have to be
// finite, non-negative in magnitude and tiny.
TEST(Kernels, GammaMatchesLongDouble) {
  double worst = 0.0;
  for (double k : {0.5, 1.0, 3.0, 20.0, 1000.0}) {
    for (double tau : {1e-12, 1e-9}) {
      for (double x : log_grid(-8, 6, 8)) {
        const double omega = x / tau;
        const cd got = gamma_kernel(omega, tau, k);
        ASSERT_TRUE(finite(got)) << x << " k " << k;
        const cld want = gamma_textbook(static_cast<long double>(omega) * tau, k);
        if (std::abs(want) < 1e-290L) {
          EXPECT_LE(std::abs(got), 1e-280) << x << " k " << k;
          continue;
        }
        const double e = rel_err(got, want);
        worst = std::max(worst, e);
        EXPECT_LE(e, 1e-12) << "omega tau " << x << " k " << k;
      }
    }
  }
  RecordProperty("worst_rel_err", std::to_string(worst));
}

// T/tau from 1e-12 (the expm1 path) to 800 (backing term below 1e-347: 0);
// bound 1e-13 (a few roundings of O(1) terms; expm1 keeps 1 - exp(-z) exact
// to ~eps relative even when |z| ~ 1e-12).
TEST(Kernels, SlabMatchesLongDouble) {
  double worst = 0.0;
  for (double tau : {1e-12, 1e-9}) {
    for (double x : log_grid(-6, 5, 4)) {
      const double omega = x / tau;
      for (double t_over_tau : {1e-12, 1e-9, 1e-4, 0.03, 0.3, 1.0, 3.0, 30.0, 800.0}) {
        for (double beta : {0.0, 0.5, 1.0, 3.0}) {
          const double transit = t_over_tau * tau;
          const cd got = slab_kernel(omega, tau, transit, beta);
          ASSERT_TRUE(finite(got)) << x << " " << t_over_tau << " " << beta;
          const cld want = slab_textbook(omega, tau, transit, beta);
          const double e = rel_err(got, want);
          worst = std::max(worst, e);
          EXPECT_LE(e, 1e-13) << "omega tau " << x << " T/tau " << t_over_tau << " beta " << beta;
        }
      }
    }
  }
  RecordProperty("worst_rel_err", std::to_string(worst));
}

// ---------------------------------------------------------------------------
// Limits
// ---------------------------------------------------------------------------

TEST(Kernels, ExponentialAndGammaAreOneAtZeroFrequency) {
  for (double tau : {1e-15, 1e-12, 1e-7, 1e-3}) {
    EXPECT_EQ(exponential_kernel(0.0, tau), cd(1.0, 0.0)) << tau;
    for (double k : {1e-3, 0.5, 1.0, 3.0, 20.0, 1000.0})
      EXPECT_EQ(gamma_kernel(0.0, tau, k), cd(1.0, 0.0)) << tau << " " << k;
  }
}

TEST(Kernels, SlabIsOneAtZeroFrequencyWithFullBacking) {
  // beta = 1: the backing returns all that the sheet has not, total 1.
  for (double t_over_tau : {1e-12, 1e-3, 1.0, 50.0}) {
    EXPECT_NEAR(std::abs(slab_kernel(0.0, 1e-10, t_over_tau * 1e-10, 1.0) - 1.0), 0.0, 4e-16) << t_over_tau;
  }
}

// At nu = 0 the slab returns what the sheet scatters back within its transit
// time plus what the backing returns of the rest: K(0) = 1 - (1 - beta) exp(-T/tau)
// (docs/simulator-model.md): light through the back that the backing does not
// return is lost, so the subsurface share of a thin sheet is smaller.
TEST(Kernels, SlabAtZeroFrequencyKeepsWhatTheSheetAndBackingReturn) {
  for (double beta : {0.0, 0.3, 2.0}) {
    for (double t_over_tau : {0.1, 1.0}) {
      const cd k0 = slab_kernel(0.0, 1e-10, t_over_tau * 1e-10, beta);
      EXPECT_NEAR(k0.real(), 1.0 - (1.0 - beta) * std::exp(-t_over_tau), 1e-15) << beta << ", T/tau " << t_over_tau;
      EXPECT_EQ(k0.imag(), 0.0);
    }
  }
}

TEST(Kernels, ExponentialTendsToMinusIOverOmegaTau) {
  // 1/(1 + i x) = -i/x (1 - i/x)^-1: relative distance from -i/x is 1/sqrt(1 + x^2) <= 1/x;
  // x Im K = -1/(1 + 1/x^2) and x^2 Re K = 1/(1 + 1/x^2) differ from -1 and 1 by ~1/x^2.
  for (double x : {1e3, 1e5, 1e7, std::nextafter(1e8, 0.0), 1e8, 1e10, 1e15, 1e100, 1e200, 1e300}) {
    const cd k = exponential_kernel(x, 1.0);
    ASSERT_TRUE(finite(k)) << x;
    EXPECT_NEAR(k.imag() * x, -1.0, 1.0 / (x * x) + 1e-15) << x;
    EXPECT_GE(k.real(), 0.0);  // Re K = 1/(1+x^2) > 0, may underflow
    EXPECT_LE(std::abs(k - cd(0.0, -1.0 / x)), 1.01 * std::abs(k) / x + 1e-300) << x;
    if (x < 1e150) {
      EXPECT_NEAR(k.real() * x * x, 1.0, 1.0 / (x * x) + 1e-15) << x;
    }
  }
  // Through the material's own units: omega tau = 2 pi * 1e11 Hz * 1e-6 s (the largest tau).
  const cd big = exponential_kernel(kTwoPi * 1e11, 1e-6);
  EXPECT_NEAR(big.imag() * kTwoPi * 1e5, -1.0, 1.0 / (kTwoPi * kTwoPi * 1e10) + 1e-15);  // 1/x^2, x = 6.3e5
  // No jump where the implementation switches form (|x| = 1e8).
  const cd below = exponential_kernel(std::nextafter(1e8, 0.0), 1.0), at = exponential_kernel(1e8, 1.0);
  EXPECT_LE(std::abs(below - at) / std::abs(at), 1e-15);
  // Negative frequencies: K(-omega) = conj(K(omega)).
  for (double x : {0.3, 1e4, 1e9}) EXPECT_EQ(exponential_kernel(-x, 1.0), std::conj(exponential_kernel(x, 1.0))) << x;
}

TEST(Kernels, GammaLargeArgumentsStayFiniteAndContinuous) {
  for (double k : {0.5, 1.0, 3.0}) {
    const double y0 = 1e8;  // the switch from log1p to log(hypot)
    const cd below = gamma_kernel(std::nextafter(y0 * k, 0.0), 1.0, k), at = gamma_kernel(y0 * k, 1.0, k);
    EXPECT_LE(std::abs(below - at) / std::abs(at), 1e-14) << k;
    for (double y : {1e10, 1e100, 1e300}) {
      const cd g = gamma_kernel(y * k, 1.0, k);
      ASSERT_TRUE(finite(g)) << y << " " << k;
      // |K| = (1 + y^2)^(-k/2) ~ y^-k where representable.
      const double expect = std::pow(y, -k);
      if (expect > 1e-290) {
        EXPECT_NEAR(std::abs(g) / expect, 1.0, 1e-12) << y << " " << k;
      }
    }
  }
}

TEST(Kernels, GammaWithShapeOneIsTheExponential) {
  // Both a few roundings from the exact value: bound 1e-14 relative.
  for (double x : log_grid(-8, 8, 6)) {
    const cd g = gamma_kernel(x, 1.0, 1.0), e = exponential_kernel(x, 1.0);
    EXPECT_LE(std::abs(g - e) / std::abs(e), 1e-14) << x;
  }
}

TEST(Kernels, GammaWithLargeShapeTendsToAPureDelay) {
  // (1 + i x/k)^-k -> exp(-i x) as k grows: error ~ x^2 / (2 k).
  for (double x : {0.01, 0.1, 0.5}) {
    const cd g = gamma_kernel(x, 1.0, 1000.0);
    EXPECT_LE(std::abs(g - std::polar(1.0, -x)), x * x / 1000.0) << x;
  }
}

TEST(Kernels, SlabWithoutBackingAndLongTransitIsTheExponential) {
  // T/tau = 1e3: exp(-1000) underflows to 0, so the slab must equal the
  // exponential to rounding (|1 - e^-z| = 1 computed as cos y + 2 sin^2(y/2)).
  for (double x : log_grid(-6, 6, 4)) {
    for (double t_over_tau : {1e3, 1e6, 1e12}) {
      const double tau = 1e-10, omega = x / tau;
      const cd s = slab_kernel(omega, tau, t_over_tau * tau, 0.0), e = exponential_kernel(omega, tau);
      ASSERT_TRUE(finite(s)) << x << " " << t_over_tau;
      EXPECT_LE(std::abs(s - e) / std::abs(e), 1e-15) << "omega tau " << x << " T/tau " << t_over_tau;
    }
  }
  // Converges as T grows: at T/tau = 40 the difference is exp(-z) / (1 + i x), |.| = 3e-18.
  const cd s40 = slab_kernel(1e9, 1e-9, 40e-9, 0.0), e40 = exponential_kernel(1e9, 1e-9);
  EXPECT_LE(std::abs(s40 - e40), 1e-16);
}

TEST(Kernels, SlabWithTinyTransitIsTheBackingDelayedByT) {
  // z = eps (1 + i x) with eps = T/tau, x = omega tau: to first order
  // K = beta + eps (1 - beta (1 + i x)); the neglected terms are ~eps^2 |1 + i x|^2.
  // With beta = 0 K is ~1e-12 itself: computing 1 - exp(-z) without expm1
  // would leave only ~4 correct digits, so the 1e-15 relative bound checks it.
  const double tau = 1e-9, omega = 1e9, x = omega * tau, eps = 1e-12;
  for (double beta : {0.0, 0.5, 2.0}) {
    const cd k = slab_kernel(omega, tau, eps * tau, beta);
    const cd first_order = beta + eps * (1.0 - beta * cd(1.0, x));
    EXPECT_LE(std::abs(k - first_order), 1e-23 + 1e-15 * std::abs(k)) << beta;
  }
}

TEST(Kernels, NeverNaNOnExtremeFiniteInputs) {
  for (double omega : {0.0, 1e-300, 1.0, 1e9, 1e15, 1e300}) {
    for (double tau : {1e-300, 1e-15, 1e-12, 1e-6, 1.0}) {
      ASSERT_TRUE(finite(exponential_kernel(omega, tau))) << omega << " " << tau;
      for (double k : {1e-3, 1.0, 1000.0}) ASSERT_TRUE(finite(gamma_kernel(omega, tau, k))) << omega << " " << tau;
      for (double t : {1e-300, 1e-12, 1e-6}) {
        for (double beta : {0.0, 1.0, 10.0}) {
          ASSERT_TRUE(finite(slab_kernel(omega, tau, t, beta))) << omega << " " << tau << " " << t << " " << beta;
        }
      }
    }
  }
}

// ---------------------------------------------------------------------------
// material_response: Fresnel share, slab transit, opaque
// ---------------------------------------------------------------------------

Material make(ResponseKind kind) {
  Material m;
  m.name = "m";
  m.kind = kind;
  m.albedo = 0.8;
  m.subsurface = 1.0;
  m.tau_ps = 300.0;
  m.gamma_k = 2.5;
  m.refractive_index = 1.5;
  m.thickness_mm = 2.0;
  m.path_factor = 1.7;
  m.backing = 0.4;
  return m;
}

TEST(Response, SchlickReflectance) {
  EXPECT_DOUBLE_EQ(tofmat::sim::schlick_reflectance(1.5, 0.0), 0.04);
  EXPECT_NEAR(tofmat::sim::schlick_reflectance(1.5, kPi / 2), 1.0, 1e-15);  // cos(pi/2) = 6e-17 in double
  EXPECT_EQ(tofmat::sim::schlick_reflectance(1.0, 0.0), 0.0);
  const double a = 1.0, f0 = 0.04;
  EXPECT_NEAR(tofmat::sim::schlick_reflectance(1.5, a), f0 + (1 - f0) * std::pow(1 - std::cos(a), 5), 1e-15);
}

TEST(Response, FresnelShareOfTheSubsurfaceTerm) {
  // R = albedo ((1 - b_eff) + b_eff K), b_eff = min(1, b (1 - F(alpha)) / (1 - F0)).
  for (double n : {1.0, 1.33, 1.5, 2.4, 4.0}) {
    for (double b : {0.2, 0.7, 1.0}) {
      for (double deg : {0.0, 30.0, 45.0, 70.0, 85.0, 89.0}) {
        Material m = make(ResponseKind::kExponential);
        m.refractive_index = n;
        m.subsurface = b;
        const double alpha = deg * kPi / 180.0, nu = 120e6;
        const double f0 = ((n - 1) / (n + 1)) * ((n - 1) / (n + 1));
        const double fa = f0 + (1 - f0) * std::pow(1 - std::cos(alpha), 5);
        const double b_eff = std::min(1.0, b * (1 - fa) / (1 - f0));
        const cd k = exponential_kernel(kTwoPi * nu, 300e-12);
        const cd want = 0.8 * ((1 - b_eff) + b_eff * k);
        const cd got = material_response(m, nu, alpha);
        EXPECT_LE(std::abs(got - want), 1e-14) << "n " << n << " b " << b << " alpha " << deg;
      }
    }
  }
}

TEST(Response, SlabTransitTimeFollowsSnell) {
  // T = path_factor * 2 * thickness * n / (c cos theta_t), sin theta_t = sin(alpha) / n.
  for (double deg : {0.0, 20.0, 60.0, 85.0}) {
    const Material m = make(ResponseKind::kSlab);
    const double alpha = deg * kPi / 180.0, nu = 80e6, n = m.refractive_index;
    const double sin_t = std::sin(alpha) / n, cos_t = std::sqrt(1 - sin_t * sin_t);
    const double transit = m.path_factor * 2 * m.thickness_mm * n / (kCTrueMmPerS * cos_t);
    const double f0 = 0.04, fa = f0 + (1 - f0) * std::pow(1 - std::cos(alpha), 5);
    const double b_eff = std::min(1.0, (1 - fa) / (1 - f0));
    const cd k = slab_kernel(kTwoPi * nu, 300e-12, transit, m.backing);
    const cd want = m.albedo * ((1 - b_eff) + b_eff * k);
    EXPECT_LE(std::abs(material_response(m, nu, alpha) - want), 1e-14) << deg;
  }
}

TEST(Response, OpaqueAndZeroSubsurfaceAreRealAlbedo) {
  for (auto kind : {ResponseKind::kOpaque, ResponseKind::kExponential, ResponseKind::kGamma, ResponseKind::kSlab}) {
    Material m = make(kind);
    if (kind != ResponseKind::kOpaque) m.subsurface = 0.0;
    for (double nu : {0.0, 16e6, 840e6, 1e11}) {
      for (double a : {0.0, 0.5, 1.5}) EXPECT_EQ(material_response(m, nu, a), cd(0.8, 0.0)) << static_cast<int>(kind);
    }
  }
}

TEST(Response, AlbedoAtZeroFrequencyForEveryKind) {
  // With K(0) = 1 (spec section 1) R(0, alpha) = albedo at any incidence.
  for (auto kind : {ResponseKind::kOpaque, ResponseKind::kExponential, ResponseKind::kGamma}) {
    const Material m = make(kind);
    for (double a : {0.0, 0.7}) EXPECT_NEAR(std::abs(material_response(m, 0.0, a) - 0.8), 0.0, 1e-15);
  }
}

TEST(Response, FiniteAtGrazingIncidence) {
  // Incidence 90 degrees: F = 1, b_eff = 0, R = albedo. For the slab with
  // n = 1 (allowed by validate) cos(theta_t) = 0 makes the transit infinite;
  // the response must still be the (finite) albedo, never NaN.
  for (auto kind : {ResponseKind::kExponential, ResponseKind::kGamma, ResponseKind::kSlab}) {
    for (double n : {1.0, 1.5}) {
      Material m = make(kind);
      m.refractive_index = n;
      const cd r = material_response(m, 120e6, kPi / 2);
      EXPECT_TRUE(finite(r)) << "kind " << tofmat::sim::response_kind_name(kind) << " n " << n << ": " << r;
      EXPECT_NEAR(std::abs(r - 0.8), 0.0, 1e-12) << tofmat::sim::response_kind_name(kind) << " n " << n;
    }
  }
}

// ---------------------------------------------------------------------------
// validate
// ---------------------------------------------------------------------------

void expect_rejects(const Material& m, const std::string& field) {
  try {
    m.validate();
    ADD_FAILURE() << "accepted " << field;
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
  }
}

TEST(Validate, AcceptsTheRangeBoundaries) {
  for (auto kind : {ResponseKind::kOpaque, ResponseKind::kExponential, ResponseKind::kGamma, ResponseKind::kSlab}) {
    Material m = make(kind);
    EXPECT_NO_THROW(m.validate());
    m.albedo = 0.0;
    m.subsurface = 0.0;
    m.refractive_index = 1.0;
    EXPECT_NO_THROW(m.validate());
    m.albedo = 1.0;
    m.subsurface = 1.0;
    m.refractive_index = 4.0;
    m.tau_ps = 1e6;
    m.gamma_k = 1000.0;
    m.thickness_mm = 1000.0;
    m.path_factor = 1e4;
    m.backing = 10.0;
    EXPECT_NO_THROW(m.validate());
    m.path_factor = 1.0;
    m.backing = 0.0;
    EXPECT_NO_THROW(m.validate());
  }
}

TEST(Validate, RejectsEachOutOfRangeParameter) {
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  for (auto kind : {ResponseKind::kOpaque, ResponseKind::kExponential, ResponseKind::kGamma, ResponseKind::kSlab}) {
    for (double v : {-0.01, 1.01, nan, inf}) {
      Material m = make(kind);
      m.albedo = v == 1.01 ? 10.01 : v;  // albedo may exceed 1 (specular metals), up to 10
      expect_rejects(m, "albedo");
      m = make(kind);
      m.subsurface = v;
      expect_rejects(m, "subsurface");
    }
    for (double v : {0.99, 4.01, nan, -inf}) {
      Material m = make(kind);
      m.refractive_index = v;
      expect_rejects(m, "refractive_index");
    }
  }
  for (auto kind : {ResponseKind::kExponential, ResponseKind::kGamma, ResponseKind::kSlab}) {
    for (double v : {0.0, -1.0, 1.0000001e6, nan, inf}) {
      Material m = make(kind);
      m.tau_ps = v;
      expect_rejects(m, "tau_ps");
    }
  }
  for (double v : {0.0, -1.0, 1000.5, nan, inf}) {
    Material m = make(ResponseKind::kGamma);
    m.gamma_k = v;
    expect_rejects(m, "gamma_k");
  }
  for (double v : {0.0, -1.0, 1000.5, nan, inf}) {
    Material m = make(ResponseKind::kSlab);
    m.thickness_mm = v;
    expect_rejects(m, "thickness_mm");
  }
  for (double v : {0.999, 1.00001e4, nan, inf}) {
    Material m = make(ResponseKind::kSlab);
    m.path_factor = v;
    expect_rejects(m, "path_factor");
  }
  for (double v : {-0.001, 10.001, nan, inf}) {
    Material m = make(ResponseKind::kSlab);
    m.backing = v;
    expect_rejects(m, "backing");
  }
}

TEST(Validate, IgnoresParametersAKindDoesNotUse) {
  Material m = make(ResponseKind::kOpaque);
  m.tau_ps = -5.0;
  m.gamma_k = -1.0;
  m.thickness_mm = -1.0;
  m.path_factor = 0.0;
  m.backing = -3.0;
  EXPECT_NO_THROW(m.validate());
  m.kind = ResponseKind::kExponential;
  m.tau_ps = 10.0;
  EXPECT_NO_THROW(m.validate());  // gamma_k and slab fields unused
  m.kind = ResponseKind::kGamma;
  EXPECT_THROW(m.validate(), std::invalid_argument);
}

TEST(Validate, KindNames) {
  for (auto kind : {ResponseKind::kOpaque, ResponseKind::kExponential, ResponseKind::kGamma, ResponseKind::kSlab}) {
    EXPECT_EQ(tofmat::sim::response_kind_from_name(tofmat::sim::response_kind_name(kind)), kind);
  }
  EXPECT_THROW(tofmat::sim::response_kind_from_name("Opaque"), std::invalid_argument);
  EXPECT_THROW(tofmat::sim::response_kind_from_name(""), std::invalid_argument);
}

}  // namespace
