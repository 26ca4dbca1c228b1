// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// tofmat_bench_fixed: the fixed-point path's error against its run time
// (issue 5). A benchmark, not a test: it prints figures and never fails on
// timing (it exits non-zero only on bad options or a missing database).
//
//   tofmat_bench_fixed [--op all|stiff|decode|roi|nn|dist|session|learning|frame|unpack|unpack_roi|
//                            unpack_region]
//                      [--kernel best|scalar|float|reference] [--reps N] [--db DIR] [--window BINS]
//
// --op all (the default) measures everything on this host and prints markdown
// tables: full-frame (512x424) and 20x20 ROI decode, float reference against
// the fixed-point scalar and best kernels, with the fixed paths' error against
// float; nearest-neighbour queries on the real database, FloatClassifier
// against FixedClassifier (us/query and accuracy per window length); and the
// composite "fixed-point full-frame decode + features + per-pixel
// classification of 29 materials" (ms per frame, one core); and the 11-bit
// unpack of a depth packet (firmware/kinect raw_unpack.hpp: nine sub-images
// to raw values), whole, rows 188..236 and the 48x48 region at the centre, the
// definition (the unpack as first written) against the scalar and best kernels.
//
// --op stiff prints the fixed-point stages' worst errors against the float
// reference at their stiff cases (tests/cpp/stiff_cases.hpp, asserted by
// test_stiff_cases), 200,000 pixels per decode case: what `tofmat report`
// shows in its stability section. No timing.
//
// Any other --op runs only that operation with that kernel N times after its
// set-up (N = 0: set-up only) and prints one line, so that an instruction
// counter (qemu-aarch64 with tests/bench/qemu_insn_count.c) can take
// (count(N) - count(0)) / (N * units) as the cost of one unit:
//   decode  full-frame decode                      unit: a frame
//   roi     20x20 region decode                     unit: a region
//   nn      one query, quantised and searched       unit: a query
//   dist    the distance kernel only (queries quantised in set-up)   unit: a query
//   session the session matcher, tuned settings                       unit: a query
//   learning the session learner as a session starts (all six scales
//            weighed; best: fixed point, float: double)               unit: a query
//   frame   fixed decode + per-pixel classification                   unit: a frame
//   unpack      11-bit unpack of a whole depth packet (9 sub-images)   unit: a packet
//   unpack_roi  the same for output rows 188..236 only (48 rows: the
//               rows of the daemon's default 48 x 48 region)           unit: a packet's rows
//   unpack_region  the same for that 48 x 48 region only (columns
//               232..280 of those rows)                                unit: a packet's region
// Kernels: best (NEON on aarch64, AVX2 on x86-64 CPUs with it, scalar
// elsewhere), scalar, float (decode, roi, nn: the float reference), reference
// (unpack, unpack_roi: the definition, unpack_raw_reference, which has rows
// but no columns). nn is FixedClassifier::classify with the
// kernel given, dist its squared_sums() on queries prepared beforehand.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <memory>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "stiff_cases.hpp"
#include "synthetic_raw.hpp"
#include "tofmat/core/classifier.hpp"
#include "tofmat/core/compact_table.hpp"
#include "tofmat/core/decode.hpp"
#include "tofmat/core/exemplar_table.hpp"
#include "tofmat/core/fixed_classifier.hpp"
#include "tofmat/core/fixed_decode.hpp"
#include "tofmat/core/fixed_distance.hpp"
#include "tofmat/core/fixed_session_classifier.hpp"
#include "tofmat/core/frame_decode.hpp"
#include "tofmat/core/pixel_classifier.hpp"
#include "tofmat/core/raw_lut.hpp"
#include "tofmat/core/session_classifier.hpp"
#include "tofmat/core/session_learner.hpp"
#include "tofmat/kinect/constants.hpp"
#include "tofmat/kinect/raw_unpack.hpp"

#ifndef TOFMAT_DB_DIR
#define TOFMAT_DB_DIR "/work/shared/data/tanaka2017_kinect2_db"
#endif

namespace {

using namespace tofmat;
using Clock = std::chrono::steady_clock;

constexpr int kWidth = 512, kHeight = 424;
constexpr std::size_t kPixels = static_cast<std::size_t>(kWidth) * kHeight;
constexpr const double* kRange = tofmat_test::kGroupRangeMm;  // group order 80, 16, 120 MHz
constexpr PixelRegion kRoi{246, 202, 266, 222};               // 20x20 in the middle
constexpr int kUnpackRow0 = 188, kUnpackRow1 = 236;           // unpack_roi: the rows of a 48x48 region at the centre
constexpr PixelRegion kUnpackRegion{232, kUnpackRow0, 280, kUnpackRow1};  // unpack_region: that region
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

volatile std::int64_t g_sink = 0;  // keeps results alive

// ---------------------------------------------------------------- frames

struct Frame {
  std::vector<std::int16_t> raw;  // 9 x kPixels, sub-image-major
  std::vector<float> p0;          // 3 x kPixels
};

// Pixel i from the phasor model (tests/cpp/synthetic_raw.hpp), random p0.
template <class Rng>
void put_pixel(Frame& f, std::size_t i, const double depth_mm[3], double amp, double offset, Rng& rng) {
  std::uniform_real_distribution<double> p0d(-kPi, kPi);
  float p0[3];
  for (float& v : p0) v = static_cast<float>(p0d(rng));
  tofmat_test::put_synthetic_pixel(f.raw.data(), f.p0.data(), kPixels, i, depth_mm, p0, amp, offset);
}

Frame empty_frame() {
  Frame f;
  f.raw.assign(9 * kPixels, 0);
  f.p0.assign(3 * kPixels, 0.0f);
  return f;
}

// As tests/cpp/test_fixed_decode.cpp's random_frame, with realistic inputs:
// depths 500..4500 mm, amplitudes 20..3000 counts (log-uniform), offsets
// within +-500 counts, random p0.
Frame random_frame(std::uint32_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> depth(500.0, 4500.0), u01(0.0, 1.0);
  Frame f = empty_frame();
  for (std::size_t i = 0; i < kPixels; ++i) {
    const double d = depth(rng);
    const double amp = std::exp(std::log(20.0) + u01(rng) * (std::log(3000.0) - std::log(20.0)));
    const double offset = (u01(rng) - 0.5) * 1000.0;
    const double dg[3] = {d, d, d};
    put_pixel(f, i, dg, amp, offset, rng);
  }
  return f;
}

// The composite benchmark's scene: depths 610..1190 mm (a ramp down the rows,
// +-2 mm jitter), 29 vertical bands, one per material, whose pixels carry that
// material's curves at their depth bin (d16 = d + row 0, d80 = d + row 1,
// d120 = d: the database's sign), amplitudes 300..3000 counts.
Frame material_frame(const ExemplarTable& t, std::uint32_t seed, std::vector<std::uint8_t>& truth) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  Frame f = empty_frame();
  truth.assign(kPixels, 0);
  const auto n_mat = static_cast<int>(t.n_materials());
  for (int y = 0; y < kHeight; ++y) {
    for (int x = 0; x < kWidth; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * kWidth + static_cast<std::size_t>(x);
      const int m = x * n_mat / kWidth;
      truth[i] = static_cast<std::uint8_t>(m);
      const double d = 610.0 + 580.0 * y / (kHeight - 1) + (u01(rng) - 0.5) * 4.0;
      const std::int32_t b = t.bins().index_of(d);
      double c16 = 0.0, c80 = 0.0;
      if (b >= 0) {
        const float* v = t.material_values(static_cast<std::size_t>(m));
        const float r0 = v[static_cast<std::size_t>(b)], r1 = v[t.n_bins() + static_cast<std::size_t>(b)];
        c16 = std::isnan(r0) ? 0.0 : static_cast<double>(r0);
        c80 = std::isnan(r1) ? 0.0 : static_cast<double>(r1);
      }
      const double dg[3] = {d + c80, d + c16, d};
      const double amp = std::exp(std::log(300.0) + u01(rng) * (std::log(3000.0) - std::log(300.0)));
      put_pixel(f, i, dg, amp, (u01(rng) - 0.5) * 500.0, rng);
    }
  }
  return f;
}

// ---------------------------------------------------------------- depth packets

// A frame's raw values as the camera sends them: each sample's nearest 11-bit
// code (the saturation marker for 32767), packed into nine sub-images.
std::vector<std::uint8_t> packet_of(const Frame& f) {
  std::vector<std::uint8_t> packet(kinect::kUsedSubImages * kinect::kSubImageBytes);
  std::vector<std::uint16_t> codes(kPixels);
  for (int s = 0; s < kinect::kUsedSubImages; ++s) {
    const std::int16_t* raw = f.raw.data() + static_cast<std::size_t>(s) * kPixels;
    for (std::size_t i = 0; i < kPixels; ++i) {
      codes[i] = raw[i] == kRawSaturated ? kRawSaturationCode : raw_code_nearest(raw[i]);
    }
    kinect::pack_codes(codes.data(), packet.data() + static_cast<std::size_t>(s) * kinect::kSubImageBytes);
  }
  return packet;
}

// A region of a packet's nine sub-images with the kernel named ("reference":
// the definition, sub-image by sub-image, whole rows).
void unpack_packet(const std::string& kernel, const std::uint8_t* packet, std::int16_t* raw, const PixelRegion& g) {
  if (kernel == "reference") {
    for (int s = 0; s < kinect::kUsedSubImages; ++s) {
      kinect::unpack_raw_reference(packet + static_cast<std::size_t>(s) * kinect::kSubImageBytes,
                                   raw + static_cast<std::size_t>(s) * kPixels, g.y0, g.y1);
    }
  } else if (g.x0 == 0 && g.x1 == kWidth) {
    kinect::unpack_depth_packet_rows(packet, raw, g.y0, g.y1,
                                     kernel == "scalar" ? FixedKernel::kScalar : FixedKernel::kBest);
  } else {
    kinect::unpack_depth_packet_region(packet, raw, g, kernel == "scalar" ? FixedKernel::kScalar : FixedKernel::kBest);
  }
}

constexpr PixelRegion kWholeFrame{0, 0, kWidth, kHeight};
constexpr PixelRegion kUnpackRows{0, kUnpackRow0, kWidth, kUnpackRow1};

// ---------------------------------------------------------------- decode error

struct DecodeError {
  double depth_mm[3] = {0, 0, 0};  // max per-frequency depth error (80, 16, 120 MHz)
  double combined_mm = 0.0;
  std::size_t both_valid = 0, flags_differ = 0;
  double worst_depth() const { return std::max({depth_mm[0], depth_mm[1], depth_mm[2]}); }
};

DecodeError compare(const DecodedFrame& f, const FixedDecodedFrame& x) {
  DecodeError e;
  for (std::size_t i = 0; i < f.pixels; ++i) {
    if (f.flags[i] != x.flags[i]) ++e.flags_differ;
    if (f.flags[i] != 0 || x.flags[i] != 0) continue;
    ++e.both_valid;
    for (std::size_t g = 0; g < 3; ++g) {
      const double d = x.depth_q16[g][i] / 65536.0;
      e.depth_mm[g] = std::max(e.depth_mm[g], std::fabs(std::remainder(d - f.depth_mm[g][i], kRange[g])));
    }
    e.combined_mm = std::max(e.combined_mm, std::fabs(x.combined_q8[i] / 256.0 - f.combined_mm[i]));
  }
  return e;
}

// ---------------------------------------------------------------- timing

template <class F>
std::vector<double> sorted_seconds(long reps, F&& f) {
  f();  // warm-up
  std::vector<double> t;
  for (long r = 0; r < std::max(1L, reps); ++r) {
    const auto t0 = Clock::now();
    f();
    t.push_back(std::chrono::duration<double>(Clock::now() - t0).count());
  }
  std::sort(t.begin(), t.end());
  return t;
}

template <typename F>
double median_seconds(long reps, F&& f) {
  const std::vector<double> t = sorted_seconds(reps, f);
  return t[t.size() / 2];
}

// ---------------------------------------------------------------- nearest neighbour

struct Query {
  std::uint32_t material = 0, window = 0;
  std::vector<float> v;  // n_rows x n_bins, NaN = missing
};

// The queries of tests/cpp/test_fixed_classifier.cpp (and `make bench`):
// windows of consecutive bins of both rows, N(0, 0.3 mm) noise, seed 1,
// 40 per material and window length.
std::vector<Query> make_queries(const ExemplarTable& t) {
  std::mt19937 rng(1);
  std::normal_distribution<double> noise(0.0, 0.3);
  std::vector<Query> out;
  for (std::uint32_t window : {1u, 3u, 10u, 30u, 100u}) {
    std::uniform_int_distribution<std::uint32_t> start(0, t.n_bins() - window);
    for (std::uint32_t m = 0; m < t.n_materials(); ++m) {
      for (int k = 0; k < 40; ++k) {
        Query q{m, window, std::vector<float>(t.elements_per_material(), kNaN)};
        const std::uint32_t s = start(rng);
        for (std::uint32_t r = 0; r < t.n_rows(); ++r) {
          for (std::uint32_t b = s; b < s + window; ++b) {
            const float v = t.material_values(m)[r * t.n_bins() + b];
            if (!std::isnan(v)) q.v[r * t.n_bins() + b] = static_cast<float>(v + noise(rng));
          }
        }
        if (std::all_of(q.v.begin(), q.v.end(), [](float v) { return std::isnan(v); })) continue;
        out.push_back(std::move(q));
      }
    }
  }
  return out;
}

// make_queries(t), only those of `window` bins (0: all five lengths): the --window of the single ops.
std::vector<Query> queries_of_window(const ExemplarTable& t, std::uint32_t window) {
  std::vector<Query> qs = make_queries(t);
  if (window != 0) {
    qs.erase(std::remove_if(qs.begin(), qs.end(), [&](const Query& q) { return q.window != window; }), qs.end());
  }
  return qs;
}

// ---------------------------------------------------------------- options

struct Options {
  std::string op = "all", kernel = "best", db = TOFMAT_DB_DIR;
  long reps = -1;            // -1: the op's default
  std::uint32_t window = 0;  // nn/dist: only queries of this window length (0: all)
};

[[noreturn]] void usage(const char* why) {
  std::fprintf(
      stderr,
      "error: %s\nusage: tofmat_bench_fixed [--op all|stiff|decode|roi|nn|dist|session|learning|frame|unpack|\n"
      "                          unpack_roi|unpack_region]\n"
      "                          [--kernel best|scalar|float|reference] [--reps N] [--db DIR] [--window BINS]\n",
      why);
  std::exit(2);
}

Options parse(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) usage(("missing value after " + a).c_str());
    const std::string v = argv[++i];
    if (a == "--op") {
      o.op = v;
    } else if (a == "--kernel") {
      o.kernel = v;
    } else if (a == "--reps") {
      char* end = nullptr;
      o.reps = std::strtol(v.c_str(), &end, 10);
      if (*end != '\0' || o.reps < 0) usage("--reps takes a count >= 0");
    } else if (a == "--db") {
      o.db = v;
    } else if (a == "--window") {
      o.window = static_cast<std::uint32_t>(std::strtoul(v.c_str(), nullptr, 10));
    } else {
      usage(("unknown option " + a).c_str());
    }
  }
  const std::vector<std::string> ops{"all",   "stiff",  "decode",     "roi",           "nn",      "dist", "session",
                                     "frame", "unpack", "unpack_roi", "unpack_region", "learning"};
  if (std::find(ops.begin(), ops.end(), o.op) == ops.end()) usage("unknown --op");
  if (o.kernel != "best" && o.kernel != "scalar" && o.kernel != "float" && o.kernel != "reference") {
    usage("unknown --kernel");
  }
  const bool unpack = o.op == "unpack" || o.op == "unpack_roi" || o.op == "unpack_region";
  if (o.kernel == "float" && (o.op == "dist" || o.op == "frame" || unpack))
    usage("--kernel float is for decode, roi, nn, session and learning");
  if (o.kernel == "scalar" && o.op == "learning") usage("--op learning runs the best kernel or float");
  if (o.kernel == "reference" && o.op != "unpack" && o.op != "unpack_roi") {
    usage("--kernel reference is for unpack and unpack_roi");
  }
  return o;
}

FixedKernel fixed_kernel(const std::string& k) { return k == "scalar" ? FixedKernel::kScalar : FixedKernel::kBest; }

const char* best_name() { return best_pixel_kernel(); }  // decode: "neon" on aarch64, "avx2" on x86-64 CPUs with it

std::shared_ptr<const ExemplarTable> load_table(const std::string& dir) {
  return std::make_shared<const ExemplarTable>(ExemplarTable::from_npy_dir(dir, 600.0, 1200.0));
}

// ---------------------------------------------------------------- one op (instruction counting)

int run_single(const Options& o) {
  const long reps = o.reps < 0 ? 1 : o.reps;
  std::size_t units = 1;
  if (o.op == "decode" || o.op == "roi") {
    const Frame f = random_frame(7);
    if (o.kernel == "float") {
      const DecodeTables t(f.p0, kPixels);
      for (long r = 0; r < reps; ++r) {
        const DecodedFrame d =
            o.op == "decode" ? decode_frame(f.raw.data(), t) : decode_region(f.raw.data(), kWidth, kHeight, t, kRoi);
        g_sink = g_sink + d.flags[d.pixels / 2];
      }
    } else {
      const FixedDecodeTables t(f.p0, kPixels);
      const FixedKernel k = fixed_kernel(o.kernel);
      for (long r = 0; r < reps; ++r) {
        const FixedDecodedFrame d = o.op == "decode"
                                        ? decode_frame_fixed(f.raw.data(), t, {}, k)
                                        : decode_region_fixed(f.raw.data(), kWidth, kHeight, t, kRoi, {}, k);
        g_sink = g_sink + d.combined_q8[d.pixels / 2];
      }
    }
  } else if (o.op == "nn" || o.op == "dist") {
    const auto table = load_table(o.db);
    const std::vector<Query> qs = queries_of_window(*table, o.window);
    units = qs.size();
    if (o.kernel == "float") {
      const FloatClassifier fl(table);
      for (long r = 0; r < reps; ++r) {
        for (const auto& q : qs) g_sink = g_sink + fl.classify(q.v.data(), q.v.size()).best().index;
      }
    } else {
      const FixedClassifier fx(table, {}, fixed_kernel(o.kernel));
      if (o.op == "nn") {
        for (long r = 0; r < reps; ++r) {
          for (const auto& q : qs) g_sink = g_sink + fx.classify(q.v.data(), q.v.size()).best().index;
        }
      } else {  // the squared sums of prepared queries: the distance kernel's calls only (into one buffer)
        std::vector<FixedClassifier::Prepared> prepared;
        for (const auto& q : qs) prepared.push_back(fx.prepare(q.v.data(), q.v.size()));
        std::vector<SquaredSum> sums(fx.compact().n_candidates());
        for (long r = 0; r < reps; ++r) {
          for (const auto& pq : prepared) {
            fx.squared_sums(pq, sums.data());
            g_sink = g_sink + static_cast<std::int64_t>(sums[0].sum);
          }
        }
      }
    }
  } else if (o.op == "session") {  // the session-robust matcher, tuned settings, a whole query
    const auto table = load_table(o.db);
    const std::vector<Query> qs = queries_of_window(*table, o.window);
    units = qs.size();
    const SessionPrior prior = SessionPrior::tuned(*table);
    if (o.kernel == "float") {
      const SessionClassifier sc(table, prior);
      for (long r = 0; r < reps; ++r) {
        for (const auto& q : qs) g_sink = g_sink + sc.classify(q.v.data(), q.v.size()).best().index;
      }
    } else {  // scalar or best (NEON on aarch64)
      const FixedSessionClassifier fs(table, prior, {}, {}, fixed_kernel(o.kernel));
      for (long r = 0; r < reps; ++r) {
        for (const auto& q : qs) g_sink = g_sink + fs.classify(q.v.data(), q.v.size()).best().index;
      }
    }
  } else if (o.op == "learning") {  // the session learner as a session starts: every scale weighed, a whole query
    const auto table = load_table(o.db);
    const std::vector<Query> qs = queries_of_window(*table, o.window);
    units = qs.size();
    const auto learner = SessionLearner::make(table, SessionPrior::tuned(*table), o.kernel != "float");
    for (long r = 0; r < reps; ++r) {
      for (const auto& q : qs) g_sink = g_sink + learner->classify(q.v.data(), q.v.size()).mixture.best().index;
    }
  } else if (o.op == "frame") {
    const auto table = load_table(o.db);
    std::vector<std::uint8_t> truth, labels;
    const Frame f = material_frame(*table, 3, truth);
    const FixedDecodeTables t(f.p0, kPixels);
    const CompactTable c(*table);
    const PixelClassifier pc(c, table->bins());
    const FixedKernel k = fixed_kernel(o.kernel);
    labels.resize(kPixels);
    for (long r = 0; r < reps; ++r) {
      g_sink = g_sink + static_cast<std::int64_t>(pc.classify_frame(f.raw.data(), t, labels.data(), {}, k));
    }
  } else if (o.op == "unpack" || o.op == "unpack_roi" || o.op == "unpack_region") {
    const std::vector<std::uint8_t> packet = packet_of(random_frame(7));
    std::vector<std::int16_t> raw(kinect::kUsedSubImages * kPixels);
    const PixelRegion g = o.op == "unpack" ? kWholeFrame : o.op == "unpack_roi" ? kUnpackRows : kUnpackRegion;
    for (long r = 0; r < reps; ++r) {
      unpack_packet(o.kernel, packet.data(), raw.data(), g);
      g_sink = g_sink + raw[static_cast<std::size_t>(kUnpackRow0) * kWidth + 240];
    }
  }
  std::printf("op %s kernel %s (best = %s) reps %ld units %zu\n", o.op.c_str(), o.kernel.c_str(), best_name(), reps,
              units);
  return 0;
}

// ---------------------------------------------------------------- everything (timings on this host)

int run_all(const Options& o) {
  const long frame_reps = o.reps < 0 ? 11 : o.reps, roi_reps = o.reps < 0 ? 501 : o.reps,
             nn_reps = o.reps < 0 ? 5 : o.reps;
  std::printf("tofmat_bench_fixed: best kernel of this build = %s; frames %dx%d; one thread\n\n", best_name(), kWidth,
              kHeight);

  // Decode: float reference, fixed scalar, fixed best.
  const Frame f = random_frame(7);
  const DecodeTables ft(f.p0, kPixels);
  const FixedDecodeTables xt(f.p0, kPixels);
  const DecodedFrame ref = decode_frame(f.raw.data(), ft);
  std::size_t ref_valid = 0;
  for (auto fl : ref.flags) ref_valid += fl == 0;
  std::printf(
      "### Decode: 512x424 synthetic frame (depths 500..4500 mm, amplitudes 20..3000 counts, random p0; "
      "%zu of %zu pixels valid in the float decode)\n\n",
      ref_valid, kPixels);
  std::printf(
      "| path | full frame, ms (median of %ld) | 20x20 ROI, us (median of %ld) | max depth error vs float, mm "
      "(80 / 16 / 120 MHz) | max combined-depth error, mm | pixels valid in both | flags differ |\n",
      frame_reps, roi_reps);
  std::printf("|---|---:|---:|---|---:|---:|---:|\n");
  {
    const double full = median_seconds(frame_reps, [&] { g_sink = g_sink + decode_frame(f.raw.data(), ft).flags[0]; });
    const double roi = median_seconds(
        roi_reps, [&] { g_sink = g_sink + decode_region(f.raw.data(), kWidth, kHeight, ft, kRoi).flags[0]; });
    std::printf("| float (`decode_frame`, `DecodeTables`) | %.2f | %.1f | (reference) | | %zu | |\n", full * 1e3,
                roi * 1e6, ref_valid);
  }
  for (const char* kname : {"scalar", "best"}) {
    const FixedKernel k = fixed_kernel(kname);
    const DecodeError e = compare(ref, decode_frame_fixed(f.raw.data(), xt, {}, k));
    const double full =
        median_seconds(frame_reps, [&] { g_sink = g_sink + decode_frame_fixed(f.raw.data(), xt, {}, k).flags[0]; });
    const double roi = median_seconds(roi_reps, [&] {
      g_sink = g_sink + decode_region_fixed(f.raw.data(), kWidth, kHeight, xt, kRoi, {}, k).flags[0];
    });
    std::printf("| fixed %s%s | %.2f | %.1f | %.5f / %.5f / %.5f | %.4f | %zu | %zu |\n", kname,
                std::strcmp(kname, "best") == 0 ? (std::string(" (= ") + best_name() + ")").c_str() : "", full * 1e3,
                roi * 1e6, e.depth_mm[0], e.depth_mm[1], e.depth_mm[2], e.combined_mm, e.both_valid, e.flags_differ);
  }

  // Nearest neighbour on the real database.
  const auto table = load_table(o.db);
  const FloatClassifier fl(table);
  const FixedClassifier fx(table);
  const std::vector<Query> qs = make_queries(*table);
  std::printf(
      "\n### Nearest neighbour (Eq. (12)): real database, %zu materials x %u bins x %u rows, fixed step %g mm "
      "(compact table %zu bytes); queries as `make bench` (windows of consecutive bins, N(0, 0.3 mm) noise, "
      "seed 1); time per query = median of %ld passes / queries\n\n",
      table->n_materials(), table->n_bins(), table->n_rows(), fx.compact().step_mm(), fx.compact().memory_bytes(),
      nn_reps);
  std::printf(
      "| window (bins) | queries | float us/query | fixed us/query | float accuracy | fixed accuracy | labels "
      "differ |\n|---:|---:|---:|---:|---:|---:|---:|\n");
  for (std::uint32_t w : {1u, 3u, 10u, 30u, 100u}) {
    std::vector<const Query*> sel;
    for (const auto& q : qs) {
      if (q.window == w) sel.push_back(&q);
    }
    std::size_t ok_f = 0, ok_x = 0, differ = 0;
    for (const Query* q : sel) {
      const auto a = fl.classify(q->v.data(), q->v.size()).best().index;
      const auto b = fx.classify(q->v.data(), q->v.size()).best().index;
      ok_f += a == q->material;
      ok_x += b == q->material;
      differ += a != b;
    }
    const double tf = median_seconds(nn_reps, [&] {
      for (const Query* q : sel) g_sink = g_sink + fl.classify(q->v.data(), q->v.size()).best().index;
    });
    const double tx = median_seconds(nn_reps, [&] {
      for (const Query* q : sel) g_sink = g_sink + fx.classify(q->v.data(), q->v.size()).best().index;
    });
    const double n = static_cast<double>(sel.size());
    std::printf("| %u | %zu | %.2f | %.2f | %.1f %% | %.1f %% | %zu |\n", w, sel.size(), tf / n * 1e6, tx / n * 1e6,
                100.0 * static_cast<double>(ok_f) / n, 100.0 * static_cast<double>(ok_x) / n, differ);
  }

  // The composite: fixed decode + features + per-pixel classification.
  std::vector<std::uint8_t> truth, labels;
  const Frame mf = material_frame(*table, 3, truth);
  const FixedDecodeTables mt(mf.p0, kPixels);
  const PixelClassifier pc(fx.compact(), table->bins());
  const FixedDecodedFrame md = decode_frame_fixed(mf.raw.data(), mt, {}, FixedKernel::kBest);
  labels.resize(kPixels);
  const std::size_t classified = pc.classify(md, labels.data());
  std::size_t correct = 0;
  for (std::size_t i = 0; i < kPixels; ++i) correct += labels[i] == truth[i];
  // The integer per-pixel labels against FloatClassifier on a one-bin query
  // holding the pixel's two features (as floats) at its bin, every 97th pixel.
  std::size_t checked = 0, check_differs = 0;
  double check_gap = 0.0;  // largest float-distance margin where they differ (mm^2)
  for (std::size_t i = 0; i < kPixels; i += 97) {
    if (labels[i] == PixelClassifier::kUnclassified) continue;
    const std::int32_t b = table->bins().index_of(md.combined_q8[i] / 256.0);
    if (b < 0) continue;
    std::vector<float> q(table->elements_per_material(), kNaN);
    q[static_cast<std::size_t>(b)] = static_cast<float>(md.features_q16[0][i] / 65536.0);
    q[table->n_bins() + static_cast<std::size_t>(b)] = static_cast<float>(md.features_q16[1][i] / 65536.0);
    ++checked;
    const Classification c = fl.classify(q.data(), q.size());
    if (c.best().index == labels[i]) continue;
    ++check_differs;
    for (const auto& m : c.ranking) {
      if (m.index == labels[i]) check_gap = std::max(check_gap, m.distance - c.best().distance);
    }
  }
  std::printf(
      "\n### Fixed-point full-frame decode + features + per-pixel classification of %zu materials (one core)\n\n"
      "Scene: depths 610..1190 mm, %zu vertical bands each carrying one material's curves, amplitudes "
      "300..3000 counts; %zu of %zu pixels classified, %.1f %% of them as their band's material (one bin per pixel); "
      "check: FloatClassifier on the same two features gives another label at %zu of %zu sampled pixels (there "
      "the float distances of the two labels differ by at most %.3g mm^2: the features' quantisation to the "
      "table's step).\n\n",
      table->n_materials(), table->n_materials(), classified, kPixels,
      100.0 * static_cast<double>(correct) / static_cast<double>(std::max<std::size_t>(1, classified)), check_differs,
      checked, check_gap);
  std::printf("| stage | ms per frame (median of %ld) | best |\n|---|---:|---:|\n", frame_reps);
  // One row: the median and the best of frame_reps runs (the best is the
  // code's own cost; the median also carries what else the machine did).
  const auto row = [&](const std::string& what, auto&& run) {
    const std::vector<double> t = sorted_seconds(frame_reps, run);
    std::printf("| %s | %.2f | %.2f |\n", what.c_str(), t[t.size() / 2] * 1e3, t.front() * 1e3);
  };
  std::vector<std::uint8_t> fused(kPixels);
  for (const char* kname : {"scalar", "best"}) {
    const FixedKernel k = fixed_kernel(kname);
    const std::string kn =
        std::string(kname) + (std::strcmp(kname, "best") == 0 ? std::string(" = ") + best_name() : "");
    row("fixed decode (" + kn + "), new frame each time",
        [&] { g_sink = g_sink + decode_frame_fixed(mf.raw.data(), mt, {}, k).flags[0]; });
    FixedDecodedFrame reused;  // a stream of frames decodes into the same buffers
    row("fixed decode (" + kn + "), into reused buffers", [&] {
      decode_frame_fixed(mf.raw.data(), mt, reused, {}, k);
      g_sink = g_sink + reused.flags[0];
    });
    row("per-pixel classification alone (" + kn + ")",
        [&] { g_sink = g_sink + static_cast<std::int64_t>(pc.classify(md, labels.data(), k)); });
    row("fixed decode + per-pixel classification, reused buffers (" + kn + ")", [&] {
      decode_frame_fixed(mf.raw.data(), mt, reused, {}, k);
      g_sink = g_sink + static_cast<std::int64_t>(pc.classify(reused, labels.data(), k));
    });
    row("**decode + features + per-pixel classification fused in 512-pixel tiles** (`classify_frame`, " + kn + ")",
        [&] {
          g_sink = g_sink + static_cast<std::int64_t>(pc.classify_frame(mf.raw.data(), mt, fused.data(), {}, k));
        });
    if (fused != labels) throw std::logic_error("classify_frame disagrees with decode + classify");
  }

  // The 11-bit unpack of a depth packet, before and after.
  const std::vector<std::uint8_t> packet = packet_of(f);
  std::vector<std::int16_t> want(kinect::kUsedSubImages * kPixels), got(want.size());
  unpack_packet("reference", packet.data(), want.data(), kWholeFrame);
  std::printf(
      "\n### 11-bit unpack of a depth packet (9 sub-images of 512x424 packed codes to int16 raw values; "
      "the decode benchmark's frame as codes; one core)\n\n"
      "Whole packet, output rows %d..%d (%d rows: the rows of a 48x48 region at the centre) and that region "
      "(columns %d..%d of those rows). The definition is the unpack as first written (code by code from "
      "16-bit words, then the device table; whole rows only); before the region-aware unpack a consumer "
      "of a region paid the whole packet.\n\n",
      kUnpackRow0, kUnpackRow1, kUnpackRow1 - kUnpackRow0, kUnpackRegion.x0, kUnpackRegion.x1);
  std::printf(
      "| kernel | whole packet, ms (median of %ld) | best | rows %d..%d, ms (median of %ld) | best | "
      "48x48 region, ms (median of %ld) | best | equals the definition |\n"
      "|---|---:|---:|---:|---:|---:|---:|---|\n",
      frame_reps, kUnpackRow0, kUnpackRow1, roi_reps, roi_reps);
  for (const char* kname : {"reference", "scalar", "best"}) {
    const std::string k = kname;
    std::fill(got.begin(), got.end(), std::int16_t{0});
    unpack_packet(k, packet.data(), got.data(), kWholeFrame);
    const bool equal = got == want;
    const auto timed = [&](long reps, const PixelRegion& g) {
      return sorted_seconds(reps, [&] {
        unpack_packet(k, packet.data(), got.data(), g);
        g_sink = g_sink + got[static_cast<std::size_t>(kUnpackRow0) * kWidth + 240];
      });
    };
    const std::vector<double> full = timed(frame_reps, kWholeFrame), rows = timed(roi_reps, kUnpackRows);
    std::string region = "- | -";
    if (k != "reference") {
      const std::vector<double> t = timed(roi_reps, kUnpackRegion);
      char buf[64];
      std::snprintf(buf, sizeof buf, "%.4f | %.4f", t[t.size() / 2] * 1e3, t.front() * 1e3);
      region = buf;
    }
    const std::string name = k == "reference" ? "definition (`unpack_raw_reference`, the old unpack)"
                             : k == "scalar"  ? "scalar kernel"
                                              : std::string("best kernel (= ") + kinect::best_unpack_kernel() + ")";
    std::printf("| %s | %.3f | %.3f | %.4f | %.4f | %s | %s |\n", name.c_str(), full[full.size() / 2] * 1e3,
                full.front() * 1e3, rows[rows.size() / 2] * 1e3, rows.front() * 1e3, region.c_str(),
                equal ? "yes" : "**NO**");
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  const Options o = parse(argc, argv);
  try {
    if (o.op == "stiff") {
      std::fputs(tofmat_test::stiff_cases_markdown(tofmat_test::stiff_cases(200000)).c_str(), stdout);
      return 0;
    }
    return o.op == "all" ? run_all(o) : run_single(o);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tofmat_bench_fixed: %s\n", e.what());
    return 1;
  }
}
