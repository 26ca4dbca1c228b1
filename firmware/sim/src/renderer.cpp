// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Renderer: ray casting of the scene's planes, per-pixel waveforms, saturation, noise and the P0 tables.
#include "tofmat/sim/renderer.hpp"

#include <algorithm>
#include <cmath>
#include <exception>
#include <random>
#include <stdexcept>
#include <thread>

#include "tofmat/core/decode.hpp"
#include "tofmat/core/raw_lut.hpp"
#include "tofmat/sim/gaussian.hpp"
#include "tofmat/sim/measurement.hpp"

namespace tofmat::sim {
namespace {

constexpr double kTwoPi = 6.283185307179586476925286766559;
constexpr double kDegToRad = kTwoPi / 360.0;
constexpr double kCTrueMmPerNs = 299.792458;

using Vec3 = Renderer::Vec3;
double dot(const Vec3& a, const Vec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }

Vec3 ray(const Camera& c, double px, double py) {
  const Vec3 v{(px + 0.5 - c.cx) / c.fx, (py + 0.5 - c.cy) / c.fy, 1.0};
  const double n = std::sqrt(dot(v, v));
  return {v.x / n, v.y / n, v.z / n};
}

// acos on [0, 1] to 2e-8 rad (Abramowitz and Stegun 4.4.46): the incidence of
// every pixel, a sixth of the render time through libm's acosf.
double acos_unit(double x) {
  const double p = 1.5707963050 +
                   x * (-0.2145988016 +
                        x * (0.0889789874 +
                             x * (-0.0501743046 +
                                  x * (0.0308918810 + x * (-0.0170881256 + x * (0.0066700901 + x * -0.0012624911))))));
  return std::sqrt(1.0 - x) * p;
}

// Normal facing the camera, turned by yaw about y, then pitch about x.
Vec3 normal(double yaw_deg, double pitch_deg) {
  const double y = yaw_deg * kDegToRad, p = pitch_deg * kDegToRad;
  return {std::sin(y) * std::cos(p), -std::sin(p), -std::cos(y) * std::cos(p)};
}

struct Plane {
  Vec3 point;
  Vec3 n;
  const Material* material;
  int id;  // index into a worker's per-plane waveform slots
};

// A worker's waveforms by plane and incidence step, so the locked cache is
// visited once per step and plane, not once per pixel.
using WaveformSlots = std::vector<std::array<const Waveform*, 91>>;

// The taps' soft full well as a table of S(u) = N(T) / T = (1 + u^p)^(-1/p)
// against u = |T| / W on [0, kSatMaxU]; beyond it S = 1/u (error < u^-p / p,
// 1e-12 for p >= 8). Linear interpolation errs by < 2e-6 (u spacing 1e-3).
constexpr double kSatMaxU = 4.0;
constexpr int kSatPoints = 4096;

std::vector<float> saturation_table(double p) {
  std::vector<float> t(kSatPoints + 2);
  for (int k = 0; k <= kSatPoints + 1; ++k) {
    const double u = kSatMaxU * k / kSatPoints;
    t[static_cast<std::size_t>(k)] = static_cast<float>(std::pow(1.0 + std::pow(u, p), -1.0 / p));
  }
  return t;
}

double saturate_lookup(const std::vector<float>& table, double t, double inv_well) {
  const double u = std::fabs(t) * inv_well;
  if (u >= kSatMaxU) return t / u;
  const double x = u * (kSatPoints / kSatMaxU);
  const auto k = static_cast<std::size_t>(x);
  const double fr = x - static_cast<double>(k);
  return t * (table[k] + fr * (table[k + 1] - table[k]));
}

// Independent noise streams per block of rows (splitmix64 of seed and block),
// so a frame does not depend on how many threads render it.
std::uint64_t block_seed(std::uint64_t seed, std::uint64_t block) {
  std::uint64_t z = seed + 0x9E3779B97F4A7C15ull * (block + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}
constexpr int kRowsPerBlock = 8;

// A worker's per-row buffers between the passes of render_rows.
struct RowBuffers {
  explicit RowBuffers(std::size_t n) : range(n), amp(n), dc(n), sigma(n), wf(n) {
    for (auto& v : m) v.resize(n);
  }
  std::vector<double> range, amp, dc, sigma;  // amp: signal counts of the return (0: none)
  std::array<std::vector<double>, 3> m;       // a group's three samples, noise-free then noisy
  std::vector<const Waveform*> wf;            // nullptr: no return
};

}  // namespace

Renderer::Renderer(DeviceProfile device, MaterialLibrary library, int threads)
    : device_(std::move(device)), library_(std::move(library)) {
  device_.validate();
  if (threads < 0 || threads > 256) throw std::invalid_argument("renderer threads must be 0..256");
  threads_ = threads > 0 ? threads : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  bool wells = false;
  for (const auto& g : device_.groups) wells = wells || std::isfinite(g.full_well);
  if (wells) saturation_ = saturation_table(device_.saturation_sharpness);
  // 1 - S(u) ~ u^p / p: below u = (1e-7 p)^(1/p) a tap is linear to 1e-7.
  linear_below_ = std::pow(1e-7 * device_.saturation_sharpness, 1.0 / device_.saturation_sharpness);
  for (const auto& m : library_.materials) m.validate();
  const auto& c = device_.camera;
  rays_.resize(static_cast<std::size_t>(c.width) * static_cast<std::size_t>(c.height));
  for (int y = 0; y < c.height; ++y) {
    for (int x = 0; x < c.width; ++x) rays_[static_cast<std::size_t>(y * c.width + x)] = ray(c, x, y);
  }
  const auto& pp = device_.pixel_phase;
  std::mt19937_64 rng(pp.seed);
  std::normal_distribution<double> normal01(0.0, 1.0);
  for (std::size_t g = 0; g < 3; ++g) {
    auto& pat = pixel_phase_[g];
    pat.resize(rays_.size());
    for (int y = 0; y < c.height; ++y) {
      for (int x = 0; x < c.width; ++x) {
        const double rx = (x + 0.5 - c.cx) / c.cx, ry = (y + 0.5 - c.cy) / c.cy;
        const double r2 = 0.5 * (rx * rx + ry * ry);  // 1 at the corners
        pat[static_cast<std::size_t>(y * c.width + x)] =
            static_cast<float>(pp.mean_rad[g] + pp.radial_rad[g] * r2 + pp.scatter_rad * normal01(rng));
      }
    }
  }
}

const Waveform& Renderer::waveform(const Material& m, int incidence_step) const {
  std::lock_guard<std::mutex> lock(cache_mutex_);
  auto& slot = cache_[{&m, incidence_step}];
  if (slot) return *slot;
  auto w = std::make_unique<Waveform>();
  const double incidence = incidence_step * kIncidenceStepDeg * kDegToRad;
  for (std::size_t g = 0; g < 3; ++g) {
    const HarmonicWeights hw = harmonic_weights(device_.groups[g], m, incidence);
    w->dc = hw.dc;
    auto& tab = w->ac[g];
    tab.resize(3 * kWaveformPoints);
    for (int k = 0; k < kWaveformPoints; ++k) {
      const auto s = ac_per_unit(hw, kTwoPi * k / kWaveformPoints);
      for (std::size_t j = 0; j < 3; ++j) tab[static_cast<std::size_t>(k) * 3 + j] = static_cast<float>(s[j]);
    }
  }
  slot = std::move(w);
  return *slot;
}

std::vector<float> Renderer::p0_table(int group) const {
  if (group < 0 || group > 2) throw std::invalid_argument("group must be 0, 1 or 2");
  const auto& pat = pixel_phase_[static_cast<std::size_t>(group)];
  const auto eps = static_cast<float>(device_.groups[static_cast<std::size_t>(group)].decode_offset_rad);
  std::vector<float> out(pat.size());
  for (std::size_t i = 0; i < pat.size(); ++i) out[i] = -(pat[i] + eps);
  return out;
}

Frame Renderer::render(const Scene& scene, std::uint64_t seed, bool noise) const {
  return render_region(scene, seed, noise, PixelRect{0, 0, device_.camera.width, device_.camera.height});
}

Frame Renderer::render_region(const Scene& scene, std::uint64_t seed, bool noise, const PixelRect& region) const {
  const auto& cam = device_.camera;
  const int w = cam.width, h = cam.height;
  if (region.x0 < 0 || region.y0 < 0 || region.x1 > w || region.y1 > h || region.x0 >= region.x1 ||
      region.y0 >= region.y1) {
    throw std::invalid_argument("render region is empty or outside the image");
  }
  const int rw = region.x1 - region.x0, rh = region.y1 - region.y0;
  const std::size_t n_px = static_cast<std::size_t>(rw) * static_cast<std::size_t>(rh);

  // Planes: one per target (two when folded), split at the target's centre column.
  struct TargetPlanes {
    Plane left, right;
    double split_x;
    std::vector<std::uint8_t> mask;  // the rectangle's pixels it covers (target_mask)
  };
  std::vector<TargetPlanes> planes;
  int n_planes = 0;
  for (const auto& t : scene.targets) {
    if (t.x0 < 0 || t.y0 < 0 || t.x1 > w || t.y1 > h || t.x0 >= t.x1 || t.y0 >= t.y1) {
      throw std::invalid_argument("target '" + t.material + "' rectangle is empty or outside the image");
    }
    if (!(t.depth_mm > 0.0) || !(std::fabs(t.yaw_deg) <= 89.0) || !(std::fabs(t.pitch_deg) <= 89.0) ||
        !(std::fabs(t.fold_deg) <= 178.0)) {
      throw std::invalid_argument("target '" + t.material +
                                  "': depth must be > 0, |yaw|, |pitch| <= 89, |fold| <= 178");
    }
    const Material* m = &library_.find(t.material);
    const double cxp = 0.5 * (t.x0 + t.x1 - 1), cyp = 0.5 * (t.y0 + t.y1 - 1);
    const Vec3 r = ray(cam, cxp, cyp);
    const Vec3 p{r.x * t.depth_mm / r.z, r.y * t.depth_mm / r.z, t.depth_mm};
    planes.push_back({Plane{p, normal(t.yaw_deg + 0.5 * t.fold_deg, t.pitch_deg), m, n_planes},
                      Plane{p, normal(t.yaw_deg - 0.5 * t.fold_deg, t.pitch_deg), m, n_planes + 1}, cxp,
                      target_mask(t)});
    n_planes += 2;
  }
  const bool has_wall = !scene.background_material.empty();
  Plane wall{};
  if (has_wall) {
    if (!(scene.background_depth_mm > 0.0)) throw std::invalid_argument("background depth must be > 0");
    wall = Plane{
        {0.0, 0.0, scene.background_depth_mm}, {0.0, 0.0, -1.0}, &library_.find(scene.background_material), n_planes++};
  }

  Frame f;
  f.x0 = region.x0;
  f.y0 = region.y0;
  f.width = rw;
  f.height = rh;
  f.raw.assign(9 * n_px, 0);
  f.range_mm.assign(n_px, NAN);
  f.depth_mm.assign(n_px, NAN);
  f.target.assign(n_px, -2);
  f.incidence_deg.assign(n_px, NAN);

  const double sat = device_.signal.saturation;
  const auto& nm = device_.noise;
  const double points_per_rad = kWaveformPoints / kTwoPi;
  // Full well in counts: full_well = 1 is the 16 MHz tap signal of an albedo-1
  // target at range_ref_mm (spec 2.1), i.e. counts_at_1m * (1000 / range_ref)^2.
  const double well_unit =
      device_.signal.counts_at_1m * (1000.0 / device_.range_ref_mm) * (1000.0 / device_.range_ref_mm);
  std::array<double, 3> omega_per_mm{}, inv_well{};  // phase per mm of range; 1 / full well (0: none)
  std::array<bool, 3> linear{};
  for (std::size_t g = 0; g < 3; ++g) {
    const auto& fm = device_.groups[g];
    omega_per_mm[g] = kTwoPi * fm.true_freq_hz() * 1e-9 * 2.0 / kCTrueMmPerNs;
    linear[g] = !std::isfinite(fm.full_well);
    inv_well[g] = linear[g] ? 0.0 : 1.0 / (fm.full_well * well_unit);
  }

  // One block of rows, a row at a time in passes over the row: geometry (and
  // the truth), then per group the noise-free samples from the waveform tables,
  // the noise and the 11-bit code. The passes keep the per-sample loops free of
  // the per-pixel branches, so the noise level and the code vectorise.
  const auto render_rows = [&](int by0, int by1, std::uint64_t block, WaveformSlots& slots, RowBuffers& row) {
    FastNormal gauss(block_seed(seed, block));
    for (int y = by0; y < by1; ++y) {
      // i0: the row's first index in the output region; gi0: in the camera's full grid.
      const std::size_t i0 = static_cast<std::size_t>(y - region.y0) * static_cast<std::size_t>(rw);
      const std::size_t gi0 =
          static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(region.x0);
      for (int x = region.x0; x < region.x1; ++x) {
        const auto c = static_cast<std::size_t>(x - region.x0);
        const std::size_t i = i0 + c;
        const Vec3& d = rays_[gi0 + c];
        const Plane* s = nullptr;
        int target = -2;
        for (int k = static_cast<int>(scene.targets.size()) - 1; k >= 0; --k) {
          const auto& t = scene.targets[static_cast<std::size_t>(k)];
          if (x < t.x0 || x >= t.x1 || y < t.y0 || y >= t.y1) continue;
          const auto& tp = planes[static_cast<std::size_t>(k)];
          if (tp.mask[static_cast<std::size_t>(y - t.y0) * static_cast<std::size_t>(t.x1 - t.x0) +
                      static_cast<std::size_t>(x - t.x0)]) {
            s = x < tp.split_x ? &tp.left : &tp.right;
            target = k;
            break;
          }
        }
        if (!s && has_wall) {
          s = &wall;
          target = -1;
        }
        double range = 0.0, cos_inc = 0.0;
        if (s) {
          const double nd = dot(s->n, d);
          range = nd < 0.0 ? dot(s->n, s->point) / nd : -1.0;
          cos_inc = -nd;
          if (!(range > 0.0)) s = nullptr;  // facing away: no return
        }
        row.wf[c] = nullptr;
        row.range[c] = 0.0;
        row.amp[c] = 0.0;
        if (!s) continue;
        const double inc_deg = acos_unit(std::min(1.0, cos_inc)) / kDegToRad;  // cos_inc > 0: range > 0
        f.range_mm[i] = static_cast<float>(range);
        f.depth_mm[i] = static_cast<float>(range * d.z);
        f.target[i] = static_cast<std::int16_t>(target);
        f.incidence_deg[i] = static_cast<float>(inc_deg);
        const auto step = static_cast<std::size_t>(std::lround(inc_deg / kIncidenceStepDeg));  // inc_deg >= 0
        auto& slot = slots[static_cast<std::size_t>(s->id)][step];
        if (!slot) slot = &waveform(*s->material, static_cast<int>(step));
        row.wf[c] = slot;
        row.range[c] = range;
        row.amp[c] = device_.signal.counts_at_1m * cos_inc * (1000.0 / range) * (1000.0 / range);
      }
      for (std::size_t g = 0; g < 3; ++g) {
        const auto& fm = device_.groups[g];
        const float* phase = &pixel_phase_[g][gi0];
        for (std::size_t c = 0; c < static_cast<std::size_t>(rw); ++c) {
          const Waveform* wf = row.wf[c];
          if (!wf) {
            row.m[0][c] = row.m[1][c] = row.m[2][c] = row.dc[c] = 0.0;
            continue;
          }
          const double a = row.amp[c] * fm.signal_scale;
          const double dc = a * wf->dc;
          // Table position: the integer part wraps by masking (N is a power of two).
          const double t = (omega_per_mm[g] * row.range[c] - phase[c]) * points_per_rad;
          const double whole = std::floor(t);
          const double fr = t - whole;
          constexpr std::int64_t kMask = kWaveformPoints - 1;
          const auto k0 = static_cast<std::size_t>(static_cast<std::int64_t>(whole) & kMask);
          const auto k1 = static_cast<std::size_t>((static_cast<std::int64_t>(whole) + 1) & kMask);
          const float* p = &wf->ac[g][k0 * 3];
          const float* q = &wf->ac[g][k1 * 3];
          double ac[3];
          double peak = 0.0;
          for (std::size_t j = 0; j < 3; ++j) {
            ac[j] = a * (p[j] + fr * (q[j] - p[j]));
            peak = std::max(peak, std::fabs(ac[j]));
          }
          // Taps in anti-phase; the sample is their difference (spec 3.1). A
          // pixel whose brighter tap stays below linear_below_ of the well is
          // linear to 1e-7: most pixels skip the two table lookups per sample.
          const bool taps_linear = linear[g] || 0.5 * (dc + peak) * inv_well[g] < linear_below_;
          for (std::size_t j = 0; j < 3; ++j) {
            const double diff = taps_linear ? ac[j]
                                            : saturate_lookup(saturation_, 0.5 * (dc + ac[j]), inv_well[g]) -
                                                  saturate_lookup(saturation_, 0.5 * (dc - ac[j]), inv_well[g]);
            row.m[j][c] = fm.step_gain[j] * diff + fm.step_offset[j] * dc;
          }
          row.dc[c] = dc;
        }
        if (noise) {
          // Shot noise follows the light the taps collected (DC) plus ambient.
          const double read2 = nm.read_noise * nm.read_noise;
          for (std::size_t c = 0; c < static_cast<std::size_t>(rw); ++c) {
            row.sigma[c] = std::sqrt(read2 + nm.shot_gain * (row.dc[c] + nm.ambient));
          }
          for (std::size_t c = 0; c < static_cast<std::size_t>(rw); ++c) {
            for (std::size_t j = 0; j < 3; ++j) row.m[j][c] += row.sigma[c] * gauss();
          }
        }
        for (std::size_t j = 0; j < 3; ++j) {
          raw_quantise(row.m[j].data(), static_cast<std::size_t>(rw), sat, &f.raw[(g * 3 + j) * n_px + i0]);
        }
      }
    }
  };

  // Blocks of rows counted from the region's top row: the same region and seed
  // give the same frame whatever the number of threads.
  const int n_blocks = (rh + kRowsPerBlock - 1) / kRowsPerBlock;
  const int n_workers = std::min(threads_, n_blocks);
  std::vector<std::exception_ptr> errors(static_cast<std::size_t>(std::max(1, n_workers)));
  const auto work = [&](int first) {
    try {
      WaveformSlots slots(static_cast<std::size_t>(n_planes));
      RowBuffers row(static_cast<std::size_t>(rw));
      for (int b = first; b < n_blocks; b += n_workers) {
        const int y0 = region.y0 + b * kRowsPerBlock;
        render_rows(y0, std::min(region.y1, y0 + kRowsPerBlock), static_cast<std::uint64_t>(b), slots, row);
      }
    } catch (...) {
      errors[static_cast<std::size_t>(first)] = std::current_exception();
    }
  };
  if (n_workers <= 1) {
    work(0);
  } else {
    std::vector<std::thread> pool;
    pool.reserve(static_cast<std::size_t>(n_workers - 1));
    for (int t = 1; t < n_workers; ++t) pool.emplace_back(work, t);
    work(0);
    for (auto& t : pool) t.join();
  }
  for (const auto& e : errors) {
    if (e) std::rethrow_exception(e);
  }
  return f;
}

}  // namespace tofmat::sim
