// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Material responses: the kernels of each response kind, Schlick reflectance, and the response at a frequency.
#include "tofmat/sim/material.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace tofmat::sim {
namespace {

constexpr double kTwoPi = 6.283185307179586476925286766559;
constexpr double kCTrueMmPerS = 299.792458e9;  // mm/s

// 1 / (1 + i x), written so that neither 1 + x^2 overflows nor precision is lost.
std::complex<double> one_over_one_plus_ix(double x) {
  const double ax = std::fabs(x);
  if (ax < 1e8) {
    const double d = 1.0 + x * x;
    return {1.0 / d, -x / d};
  }
  const double inv = 1.0 / x;  // 1/(1+ix) = -i/x * 1/(1 - i/x)
  const double d = 1.0 + inv * inv;
  return {inv * inv / d, -inv / d};
}

// exp(z) - 1 for complex z without cancellation near 0.
std::complex<double> expm1_complex(std::complex<double> z) {
  const double x = z.real(), y = z.imag();
  const double em1 = std::expm1(x);
  const double s = std::sin(0.5 * y);
  // e^x cos y - 1 = expm1(x) cos y - 2 sin^2(y/2)
  return {em1 * std::cos(y) - 2.0 * s * s, std::exp(x) * std::sin(y)};
}

}  // namespace

ResponseKind response_kind_from_name(const std::string& name) {
  if (name == "opaque") return ResponseKind::kOpaque;
  if (name == "exponential") return ResponseKind::kExponential;
  if (name == "gamma") return ResponseKind::kGamma;
  if (name == "slab") return ResponseKind::kSlab;
  if (name == "double") return ResponseKind::kDouble;
  throw std::invalid_argument("unknown material kind '" + name + "' (opaque, exponential, gamma, slab, double)");
}

const char* response_kind_name(ResponseKind kind) {
  switch (kind) {
    case ResponseKind::kOpaque: return "opaque";
    case ResponseKind::kExponential: return "exponential";
    case ResponseKind::kGamma: return "gamma";
    case ResponseKind::kSlab: return "slab";
    case ResponseKind::kDouble: return "double";
  }
  return "?";
}

void Material::validate() const {
  auto bad = [&](const char* what) { throw std::invalid_argument("material '" + name + "': " + what); };
  if (!(albedo >= 0.0 && albedo <= 10.0)) bad("albedo must be in [0, 10]");
  if (!(subsurface >= 0.0 && subsurface <= 1.0)) bad("subsurface must be in [0, 1]");
  if (kind != ResponseKind::kOpaque && !(tau_ps > 0.0 && tau_ps <= 1e6)) bad("tau_ps must be in (0, 1e6]");
  if (kind == ResponseKind::kGamma && !(gamma_k >= 1e-2 && gamma_k <= 1e3)) bad("gamma_k must be in [0.01, 1000]");
  if (!(refractive_index >= 1.0 && refractive_index <= 4.0)) bad("refractive_index must be in [1, 4]");
  if (kind == ResponseKind::kDouble) {
    if (!(subsurface2 >= 0.0 && subsurface + subsurface2 <= 1.0))
      bad("subsurface2 must be >= 0 with subsurface + subsurface2 <= 1");
    if (!(tau2_ps > 0.0 && tau2_ps <= 1e6)) bad("tau2_ps must be in (0, 1e6]");
  }
  if (!(noise_mm >= 0.0 && noise_mm <= 1e3)) bad("noise_mm must be in [0, 1000]");
  if (kind == ResponseKind::kSlab) {
    if (!(thickness_mm > 0.0 && thickness_mm <= 1e3)) bad("thickness_mm must be in (0, 1000]");
    if (!(path_factor >= 1.0 && path_factor <= 1e4)) bad("path_factor must be in [1, 1e4]");
    if (!(backing >= 0.0 && backing <= 10.0)) bad("backing must be in [0, 10]");
  }
}

std::complex<double> exponential_kernel(double omega, double tau_s) { return one_over_one_plus_ix(omega * tau_s); }

std::complex<double> gamma_kernel(double omega, double tau_s, double k) {
  const double y = omega * tau_s / k;
  // log(1 + i y) = 0.5 log(1 + y^2) + i atan(y); log1p keeps small y exact,
  // log(hypot) avoids y^2 overflow for large y.
  const double log_mag = std::fabs(y) < 1e8 ? 0.5 * std::log1p(y * y) : std::log(std::hypot(1.0, y));
  return std::polar(std::exp(-k * log_mag), -k * std::atan(y));
}

std::complex<double> slab_kernel(double omega, double tau_s, double transit_s, double backing) {
  // Beyond T/tau = 745, e^{-T/tau} underflows: the slab is optically thick (this
  // also covers an infinite transit at grazing refraction).
  if (!(transit_s / tau_s < 745.0)) return one_over_one_plus_ix(omega * tau_s);
  // z = T (1/tau + i omega); 1 - e^{-z} = -expm1(-z)
  const std::complex<double> z{transit_s / tau_s, omega * transit_s};
  const std::complex<double> one_minus = -expm1_complex(-z);
  const std::complex<double> e = std::exp(-z);
  return one_minus * one_over_one_plus_ix(omega * tau_s) + backing * e;
}

double schlick_reflectance(double n, double incidence_rad) {
  const double f0 = ((n - 1.0) / (n + 1.0)) * ((n - 1.0) / (n + 1.0));
  const double c = std::clamp(std::cos(incidence_rad), 0.0, 1.0);
  const double x = 1.0 - c;
  return f0 + (1.0 - f0) * x * x * x * x * x;
}

std::complex<double> material_response(const Material& m, double freq_hz, double incidence_rad) {
  const bool second = m.kind == ResponseKind::kDouble && m.subsurface2 != 0.0;
  if (m.kind == ResponseKind::kOpaque || (m.subsurface == 0.0 && !second)) return {m.albedo, 0.0};
  const double n = m.refractive_index;
  const double f0 = schlick_reflectance(n, 0.0);
  // Fresnel transmission scales every subsurface share alike.
  const double transmitted = (1.0 - schlick_reflectance(n, incidence_rad)) / (1.0 - f0);
  const double b = std::min(1.0, m.subsurface * transmitted);
  const double omega = kTwoPi * freq_hz;
  const double tau = m.tau_ps * 1e-12;
  std::complex<double> k;
  switch (m.kind) {
    case ResponseKind::kExponential: k = exponential_kernel(omega, tau); break;
    case ResponseKind::kGamma: k = gamma_kernel(omega, tau, m.gamma_k); break;
    case ResponseKind::kSlab: {
      const double sin_t = std::sin(incidence_rad) / n;
      const double cos_t = std::sqrt(std::max(0.0, 1.0 - sin_t * sin_t));
      const double transit = m.path_factor * 2.0 * m.thickness_mm * n / (kCTrueMmPerS * cos_t);
      k = slab_kernel(omega, tau, transit, m.backing);
      break;
    }
    case ResponseKind::kDouble: {
      const double b2 = std::min(1.0, m.subsurface2 * transmitted);
      return m.albedo *
             ((1.0 - b - b2) + b * exponential_kernel(omega, tau) + b2 * exponential_kernel(omega, m.tau2_ps * 1e-12));
    }
    case ResponseKind::kOpaque: k = 1.0; break;
  }
  return m.albedo * ((1.0 - b) + b * k);
}

}  // namespace tofmat::sim
