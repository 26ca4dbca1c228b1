// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The stiff cases of stiff_cases.hpp. Inputs come from the phasor model of
// synthetic_raw.hpp; each fixed-point stage is compared with its float
// reference on the same raw samples (never with itself).
#include "stiff_cases.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <complex>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <memory>
#include <random>
#include <sstream>

#include "synthetic_raw.hpp"
#include "tofmat/core/bin_spec.hpp"
#include "tofmat/core/decode.hpp"
#include "tofmat/core/depth_bins.hpp"
#include "tofmat/core/fixed_decode.hpp"
#include "tofmat/core/fixed_depth_bins.hpp"
#include "tofmat/core/frame_smoothing.hpp"
#include "tofmat/core/raw_lut.hpp"

namespace tofmat_test {

using namespace tofmat;

namespace {

constexpr double kTwoPi = 2.0 * kPi;
constexpr const double* kRange = kGroupRangeMm;

// The budgets of docs/numerics.md (fixed against float).
constexpr double kPhaseBudgetRad = 1e-6;
constexpr double kAmplitudeBudgetRel = 1e-4;  // beyond the Q8 step, relative to max(A, 1 count)
constexpr double kDepthBudgetMm = 0.002;      // per frequency
constexpr double kCombinedBudgetMm = 0.006;   // its Q8 step plus a depth's budget
constexpr double kFeatureBudgetMm = 0.004;    // two depths' worth
constexpr double kBinMeanBudgetMm = 0.03;
constexpr double kBoxMeanBudgetMm = 1.0 / 512.0 + 1.0 / 65536.0;

double wrapped_diff(double a, double b, double period) { return std::remainder(a - b, period); }

// The worst errors of the fixed decode against the float one on a frame.
struct DecodeErrors {
  std::size_t pixels = 0, phase_compared = 0, both_valid = 0, flags_differ = 0;
  double phase = 0.0, amplitude = 0.0, depth = 0.0, combined = 0.0, feature = 0.0;
  std::size_t flags_not_allowed = 0, saturation_differs = 0;
};

DecodeErrors compare_decode(const SyntheticFrame& s) {
  const DecodedFrame f = decode_frame(s.raw.data(), s.n, s.p0);
  const FixedDecodedFrame x = decode_frame_fixed(s.raw.data(), FixedDecodeTables(s.p0, s.n), {}, FixedKernel::kScalar);
  DecodeErrors e;
  e.pixels = s.n;
  for (std::size_t i = 0; i < s.n; ++i) {
    for (std::size_t g = 0; g < 3; ++g) {
      const double fa = f.amplitude[g][i], a = x.amplitude_q8[g][i] / 256.0;
      e.amplitude = std::max(e.amplitude, (std::fabs(a - fa) - 1.0 / 256.0) / std::max(fa, 1.0));
      // Every phasor but zero (three equal samples: no phase, and the float
      // path's rounding leaves it a few 1e-7 counts long), down to the
      // smallest the integer samples make.
      const std::int16_t m0 = s.raw[3 * g * s.n + i], m1 = s.raw[(3 * g + 1) * s.n + i],
                         m2 = s.raw[(3 * g + 2) * s.n + i];
      if (m0 != m1 || m1 != m2) {
        ++e.phase_compared;
        const double ph = x.phase_turns[g][i] * (kTwoPi / 4294967296.0);
        e.phase = std::max(e.phase, std::fabs(wrapped_diff(ph, f.phase_rad[g][i], kTwoPi)));
      }
    }
    if ((x.flags[i] ^ f.flags[i]) & kDecodeSaturated) ++e.saturation_differs;
    if (x.flags[i] != f.flags[i]) {
      ++e.flags_differ;
      if (!flag_difference_allowed(f, i)) ++e.flags_not_allowed;
      continue;
    }
    if (f.flags[i]) continue;
    ++e.both_valid;
    for (std::size_t g = 0; g < 3; ++g) {
      e.depth = std::max(e.depth, std::fabs(wrapped_diff(x.depth_q16[g][i] / 65536.0, f.depth_mm[g][i], kRange[g])));
    }
    e.combined = std::max(e.combined, std::fabs(x.combined_q8[i] / 256.0 - f.combined_mm[i]));
    for (std::size_t k = 0; k < 2; ++k) {
      // A difference of wrapped depths: at a wrap point the two paths may sit
      // on opposite sides; wavelengths are multiples of 625 mm.
      e.feature =
          std::max(e.feature, std::fabs(std::remainder(x.features_q16[k][i] / 65536.0 - f.features[k][i], 625.0)));
    }
  }
  return e;
}

enum Quantity : unsigned {
  kPhase = 1,
  kAmplitude = 2,
  kDepth = 4,
  kCombined = 8,
  kFeature = 16,
  kFlags = 32,
  kSaturation = 64
};

void add_decode_rows(std::vector<StiffRow>& rows, const std::string& scenario, const std::string& inputs,
                     const DecodeErrors& e, unsigned which) {
  const std::string pa = "decode: phase, amplitude (phase_amplitude)";
  const std::string fin = "decode: unwrap, depths, features, flags (finish_pixels)";
  const auto row = [&](const std::string& stage, std::size_t n, const std::string& q, double worst, double budget) {
    rows.push_back({stage, scenario, inputs, n, q, worst, budget});
  };
  if (which & kPhase) row(pa, e.phase_compared, "phase, rad (every non-zero phasor)", e.phase, kPhaseBudgetRad);
  if (which & kAmplitude) {
    row(pa, 3 * e.pixels, "amplitude beyond its Q8 step, relative to max(A, 1 count)", e.amplitude,
        kAmplitudeBudgetRel);
  }
  if (which & kSaturation) row(pa, e.pixels, "saturation flags that differ", double(e.saturation_differs), 0.0);
  if (which & kDepth) row(fin, e.both_valid, "per-frequency depth, mm", e.depth, kDepthBudgetMm);
  if (which & kCombined) row(fin, e.both_valid, "combined depth, mm", e.combined, kCombinedBudgetMm);
  if (which & kFeature) row(fin, e.both_valid, "features (Eq. 10), mm", e.feature, kFeatureBudgetMm);
  if (which & kFlags) {
    row(fin, e.pixels,
        "flags that differ off a threshold's edge and the 16 MHz wrap point (" + std::to_string(e.flags_differ) +
            " differ, " + std::to_string(e.both_valid) + " valid in both)",
        double(e.flags_not_allowed), 0.0);
  }
}

// A frame of n pixels whose pixel i sees true depth depth(i) (mm, every
// group; the material's distortion comes on top in `shift`), amplitude amp(i)
// counts and a random offset and p0.
SyntheticFrame frame_of(std::size_t n, std::uint32_t seed, const std::function<double(std::size_t)>& depth,
                        const std::function<double(std::size_t)>& amp,
                        const std::function<std::complex<double>(std::size_t g)>& response = nullptr) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> p0d(-kPi, kPi), u01(0.0, 1.0);
  SyntheticFrame s;
  s.n = n;
  s.raw.assign(9 * n, 0);
  s.p0.assign(3 * n, 0.0f);
  for (std::size_t i = 0; i < n; ++i) {
    const double d = depth(i);
    double a = amp(i);
    double dg[3] = {d, d, d};
    double ag = a;
    if (response) {
      // A material's response R per frequency: its phase delays the group
      // (measured depth + arg(R)/2pi of a range), its modulus scales the
      // amplitude (the decode sees one amplitude per group: the smallest
      // factor is applied to all, keeping the groups' ratios near 1).
      double smallest = 1.0;
      for (std::size_t g = 0; g < 3; ++g) {
        const std::complex<double> r = response(g);
        dg[g] = d - std::arg(r) / kTwoPi * kRange[g];
        smallest = std::min(smallest, std::abs(r));
      }
      ag = a * smallest;
    }
    const double offset = (u01(rng) - 0.5) * 2.0 * std::max(0.0, 16000.0 - ag);
    float p0[3];
    for (float& v : p0) v = static_cast<float>(p0d(rng));
    put_synthetic_pixel(s.raw.data(), s.p0.data(), n, i, dg, p0, ag, offset);
  }
  return s;
}

std::function<double(std::size_t)> uniform(std::uint32_t seed, double lo, double hi) {
  auto rng = std::make_shared<std::mt19937_64>(seed);
  return [rng, lo, hi](std::size_t) { return std::uniform_real_distribution<double>(lo, hi)(*rng); };
}

std::function<double(std::size_t)> log_uniform(std::uint32_t seed, double lo, double hi) {
  auto rng = std::make_shared<std::mt19937_64>(seed);
  return [rng, lo, hi](std::size_t) {
    return std::exp(std::uniform_real_distribution<double>(std::log(lo), std::log(hi))(*rng));
  };
}

// The exponential subsurface kernel of the simulator (docs/simulator-model.md):
// R = (1 - b) + b / (1 + i omega tau), a share b of the light delayed, at
// each group's modulation frequency (c / (2 range): 80, 16, 120 MHz with the device's c).
std::function<std::complex<double>(std::size_t)> subsurface(double tau_s, double b) {
  return [tau_s, b](std::size_t g) {
    const double f_hz = 3e11 / (2.0 * kRange[g]);  // c = 3e11 mm/s
    return (1.0 - b) + b / std::complex<double>(1.0, kTwoPi * f_hz * tau_s);
  };
}

void decode_cases(std::vector<StiffRow>& rows, std::size_t n) {
  const unsigned finish = kDepth | kCombined | kFeature | kFlags;
  {  // Near-zero amplitude: the rounding of the samples is most of the phasor.
    const SyntheticFrame s = frame_of(n, 1, uniform(11, 0.0, 9375.0), log_uniform(12, 0.01, 3.0));
    add_decode_rows(rows, "near-zero amplitude", "A 0.01..3 counts (log-uniform), depths 0..9375 mm", compare_decode(s),
                    kPhase | kAmplitude | kFlags);
  }
  {  // Saturation: one to nine samples of half the pixels at 32767.
    SyntheticFrame s = frame_of(n, 2, uniform(21, 0.0, 9375.0), log_uniform(22, 3.0, 8000.0));
    std::mt19937 rng(23);
    for (std::size_t i = 0; i < n; i += 2) {
      const int k = std::uniform_int_distribution<int>(1, 9)(rng);
      for (int j = 0; j < k; ++j) {
        s.raw[static_cast<std::size_t>(std::uniform_int_distribution<int>(0, 8)(rng)) * n + i] = kRawSaturated;
      }
    }
    add_decode_rows(rows, "saturation", "1..9 samples of every second pixel at 32767, A 3..8000 counts",
                    compare_decode(s), kPhase | kAmplitude | kSaturation | kFlags);
  }
  {  // The largest magnitudes: samples up to +-16320 (clamped there).
    const SyntheticFrame s = frame_of(n, 3, uniform(31, 0.0, 9375.0), uniform(32, 8000.0, 16320.0));
    add_decode_rows(rows, "largest magnitudes", "A 8000..16320 counts, samples clamped to +-16320", compare_decode(s),
                    kPhase | kAmplitude | finish);
  }
  {  // Wrap points: exactly on multiples of 1250 mm (the 120 MHz range; 3750
     // and 7500 are every group's), and a hair either side of the 80 MHz ones.
    const auto depth = [](std::size_t i) {
      const double k = static_cast<double>((i / 3) % 8);
      return i % 3 == 0 ? kRange[2] * k : kRange[0] * (k + 1.0) + (i % 3 == 1 ? -1e-7 : 1e-7);
    };
    const SyntheticFrame s = frame_of(n, 4, depth, log_uniform(41, 100.0, 8000.0));
    add_decode_rows(rows, "wrap points", "depths k x 1250 mm, and k x 1875 mm +-1e-7 mm; A 100..8000 counts",
                    compare_decode(s), finish);
  }
  {  // The ends of the unambiguous range (9375 mm): just above 0, just below 9375.
    const auto depth = [rng = std::make_shared<std::mt19937_64>(51)](std::size_t i) {
      const double e = std::uniform_real_distribution<double>(0.0, 1e-3)(*rng);
      return i % 2 == 0 ? e : 9375.0 - e;
    };
    const SyntheticFrame s = frame_of(n, 5, depth, log_uniform(52, 100.0, 8000.0));
    add_decode_rows(rows, "range ends", "depths 0..0.001 mm and 9374.999..9375 mm; A 100..8000 counts",
                    compare_decode(s), finish);
  }
  {  // Tiny tau: all the light delayed by 1 ps (omega tau 5e-4 at 80 MHz)
     // moves each group by about a micrometre.
    const SyntheticFrame s =
        frame_of(n, 6, uniform(61, 500.0, 4500.0), log_uniform(62, 50.0, 8000.0), subsurface(1e-12, 1.0));
    add_decode_rows(rows, "tiny tau (1 ps)", "R = 1/(1 + i omega tau) per group; depths 500..4500 mm, A 50..8000",
                    compare_decode(s), kPhase | finish);
  }
  {  // Huge tau, half the light: 100 ns (omega tau 10 to 75) leaves the
     // delayed half almost in quadrature, so each group moves by about
     // 1/(omega tau) rad: 75 mm at 16 MHz, 3 mm at 80 MHz, the groups' depths
     // tens of millimetres apart (as a strongly distorting material) but valid.
    const SyntheticFrame s =
        frame_of(n, 7, uniform(71, 500.0, 4500.0), log_uniform(72, 50.0, 8000.0), subsurface(1e-7, 0.5));
    add_decode_rows(rows, "huge tau (100 ns), half the light",
                    "R = 0.5 + 0.5/(1 + i omega tau) per group; depths 500..4500 mm, A 50..8000", compare_decode(s),
                    kPhase | kAmplitude | finish);
  }
  {  // Huge tau, all the light: every group a quarter turn late and its
     // amplitude down to 1/75: the unwrapped depths disagree, both paths
     // flag the pixels.
    const SyntheticFrame s =
        frame_of(n, 8, uniform(81, 500.0, 4500.0), log_uniform(82, 50.0, 8000.0), subsurface(1e-7, 1.0));
    add_decode_rows(rows, "huge tau (100 ns), all the light",
                    "R = 1/(1 + i omega tau) per group; depths 500..4500 mm, A 50..8000", compare_decode(s),
                    kPhase | kAmplitude | kFlags);
  }
}

// Depth bins: the float accumulator fed the float decode, the fixed one the
// fixed decode, `adds` times each.
void bin_case(std::vector<StiffRow>& rows, const std::string& scenario, const std::string& inputs,
              const SyntheticFrame& s, const BinSpec& bins, std::size_t adds) {
  const DecodedFrame f = decode_frame(s.raw.data(), s.n, s.p0);
  const FixedDecodedFrame x = decode_frame_fixed(s.raw.data(), FixedDecodeTables(s.p0, s.n));
  DepthBinAccumulator fl(bins, 2);
  FixedDepthBinAccumulator fx(bins, 2);
  for (std::size_t k = 0; k < adds; ++k) {
    for (std::size_t i = 0; i < s.n; ++i) {
      if (f.flags[i]) continue;
      const float v[2] = {f.features[0][i], f.features[1][i]};
      fl.add(f.combined_mm[i], v);
    }
    fx.add_frame(x);
  }
  const auto qf = fl.query(), qx = fx.query();
  double worst = 0.0;
  std::size_t compared = 0, moved = 0;
  for (std::uint32_t r = 0; r < 2; ++r) {
    for (std::uint32_t j = 0; j < bins.count; ++j) {
      const auto a = fl.count(r, j), b = fx.count(r, j);
      moved += a > b ? a - b : b - a;
      if (a != b || a == 0) continue;
      ++compared;
      const std::size_t k = r * bins.count + j;
      worst = std::max(worst, std::fabs(static_cast<double>(qf[k]) - qx[k]));
    }
  }
  const std::string stage = "depth bins (FixedDepthBinAccumulator)";
  rows.push_back({stage, scenario, inputs, compared, "bin mean, mm", worst, kBinMeanBudgetMm});
  rows.push_back({stage, scenario, inputs, compared, "observations in another bin", double(moved), 0.0});
}

void bin_cases(std::vector<StiffRow>& rows) {
  const BinSpec bins = BinSpec::linspace(600.0, 1200.0, 200);  // the real database's
  const auto centre = [&bins](std::size_t i) { return bins.lower_edge_mm(std::uint32_t(i)) + bins.width_mm / 2; };
  {  // One valid element: one pixel at the centre of every bin.
    const SyntheticFrame s = frame_of(bins.count, 9, centre, log_uniform(91, 30.0, 3000.0));
    bin_case(rows, "one valid element", "one pixel at the centre of each of 200 bins of 3 mm, A 30..3000 counts", s,
             bins, 1);
  }
  {  // Many: about 2^20 observations a bin (Q16 sums near 2^20 x 2^23).
    const std::size_t per_bin = 256, used = 8;
    const SyntheticFrame s = frame_of(
        per_bin * used, 10, [&](std::size_t i) { return centre(i % used); }, log_uniform(101, 30.0, 3000.0));
    bin_case(rows, "about 2^20 observations a bin", "256 pixels at each of 8 bin centres, the frame added 4096 times",
             s, bins, 4096);
  }
}

// The box mean against a long-double mean over the same window of the same
// Q16 features.
void box_case(std::vector<StiffRow>& rows, const std::string& scenario, const std::string& inputs, int w, int h,
              int side, const std::vector<std::int32_t>& f0, const std::vector<std::uint8_t>& flags) {
  BoxMeanFilter box(w, h, side);
  std::vector<std::int32_t> o0(f0.size()), o1(f0.size());
  std::vector<std::int32_t> f1(f0.size());
  for (std::size_t i = 0; i < f0.size(); ++i) f1[i] = f0[i] == kFixedInvalid ? kFixedInvalid : -f0[i];
  box.apply(f0.data(), f1.data(), flags.data(), 0, h, o0.data(), o1.data(), FixedKernel::kScalar);
  const int r = side / 2;
  double worst = 0.0;
  std::size_t compared = 0;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const auto i = static_cast<std::size_t>(y * w + x);
      if (flags[i]) continue;
      long double sum = 0.0L;
      int count = 0;
      for (int v = std::max(0, y - r); v <= std::min(h - 1, y + r); ++v) {
        for (int u = std::max(0, x - r); u <= std::min(w - 1, x + r); ++u) {
          const auto j = static_cast<std::size_t>(v * w + u);
          if (flags[j]) continue;
          sum += f0[j] / 65536.0L;
          ++count;
        }
      }
      const long double mean = sum / count;
      ++compared;
      worst = std::max({worst, static_cast<double>(std::fabs(o0[i] / 65536.0L - mean)),
                        static_cast<double>(std::fabs(o1[i] / 65536.0L + mean))});
    }
  }
  rows.push_back({"segmentation smoothing (BoxMeanFilter)", scenario, inputs, compared, "window mean, mm", worst,
                  kBoxMeanBudgetMm});
}

void box_cases(std::vector<StiffRow>& rows) {
  // The features' extremes: differences of wrapped depths, |f| < 9375 mm.
  const std::int32_t extreme = 9375 * 65536 - 1;
  std::mt19937 rng(2017);
  {
    const int w = 48, h = 40;
    std::vector<std::int32_t> f(static_cast<std::size_t>(w * h));
    std::vector<std::uint8_t> flags(f.size());
    for (std::size_t i = 0; i < f.size(); ++i) {
      flags[i] = rng() % 20 == 0 ? kDecodeUnwrap : 0;
      const std::int32_t v = rng() % 2 ? extreme : -extreme + static_cast<std::int32_t>(rng() % 65536);
      f[i] = flags[i] ? kFixedInvalid : v;
    }
    box_case(rows, "widest window at the extremes", "15 x 15 over +-9375 mm features, 5 % flagged, 48 x 40", w, h, 15,
             f, flags);
  }
  {
    const int w = 64, h = 48;
    std::vector<std::int32_t> f(static_cast<std::size_t>(w * h), kFixedInvalid);
    std::vector<std::uint8_t> flags(f.size(), kDecodeDark);
    for (int y = 3; y < h; y += 16) {
      for (int x = 5; x < w; x += 16) {
        const auto i = static_cast<std::size_t>(y * w + x);
        flags[i] = 0;
        f[i] = static_cast<std::int32_t>(rng() % 2 ? extreme - rng() % 256 : -extreme + rng() % 256);
      }
    }
    box_case(rows, "one valid element", "15 x 15 windows holding one valid pixel each, at +-9375 mm", w, h, 15, f,
             flags);
  }
  {
    const int w = 7, h = 5;
    std::vector<std::int32_t> f(static_cast<std::size_t>(w * h));
    std::vector<std::uint8_t> flags(f.size(), 0);
    for (auto& v : f) v = static_cast<std::int32_t>(rng() % (2u * extreme)) - extreme;
    box_case(rows, "window wider than the frame", "15 x 15 over a 7 x 5 frame, +-9375 mm", w, h, 15, f, flags);
  }
}

std::string format_number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", v);
  return buf;
}

}  // namespace

bool flag_difference_allowed(const DecodedFrame& f, std::size_t i) {
  const DecodeOptions o;
  const double a0 = f.amplitude[0][i], a1 = f.amplitude[1][i], a2 = f.amplitude[2][i];
  std::array<double, 3> wrapped{};
  for (std::size_t g = 0; g < 3; ++g) wrapped[g] = f.phase_rad[g][i] / kTwoPi * kRange[g];
  const UnwrappedDepth u = unwrap_depths(wrapped);
  const double gap1 = std::fabs(u.depth_mm[kGroup80] - u.depth_mm[kGroup16]);
  const double gap2 = std::fabs(u.depth_mm[kGroup120] - u.depth_mm[kGroup80]);
  const auto near = [](double v, double edge, double tol) { return std::fabs(v - edge) < tol; };
  const bool wrap16 = std::min(wrapped[kGroup16], kRange[kGroup16] - wrapped[kGroup16]) < 0.002;
  return near(a0, o.min_amplitude, 0.01) || near(a1, o.min_amplitude, 0.01) || near(a2, o.min_amplitude, 0.01) ||
         near(a0 + a1 + a2, 3.0 * o.min_mean_amplitude, 0.01) || near(a1, o.min_unwrap_amplitude, 0.01) ||
         near(gap1, o.max_gap_16_80_mm, 0.01) || near(gap2, o.max_gap_80_120_mm, 0.01) || wrap16;
}

std::vector<StiffRow> stiff_cases(std::size_t pixels) {
  std::vector<StiffRow> rows;
  decode_cases(rows, pixels);
  bin_cases(rows);
  box_cases(rows);
  return rows;
}

std::string stiff_cases_markdown(const std::vector<StiffRow>& rows) {
  std::ostringstream out;
  out << "## Stiff cases\n\n"
      << "| stage | case | inputs | compared | quantity | worst error | budget | within budget |\n"
      << "|---|---|---|--:|---|--:|--:|---|\n";
  for (const StiffRow& r : rows) {
    out << "| " << r.stage << " | " << r.scenario << " | " << r.inputs << " | " << r.compared << " | " << r.quantity
        << " | " << format_number(r.worst) << " | " << format_number(r.budget) << " | " << (r.within() ? "yes" : "NO")
        << " |\n";
  }
  return out.str();
}

}  // namespace tofmat_test
