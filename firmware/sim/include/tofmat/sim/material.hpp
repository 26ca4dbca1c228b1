// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Material temporal responses in closed form (docs/simulator-model.md, section 1).
// The Fourier coefficient r^(nu) of a material's impulse response shifts the
// phase of every modulation frequency and harmonic: Eq. (5) of the paper.
#pragma once

#include <complex>
#include <string>

namespace tofmat::sim {

enum class ResponseKind { kOpaque, kExponential, kGamma, kSlab, kDouble };

struct Material {
  std::string name;
  ResponseKind kind = ResponseKind::kOpaque;
  // Amplitude only, never phase. In a calibrated library its unit is the one
  // of the device's full_well (values above 1 are allowed: specular metals).
  double albedo = 0.5;
  double subsurface = 0.0;        // b: share of light returned after subsurface transport
  double tau_ps = 0.0;            // time constant of the subsurface kernel
  double gamma_k = 1.0;           // shape of the gamma kernel (1 = exponential)
  double refractive_index = 1.5;  // Fresnel share at incidence and slab transit
  double thickness_mm = 0.0;      // slab only
  double path_factor = 1.0;       // slab only: effective path / geometric round trip
  double backing = 0.0;           // slab only: backing reflection, relative
  double subsurface2 = 0.0;       // double only: share of the second exponential
  double tau2_ps = 1000.0;        // double only: its time constant
  // The per-sample 120 MHz depth noise of the capture the material was fitted
  // to (docs/simulator-model.md 4.1). Only distortion curves use it; rendered
  // frames get their noise from the device's noise model.
  double noise_mm = 0.0;

  // Throws std::invalid_argument for a parameter outside its physical range.
  void validate() const;
};

ResponseKind response_kind_from_name(const std::string& name);
const char* response_kind_name(ResponseKind kind);

// Kernels, accurate for omega*tau from 0 to 1e6 (no cancellation, no overflow,
// never NaN for finite inputs). Exponential and gamma are 1 at nu = 0; the
// slab is 1 - (1 - backing) exp(-T/tau) there: light that leaves through the
// back and is not returned by the backing is lost.
std::complex<double> exponential_kernel(double omega, double tau_s);
std::complex<double> gamma_kernel(double omega, double tau_s, double k);
// Exponential truncated at round-trip time T, plus the backing's reflection delayed by T.
std::complex<double> slab_kernel(double omega, double tau_s, double transit_s, double backing);

// Fresnel (Schlick) reflectance at incidence alpha for refractive index n.
double schlick_reflectance(double n, double incidence_rad);

// R(nu, alpha) = albedo * ((1 - b_eff) + b_eff * K(nu)); the double kind adds
// a second exponential, b2_eff / (1 + i omega tau2) (spec 1.1).
std::complex<double> material_response(const Material& m, double freq_hz, double incidence_rad);

}  // namespace tofmat::sim
