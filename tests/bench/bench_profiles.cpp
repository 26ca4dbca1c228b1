// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// tofmat_bench_profiles: what each scene profile of tofmatd costs per frame,
// from the reassembled USB depth packet to the bytes of the event written to
// a socket. A benchmark, not a test: it prints figures and never fails on
// timing (it exits non-zero only on bad options or missing data).
//
//   tofmat_bench_profiles [--profile all|handheld|sorting|sorting-idle|segmentation|unpack-full|decode-full|
//                                    smooth-box|smooth-majority]
//                         [--reps R] [--kernel best|scalar] [--smooth N] [--no-truth] [--no-region-vote]
//                         [--accumulate N] [--session-learning [--warm-session] | --no-session-learning]
//                         [--table DIR|FILE.tmx] [--sim-data DIR] [--candidates a,b,c]
//
// The path measured, per frame, as tofmatd runs it (docs/daemon.md):
//   depth packet (kDepthPacketBytes, as Kinect2Device reassembles it)
//   -> kinect::unpack_depth_packet_region of exactly profile->input_region()
//      into a reused 9 x kPixels buffer (nothing when it is nullopt: sorting
//      between bursts; the frame then carries an empty region)
//   -> profile->process(frame, emitter)
//   -> the emitter encodes the event as the daemon's does: protocol::encode_label_wire,
//      or encode_label_map then protocol::encode (wire.hpp), the bytes
//      Server::publish queues for a subscriber. No client wants depth images
//      (wants_depth is false): label and label-map subscribers only.
//
// Packets are real ones, made once at start: a sim::SimulatedKinect
// (realtime = false, device kinect2_tanaka2017, library tanaka2017, the data
// of firmware/sim/data; one render thread, as tofmatd has: with more, the
// rendering's instruction count varies from run to run by more than a
// handheld frame costs) behind kinect::Kinect2Device, whose start() callback
// copies each packet and whose identity gives the P0 tables (Calibration).
//   handheld      4 materials, each swept 650..1150 mm in 6 frames
//                 (Scene::centred_target, yaw 10 deg, 160 px): 24 frames
//   sorting       the same 4 materials, each a burst of 8 frames at one depth
//                 (700, 850, 1000, 1150 mm): trigger(8), then 8 frames; 32 frames
//   sorting-idle  the sorting packets with no trigger: input_region() is nullopt
//   segmentation  sim_source.cpp's `regions` scene of cork, pvc and wood at
//                 600, 900 and 1200 mm: 3 frames (noise seeds differ)
//   unpack-full, decode-full  (for the segmentation breakdown) the full-frame
//                 unpack alone, and it followed by decode_frame_fixed
//   smooth-box, smooth-majority  segmentation's smoothing alone: its
//                 features' box mean and the label map's majority filter
//                 (frame_smoothing.hpp, the whole frame as one band), on
//                 frames decoded and labelled beforehand
// The table: the real database (TOFMAT_DB_DIR, loaded as tofmatd loads a
// folder: load_table_file, bins 600..1200 mm) unless --table says otherwise;
// profiles with the daemon's default configuration (ProfileConfig{}: every
// material of the table a candidate, 48 x 48 ROI at the centre, smooth 9).
//
// --profile P (not all) runs one warm-up pass and then R passes over the
// prepared packets and prints one line ending in " units N" (N = frames per
// pass), so that an instruction counter (qemu-aarch64 with
// tests/bench/qemu_insn_count.c, tests/bench/profile_counts.sh) can take
// (count(R) - count(0)) / (R x N) as the cost of one frame: the packets'
// preparation (rendering) and the warm-up happen in both and cancel.
// --kernel scalar selects the scalar unpack; the profiles choose their own
// kernels (FixedKernel::kBest throughout) unless ProfileConfig has a `kernel`
// member, which is then set too (the line says which applied).
//
// --session-learning (tofmatd's default) / --no-session-learning: the
// handheld and sorting profiles with the session learner
// (session_learner.hpp) or the session matcher alone. The learner is
// measured as a session starts: every pass is a new session (its weights
// reset), so that every frame is scored under each scale its weights still
// give weight to (all six over a pass's four sweeps; the finished sweeps it
// learns from included). --warm-session: one session over every pass
// instead, so that the counted passes come after the warm-up pass's four
// sweeps have been learned (the bench's scenes are a session that did not
// move: its weights gather on scale 0 and the scales they leave are not scored).
//
// --profile all (the default) prints markdown tables on this host (one core):
// per profile the median host ms per frame over R passes (default 7) with its
// stages, and the error against the simulator's truth and against the float
// reference (Backend::kFloat) where one exists; then the segmentation
// profile's steps.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "tofmat/core/compact_table.hpp"
#include "tofmat/core/exemplar_table.hpp"
#include "tofmat/core/fixed_decode.hpp"
#include "tofmat/core/fixed_kernel.hpp"
#include "tofmat/core/frame_smoothing.hpp"
#include "tofmat/core/pixel_classifier.hpp"
#include "tofmat/daemon/daemon.hpp"
#include "tofmat/daemon/frame.hpp"
#include "tofmat/daemon/profile.hpp"
#include "tofmat/daemon/sim_source.hpp"
#include "tofmat/kinect/constants.hpp"
#include "tofmat/kinect/device.hpp"
#include "tofmat/kinect/raw_unpack.hpp"
#include "tofmat/protocol/messages.hpp"
#include "tofmat/protocol/wire.hpp"
#include "tofmat/sim/kinect_device.hpp"
#include "tofmat/sim/profile_io.hpp"
#include "tofmat/sim/renderer.hpp"

#ifndef TOFMAT_DB_DIR
#define TOFMAT_DB_DIR "/work/shared/data/tanaka2017_kinect2_db"
#endif
#ifndef TOFMAT_SIM_DATA_DIR
#define TOFMAT_SIM_DATA_DIR "firmware/sim/data"
#endif

namespace {

using namespace tofmat;
using namespace tofmat::daemon;
using Clock = std::chrono::steady_clock;

volatile std::uint64_t g_sink = 0;  // keeps results alive

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// ---------------------------------------------------------------- options

struct Options {
  std::string profile = "all", kernel = "best", table = TOFMAT_DB_DIR, sim_data = TOFMAT_SIM_DATA_DIR;
  long reps = -1;   // -1: 1 for one profile, 7 for all
  int smooth = -1;  // -1: the profile's default
  int threads = 1;  // segmentation: threads sharing each frame (one core unless told)
  bool truth = true;
  bool region_vote = true;  // segmentation: --no-region-vote leaves it out
  int accumulate = 1;       // segmentation: --accumulate N (frames each pixel's features are averaged over)
  std::vector<std::string> candidates;
  std::string classifier;                                    // empty: the daemon's default
  bool session_learning = ProfileConfig{}.session_learning;  // the daemon's default
  bool warm_session = false;                                 // one session over every pass
};

const std::vector<std::string> kProfiles{"all",         "handheld",    "sorting",    "sorting-idle",   "segmentation",
                                         "unpack-full", "decode-full", "smooth-box", "smooth-majority"};

[[noreturn]] void usage(const char* why) {
  std::fprintf(
      stderr,
      "error: %s\nusage: tofmat_bench_profiles [--profile "
      "all|handheld|sorting|sorting-idle|segmentation|unpack-full|decode-full|smooth-box|smooth-majority]\n"
      "                             [--reps R] [--kernel best|scalar] [--smooth N] [--threads N] [--no-truth]\n"
      "                             [--no-region-vote] [--accumulate N] [--[no-]session-learning] [--warm-session]\n"
      "                             [--table DIR|FILE] [--sim-data DIR] [--candidates a,b,c] [--classifier "
      "eq12|session]\n",
      why);
  std::exit(2);
}

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  std::size_t from = 0;
  while (from <= s.size()) {
    const std::size_t comma = std::min(s.find(',', from), s.size());
    if (comma > from) out.push_back(s.substr(from, comma - from));
    from = comma + 1;
  }
  return out;
}

Options parse(int argc, char** argv) {
  Options o;
  std::optional<bool> learning;  // --session-learning / --no-session-learning
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--no-truth") {
      o.truth = false;
      continue;
    }
    if (a == "--no-region-vote") {
      o.region_vote = false;
      continue;
    }
    if (a == "--warm-session") {
      o.warm_session = true;
      continue;
    }
    if (a == "--session-learning" || a == "--no-session-learning") {
      learning = a == "--session-learning";
      continue;
    }
    if (i + 1 >= argc) usage(("missing value after " + a).c_str());
    const std::string v = argv[++i];
    char* end = nullptr;
    if (a == "--profile") {
      o.profile = v;
    } else if (a == "--kernel") {
      o.kernel = v;
    } else if (a == "--reps") {
      o.reps = std::strtol(v.c_str(), &end, 10);
      if (*end != '\0' || o.reps < 0) usage("--reps takes a count >= 0");
    } else if (a == "--smooth") {
      o.smooth = static_cast<int>(std::strtol(v.c_str(), &end, 10));
      if (*end != '\0') usage("--smooth takes an odd number of pixels");
    } else if (a == "--accumulate") {
      o.accumulate = static_cast<int>(std::strtol(v.c_str(), &end, 10));
      if (*end != '\0' || o.accumulate < 1 || o.accumulate > 256) usage("--accumulate takes 1..256 frames");
    } else if (a == "--threads") {
      o.threads = static_cast<int>(std::strtol(v.c_str(), &end, 10));
      if (*end != '\0' || o.threads < 0) usage("--threads takes a count >= 0 (0: every core)");
    } else if (a == "--table") {
      o.table = v;
    } else if (a == "--sim-data") {
      o.sim_data = v;
    } else if (a == "--candidates") {
      o.candidates = split(v);
    } else if (a == "--classifier") {
      o.classifier = v;
      if (v != "eq12" && v != "session") usage("--classifier takes eq12 or session");
    } else {
      usage(("unknown option " + a).c_str());
    }
  }
  if (std::find(kProfiles.begin(), kProfiles.end(), o.profile) == kProfiles.end()) usage("unknown --profile");
  if (o.kernel != "best" && o.kernel != "scalar") usage("unknown --kernel (best, scalar)");
  if (o.classifier == "eq12" && learning.value_or(false))
    usage("--session-learning learns the session matcher's session: not with --classifier eq12");
  o.session_learning = learning.value_or(o.session_learning) && o.classifier != "eq12";
  if (o.warm_session && !o.session_learning) usage("--warm-session is the session learner's");
  return o;
}

FixedKernel fixed_kernel(const std::string& k) { return k == "scalar" ? FixedKernel::kScalar : FixedKernel::kBest; }

// ProfileConfig::kernel, if the daemon has one (set it), else nothing (false).
template <class C, class = void>
struct HasKernel : std::false_type {};
template <class C>
struct HasKernel<C, std::void_t<decltype(std::declval<C&>().kernel)>> : std::true_type {};
template <class C>
bool set_profile_kernel(C& c, FixedKernel k) {
  if constexpr (HasKernel<C>::value) {
    c.kernel = k;
    return true;
  } else {
    (void)c;
    (void)k;
    return false;
  }
}

// ---------------------------------------------------------------- packets from the simulator

struct Packet {
  std::vector<std::uint8_t> bytes;  // kDepthPacketBytes
  std::uint64_t sequence = 0;
  std::shared_ptr<const FrameTruth> truth;
  std::size_t target = 0;  // handheld: the sweep, sorting: the burst, segmentation: the frame
  std::string material;    // handheld, sorting: the target's material
};

struct Packets {
  std::shared_ptr<const Calibration> calibration;
  std::vector<Packet> packets;
  std::size_t targets = 0;
  double render_s = 0.0;
};

const std::vector<std::string> kMaterials{"cork", "pvc", "wood", "paper"};
constexpr int kSweepFrames = 6, kBurst = 8;
constexpr double kYawDeg = 10.0;
constexpr int kTargetSize = 160;

// The scenes of a profile, frame by frame, with their target index and material.
struct Script {
  std::vector<sim::Scene> scenes;
  std::vector<std::size_t> target;
  std::vector<std::string> material;
  std::size_t targets = 0;
};

Script script_of(const std::string& profile) {
  Script s;
  if (profile == "handheld") {
    for (std::size_t m = 0; m < kMaterials.size(); ++m) {
      for (int k = 0; k < kSweepFrames; ++k) {
        s.scenes.push_back(sim::Scene::centred_target(kMaterials[m], 650.0 + 100.0 * k, kYawDeg, kTargetSize));
        s.target.push_back(m);
        s.material.push_back(kMaterials[m]);
      }
    }
    s.targets = kMaterials.size();
  } else if (profile == "sorting" || profile == "sorting-idle") {
    for (std::size_t m = 0; m < kMaterials.size(); ++m) {
      for (int k = 0; k < kBurst; ++k) {
        s.scenes.push_back(
            sim::Scene::centred_target(kMaterials[m], 700.0 + 150.0 * static_cast<double>(m), kYawDeg, kTargetSize));
        s.target.push_back(m);
        s.material.push_back(kMaterials[m]);
      }
    }
    s.targets = kMaterials.size();
  } else {  // segmentation, unpack-full, decode-full: the daemon's regions scene
    const SimSpec spec = parse_sim_spec("regions,materials=cork+pvc+wood,realtime=0");
    for (std::uint64_t k = 0; k < 3; ++k) {
      s.scenes.push_back(sim_scene_at(spec, k));
      s.target.push_back(k);
      s.material.emplace_back();
    }
    s.targets = 3;
  }
  return s;
}

Packets make_packets(const std::string& profile, const std::string& sim_data) {
  const Script script = script_of(profile);
  const auto t0 = Clock::now();
  auto renderer = std::make_shared<const sim::Renderer>(sim::load_device("kinect2_tanaka2017", sim_data),
                                                        sim::load_library("tanaka2017", sim_data), 1);
  const std::vector<sim::Scene> scenes = script.scenes;
  auto camera = std::make_shared<sim::SimulatedKinect>(
      renderer, [scenes](std::uint64_t i) { return scenes[std::min<std::size_t>(i, scenes.size() - 1)]; },
      /*realtime=*/false);
  Packets out;
  out.targets = script.targets;
  {
    kinect::DriverOptions o;
    o.status_poll_ms = 1;
    kinect::Kinect2Device device(camera->connect(), o);
    device.open();
    const std::size_t n = script.scenes.size();
    const auto& identity = device.start([&](const kinect::DepthPacket& p) {
      if (out.packets.size() >= n) return;
      const std::size_t i = out.packets.size();
      Packet k;
      k.bytes.assign(p.data, p.data + kinect::kDepthPacketBytes);
      k.sequence = p.sequence;
      k.target = script.target[i];
      k.material = script.material[i];
      // The truth as sim_source.cpp converts it.
      if (auto f = camera->truth(p.sequence); f && f->width == kWidth && f->height == kHeight) {
        auto t = std::make_shared<FrameTruth>();
        for (const auto& target : scenes[std::min<std::size_t>(p.sequence, n - 1)].targets)
          t->materials.push_back(target.material);
        t->target = f->target;
        t->depth_mm = f->depth_mm;
        k.truth = std::move(t);
      }
      out.packets.push_back(std::move(k));
    });
    out.calibration = std::make_shared<const Calibration>(identity.p0.p0_rad());
    while (out.packets.size() < n) device.pump(100);
    device.stop();
    device.close();
  }
  out.render_s = seconds_since(t0);
  return out;
}

// ---------------------------------------------------------------- the path

// What the emitter saw (kept only when asked: not in the counted passes).
struct Event {
  std::uint64_t frame = 0;
  std::string state, material;
  std::optional<std::string> truth;
  std::optional<double> accuracy;  // label maps
};

struct Run {
  std::shared_ptr<const ExemplarTable> table;
  ProfileConfig config;
  std::unique_ptr<Profile> profile;
  FixedKernel unpack_kernel = FixedKernel::kBest;
  bool with_truth = true;
  bool warm_session = false;  // --warm-session
  RawFrame frame;             // its raw buffer (9 x kPixels) is allocated once and reused
  Emitter emit;
  std::vector<Event>* events = nullptr;                    // where the emitter records, if anywhere
  std::vector<std::vector<std::uint8_t>>* maps = nullptr;  // label maps, if kept
  double encode_s = 0.0;                                   // time inside the emitter (encoding)
  bool timing = false;                                     // time the stages (all mode)
  double unpack_s = 0.0, process_s = 0.0;
  std::uint64_t bytes = 0;  // encoded event bytes

  Run(std::shared_ptr<const ExemplarTable> t, ProfileConfig c) : table(std::move(t)), config(std::move(c)) {
    if (config.method == Method::kSession && config.session_learning) {  // (as Pipeline::apply makes it)
      config.learner = SessionLearner::make(table, SessionPrior::tuned(*table), config.backend == Backend::kFixed, {},
                                            candidate_indices(*table, config.candidates));
    }
    profile = make_profile(config, table);
    frame.raw.assign(9 * kPixels, 0);
    emit.label = [this](const protocol::LabelEvent& e) {
      const auto t0 = timing ? Clock::now() : Clock::time_point{};
      const std::vector<std::uint8_t> wire = protocol::encode_label_wire(e);
      bytes += wire.size();
      g_sink = g_sink + wire.back();
      if (timing) encode_s += seconds_since(t0);
      if (events) {
        Event v{e.frame, e.state, e.material, std::nullopt, std::nullopt};
        if (e.truth) v.truth = e.truth->material;
        events->push_back(std::move(v));
      }
    };
    emit.label_map = [this](const protocol::LabelMapEvent& e) {
      const auto t0 = timing ? Clock::now() : Clock::time_point{};
      const std::vector<std::uint8_t> wire = protocol::encode(protocol::encode_label_map(e));
      bytes += wire.size();
      g_sink = g_sink + wire.back();
      if (timing) encode_s += seconds_since(t0);
      if (events) events->push_back(Event{e.frame, "map", "", std::nullopt, e.truth_accuracy});
      if (maps) maps->push_back(e.labels);
    };
    emit.wants_depth = [](const std::string&) { return false; };
    emit.depth = [](const protocol::DepthEvent&) {};
  }

  // One packet, as the daemon's source and pipeline handle it.
  void frame_of(const Packets& ps, const Packet& p) {
    const auto t0 = timing ? Clock::now() : Clock::time_point{};
    const std::optional<PixelRegion> wanted = profile->input_region();
    if (wanted && wanted->x0 < wanted->x1 && wanted->y0 < wanted->y1) {
      kinect::unpack_depth_packet_region(p.bytes.data(), frame.raw.data(), *wanted, unpack_kernel);
      frame.region = *wanted;
    } else {
      frame.region = PixelRegion{0, 0, 0, 0};
    }
    frame.sequence = p.sequence;
    frame.arrival_ns = p.sequence * 33'333'333ull;
    frame.calibration = ps.calibration;
    frame.truth = with_truth ? p.truth : nullptr;
    frame.simulated = true;
    const auto t1 = timing ? Clock::now() : Clock::time_point{};
    profile->process(frame, emit);
    if (timing) {
      unpack_s += std::chrono::duration<double>(t1 - t0).count();
      process_s += seconds_since(t1);
    }
  }

  // One pass over the packets (sorting: a trigger before each burst).
  void pass(const Packets& ps, const std::string& name) {
    profile->reset();
    if (config.learner && !warm_session) config.learner->reset();  // (a new session each pass)
    std::size_t last_target = ps.packets.size() + 1;
    for (const Packet& p : ps.packets) {
      if (name == "sorting" && p.target != last_target) profile->trigger(kBurst);
      last_target = p.target;
      frame_of(ps, p);
    }
  }
};

// The unpack-full / decode-full steps (segmentation's first steps alone).
struct Steps {
  std::vector<std::int16_t> raw = std::vector<std::int16_t>(9 * kPixels);
  FixedDecodedFrame decoded;
  void pass(const Packets& ps, bool decode, FixedKernel k) {
    for (const Packet& p : ps.packets) {
      kinect::unpack_depth_packet_region(p.bytes.data(), raw.data(), PixelRegion{0, 0, kWidth, kHeight}, k);
      if (decode) {
        decode_frame_fixed(raw.data(), ps.calibration->fixed_tables, decoded);
        g_sink = g_sink + static_cast<std::uint64_t>(decoded.combined_q8[kPixels / 2]);
      } else {
        g_sink = g_sink + static_cast<std::uint64_t>(raw[kPixels / 2]);
      }
    }
  }
};

// The segmentation profile's smoothing alone, with the classes it runs
// (frame_smoothing.hpp) on one band, the whole frame: the features' box mean,
// and the label map's majority filter, on the decoded frames and smooth = 1
// label maps of the packets, made beforehand.
struct Smoothing {
  int side = 9;
  int classes = 1;
  std::vector<FixedDecodedFrame> decoded;
  std::vector<std::vector<std::uint8_t>> maps;
  std::vector<std::int32_t> q0 = std::vector<std::int32_t>(kPixels), q1 = std::vector<std::int32_t>(kPixels);
  std::vector<std::uint8_t> cleaned = std::vector<std::uint8_t>(kPixels);

  void box_pass() {
    tofmat::BoxMeanFilter box(kWidth, kHeight, side);
    for (const FixedDecodedFrame& fr : decoded) {
      box.apply(fr.features_q16[0].data(), fr.features_q16[1].data(), fr.flags.data(), 0, kHeight, q0.data(),
                q1.data());
      g_sink = g_sink + static_cast<std::uint64_t>(q0[kPixels / 2]);
    }
  }
  void majority_pass() {
    tofmat::MajorityFilter majority(kWidth, kHeight, side, classes);
    for (const std::vector<std::uint8_t>& m : maps) {
      majority.apply(m.data(), 0, kHeight, cleaned.data());
      g_sink = g_sink + cleaned[kPixels / 2];
    }
  }
};

ProfileConfig config_of(const Options& o, const std::string& profile, Backend backend, bool& kernel_applied) {
  ProfileConfig c;
  c.name = profile == "sorting-idle" ? "sorting" : profile;
  c.backend = backend;
  c.candidates = o.candidates;
  if (!o.classifier.empty()) c.method = parse_method(o.classifier);
  if (o.smooth > 0) c.smooth = o.smooth;
  c.region_vote = o.region_vote;
  c.accumulate = o.accumulate;
  c.threads = o.threads;
  c.session_learning = o.session_learning && c.name != "segmentation";
  kernel_applied = set_profile_kernel(c, fixed_kernel(o.kernel));
  return c;
}

Smoothing smoothing_of(const Options& o, const Packets& ps, const std::shared_ptr<const ExemplarTable>& table) {
  Smoothing sm;
  bool applied = false;
  ProfileConfig c = config_of(o, "segmentation", Backend::kFixed, applied);
  sm.side = c.smooth > 1 ? c.smooth : 9;
  sm.classes = static_cast<int>(c.candidates.empty() ? table->materials().size() : c.candidates.size());
  c.smooth = 1;
  Run run(table, c);
  run.with_truth = false;
  run.maps = &sm.maps;
  run.pass(ps, "segmentation");
  run.maps = nullptr;
  Steps st;
  for (const Packet& p : ps.packets) {
    kinect::unpack_depth_packet(p.bytes.data(), st.raw.data());
    sm.decoded.push_back(decode_frame_fixed(st.raw.data(), ps.calibration->fixed_tables));
  }
  return sm;
}

// ---------------------------------------------------------------- one profile (instruction counting)

int run_single(const Options& o) {
  const long reps = o.reps < 0 ? 1 : o.reps;
  const Packets ps = make_packets(o.profile, o.sim_data);
  const FixedKernel k = fixed_kernel(o.kernel);
  const std::size_t units = ps.packets.size();
  std::string process_kernel = "best";
  if (o.profile == "smooth-box" || o.profile == "smooth-majority") {
    Smoothing sm = smoothing_of(o, ps, load_table_file(o.table));
    const bool box = o.profile == "smooth-box";
    box ? sm.box_pass() : sm.majority_pass();  // warm-up
    for (long r = 0; r < reps; ++r) box ? sm.box_pass() : sm.majority_pass();
    process_kernel = "frame_smoothing";
  } else if (o.profile == "unpack-full" || o.profile == "decode-full") {
    Steps s;
    const bool decode = o.profile == "decode-full";
    s.pass(ps, decode, k);  // warm-up
    for (long r = 0; r < reps; ++r) s.pass(ps, decode, k);
    process_kernel = decode ? "best (decode_frame_fixed default)" : "-";
  } else {
    bool applied = false;
    const ProfileConfig c = config_of(o, o.profile, Backend::kFixed, applied);
    if (applied) process_kernel = o.kernel;
    Run run(load_table_file(o.table), c);
    run.unpack_kernel = k;
    run.with_truth = o.truth;
    run.warm_session = o.warm_session;
    run.pass(ps, o.profile);  // warm-up
    for (long r = 0; r < reps; ++r) run.pass(ps, o.profile);
    g_sink = g_sink + run.bytes;
  }
  std::printf("profile %s kernel %s (unpack %s = %s, process %s; best pixel kernel = %s) truth %s reps %ld units %zu\n",
              o.profile.c_str(), o.kernel.c_str(), o.kernel.c_str(),
              k == FixedKernel::kScalar ? "scalar" : kinect::best_unpack_kernel(), process_kernel.c_str(),
              best_pixel_kernel(), o.truth ? "yes" : "no", reps, units);
  return 0;
}

// ---------------------------------------------------------------- everything (timings on this host)

struct Timed {
  std::vector<double> total, unpack, process, encode;  // per frame, seconds, one entry per pass
  static double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v.empty() ? 0.0 : v[v.size() / 2];
  }
  static double best(const std::vector<double>& v) { return v.empty() ? 0.0 : *std::min_element(v.begin(), v.end()); }
};

Timed time_passes(Run& run, const Packets& ps, const std::string& name, long reps) {
  Timed t;
  run.timing = true;
  run.pass(ps, name);  // warm-up
  const double n = static_cast<double>(ps.packets.size());
  for (long r = 0; r < reps; ++r) {
    run.unpack_s = run.process_s = run.encode_s = 0.0;
    const auto t0 = Clock::now();
    run.pass(ps, name);
    t.total.push_back(seconds_since(t0) / n);
    t.unpack.push_back(run.unpack_s / n);
    t.process.push_back((run.process_s - run.encode_s) / n);
    t.encode.push_back(run.encode_s / n);
  }
  run.timing = false;
  return t;
}

// One pass recording the events.
std::vector<Event> events_of(Run& run, const Packets& ps, const std::string& name) {
  std::vector<Event> ev;
  run.events = &ev;
  run.pass(ps, name);
  run.events = nullptr;
  return ev;
}

// The label of each target: the last label event on a frame of that target
// ("" when none, or no_target).
std::vector<std::string> final_labels(const std::vector<Event>& ev, const Packets& ps) {
  std::vector<std::string> out(ps.targets);
  for (const Event& e : ev) {
    for (const Packet& p : ps.packets) {
      if (p.sequence == e.frame) out[p.target] = e.state == "no_target" ? "" : e.material;
    }
  }
  return out;
}

std::string fraction(std::size_t a, std::size_t b) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%zu / %zu", a, b);
  return buf;
}

int run_all(const Options& o) {
  const long reps = o.reps < 0 ? 7 : std::max(1L, o.reps);
  const auto table = load_table_file(o.table);
  std::printf(
      "tofmat_bench_profiles: best pixel kernel = %s, unpack kernel = %s; table %s (%zu materials, all "
      "candidates unless --candidates); one thread; host ms per frame = median of %ld passes over the "
      "prepared packets (after a warm-up pass), best = fastest pass\n\n",
      best_pixel_kernel(), kinect::best_unpack_kernel(), o.table.c_str(), table->n_materials(), reps);
  std::printf(
      "| profile | frames / pass | ms per frame (median) | best | unpack | process | encode | error vs truth | "
      "agrees with float | float backend ms per frame |\n");
  std::printf("|---|---:|---:|---:|---:|---:|---:|---|---|---:|\n");
  const auto row = [&](const std::string& name, const Packets& ps, const Timed& t, const std::string& truth_err,
                       const std::string& vs_float, const std::string& float_ms) {
    std::printf("| %s | %zu | %.3f | %.3f | %.4f | %.3f | %.4f | %s | %s | %s |\n", name.c_str(), ps.packets.size(),
                Timed::median(t.total) * 1e3, Timed::best(t.total) * 1e3, Timed::median(t.unpack) * 1e3,
                Timed::median(t.process) * 1e3, Timed::median(t.encode) * 1e3, truth_err.c_str(), vs_float.c_str(),
                float_ms.c_str());
    std::fflush(stdout);
  };
  bool applied = false;
  std::vector<std::string> notes;

  for (const std::string name : {"handheld", "sorting"}) {
    const Packets ps = make_packets(name, o.sim_data);
    notes.push_back(name + ": " + std::to_string(ps.packets.size()) + " packets rendered in " +
                    std::to_string(static_cast<int>(ps.render_s * 1e3)) + " ms");
    Run fixed(table, config_of(o, name, Backend::kFixed, applied));
    Run fl(table, config_of(o, name, Backend::kFloat, applied));
    fixed.with_truth = fl.with_truth = o.truth;
    const std::vector<Event> ef = events_of(fixed, ps, name), el = events_of(fl, ps, name);
    const std::vector<std::string> lf = final_labels(ef, ps), ll = final_labels(el, ps);
    std::size_t right = 0, agree_final = 0;
    for (std::size_t t = 0; t < ps.targets; ++t) {
      std::string want;
      for (const Packet& p : ps.packets)
        if (p.target == t) want = p.material;
      right += lf[t] == want;
      agree_final += lf[t] == ll[t];
    }
    // Every label event (handheld: one per frame) against the float one of the same frame.
    std::size_t agree = 0, compared = 0;
    for (const Event& a : ef) {
      for (const Event& b : el) {
        if (b.frame == a.frame && b.state == a.state) {
          ++compared;
          agree += a.material == b.material;
        }
      }
    }
    {
      std::string said = name + " labels (target: fixed / float):";
      for (std::size_t t = 0; t < ps.targets; ++t) {
        said +=
            " " + kMaterials[t] + ": " + (lf[t].empty() ? "-" : lf[t]) + " / " + (ll[t].empty() ? "-" : ll[t]) + ";";
      }
      notes.push_back(said);
    }
    const Timed tf = time_passes(fixed, ps, name, reps);
    const Timed tl = time_passes(fl, ps, name, reps);
    char fms[32];
    std::snprintf(fms, sizeof fms, "%.3f", Timed::median(tl.total) * 1e3);
    const std::string unit = name == "handheld" ? "final label per target" : "burst labels";
    row(name, ps, tf, fraction(right, ps.targets) + " " + unit + " right",
        fraction(agree_final, ps.targets) + " final; " + fraction(agree, compared) + " label events", fms);
    if (name == "handheld") {
      // The ROI's unpack when the packet is in the cache (the same packet
      // every time) against the passes above, which cycle through packets
      // of 3 MB each (cold, as a new frame is).
      const PixelRegion roi = fixed.config.roi;
      std::vector<double> t;
      for (int r = 0; r < 200; ++r) {
        const auto t0 = Clock::now();
        kinect::unpack_depth_packet_region(ps.packets[0].bytes.data(), fixed.frame.raw.data(), roi);
        t.push_back(seconds_since(t0));
      }
      char buf[160];
      std::snprintf(buf, sizeof buf, "ROI unpack of one packet again and again (in the cache): %.4f ms (median of 200)",
                    Timed::median(t) * 1e3);
      notes.push_back(buf);
    }
    if (name == "sorting") {
      Run idle(table, config_of(o, "sorting-idle", Backend::kFixed, applied));
      idle.with_truth = o.truth;
      row("sorting-idle (between bursts)", ps, time_passes(idle, ps, "sorting-idle", reps), "-", "-", "-");
    }
  }

  // Segmentation, and its steps.
  const Packets ps = make_packets("segmentation", o.sim_data);
  notes.push_back("segmentation: " + std::to_string(ps.packets.size()) + " packets rendered in " +
                  std::to_string(static_cast<int>(ps.render_s * 1e3)) + " ms");
  Run seg(table, config_of(o, "segmentation", Backend::kFixed, applied));
  seg.with_truth = true;
  const std::vector<Event> ev = events_of(seg, ps, "segmentation");
  double acc = 0.0;
  for (const Event& e : ev) acc += e.accuracy.value_or(0.0);
  char err[96];
  std::snprintf(err, sizeof err, "%.1f %% of target pixels right (mean of %zu frames)",
                100.0 * acc / static_cast<double>(std::max<std::size_t>(1, ev.size())), ev.size());
  seg.with_truth = o.truth;
  const Timed ts = time_passes(seg, ps, "segmentation", reps);
  row("segmentation (smooth " + std::to_string(seg.config.smooth) + ")", ps, ts, err, "- (no float backend)", "-");

  std::printf(
      "\n### Segmentation, step by step (ms per frame, median of %ld passes; each row is the whole of what it "
      "names)\n\n| step | ms per frame | best |\n|---|---:|---:|\n",
      reps);
  const auto step = [&](const std::string& what, auto&& f) {
    f();  // warm-up
    std::vector<double> t;
    for (long r = 0; r < reps; ++r) {
      const auto t0 = Clock::now();
      f();
      t.push_back(seconds_since(t0) / static_cast<double>(ps.packets.size()));
    }
    std::printf("| %s | %.3f | %.3f |\n", what.c_str(), Timed::median(t) * 1e3, Timed::best(t) * 1e3);
    std::fflush(stdout);
  };
  Steps s;
  step("unpack of the whole packet", [&] { s.pass(ps, false, FixedKernel::kBest); });
  step("unpack + decode_frame_fixed (reused buffers)", [&] { s.pass(ps, true, FixedKernel::kBest); });
  for (const int smooth : {1, seg.config.smooth}) {
    for (const bool truth : {false, true}) {
      Options so = o;
      so.smooth = smooth;
      Run r(table, config_of(so, "segmentation", Backend::kFixed, applied));
      r.with_truth = truth;
      step("unpack + process (smooth " + std::to_string(smooth) + (smooth == 1 ? ": no box mean, no majority" : "") +
               (truth ? ", with truth: accuracy()" : ", no truth") + ") + encode",
           [&] { r.pass(ps, "segmentation"); });
    }
  }
  {
    // The full frame from the packet to the labels without smoothing, as
    // "unpack + process (smooth 1 ...)" but without the daemon's event: once
    // whole-frame stage by stage (the unpack writes every sample, the decode
    // reads them back), once band by band (8 rows unpacked, decoded and
    // classified while their samples are still in the cache).
    const PixelClassifier pc(CompactTable(*table, {}), table->bins());
    const FixedThresholds th = fixed_thresholds(DecodeOptions{});
    std::vector<std::int16_t> raw(9 * kPixels);
    std::vector<std::uint8_t> labels(kPixels);
    FixedDecodedFrame fr;
    size_fixed_frame(fr, kPixels);
    step("unpack, decode, classify (no smoothing, no event): stage by stage over the whole frame", [&] {
      for (const Packet& p : ps.packets) {
        kinect::unpack_depth_packet_region(p.bytes.data(), raw.data(), PixelRegion{0, 0, kWidth, kHeight});
        decode_pixels_fixed(raw.data(), ps.calibration->fixed_tables, 0, kPixels, th, planes_of(fr, 0));
        pc.classify(fr, labels.data());
        g_sink = g_sink + labels[kPixels / 2];
      }
    });
    step("unpack, decode, classify (no smoothing, no event): band by band, 8 rows", [&] {
      for (const Packet& p : ps.packets) {
        for (int y = 0; y < kHeight; y += 8) {
          const int y1 = std::min(y + 8, kHeight);
          const std::size_t at = static_cast<std::size_t>(y) * kWidth, n = static_cast<std::size_t>(y1 - y) * kWidth;
          kinect::unpack_depth_packet_region(p.bytes.data(), raw.data(), PixelRegion{0, y, kWidth, y1});
          const FixedPlanes band = planes_of(fr, at);
          decode_pixels_fixed(raw.data(), ps.calibration->fixed_tables, at, n, th, band);
          pc.classify_range(band.combined, band.flags, band.features[0], band.features[1], n, labels.data() + at);
        }
        g_sink = g_sink + labels[kPixels / 2];
      }
    });
  }
  Smoothing sm = smoothing_of(o, ps, table);
  step("smoothing alone: box mean " + std::to_string(sm.side) + "x" + std::to_string(sm.side) +
           " of the two features (integers)",
       [&] { sm.box_pass(); });
  step("smoothing alone: majority " + std::to_string(sm.side) + "x" + std::to_string(sm.side) + " of the label map",
       [&] { sm.majority_pass(); });
  {
    // The frame split over two threads against one, side by side in this run
    // (wall time; this machine's cores may be shared with other work).
    for (const int threads : {1, 2}) {
      Options so = o;
      so.threads = threads;
      Run r(table, config_of(so, "segmentation", Backend::kFixed, applied));
      r.with_truth = false;
      step("unpack + process (smooth " + std::to_string(r.config.smooth) + ", no truth) + encode, " +
               std::to_string(threads) + (threads == 1 ? " thread" : " threads (wall time)"),
           [&] { r.pass(ps, "segmentation"); });
    }
  }
  std::printf("\n");
  for (const auto& n : notes) std::printf("- %s\n", n.c_str());
  std::printf("- the profiles run FixedKernel::kBest internally%s\n",
              applied ? " (ProfileConfig::kernel set from --kernel)" : " (ProfileConfig has no kernel member)");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  const Options o = parse(argc, argv);
  try {
    return o.profile == "all" ? run_all(o) : run_single(o);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tofmat_bench_profiles: %s\n", e.what());
    return 1;
  }
}
