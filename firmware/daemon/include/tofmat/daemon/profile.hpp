// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Scene profiles (DESIGN.md section 5): what the daemon computes for a scene,
// and nothing else. A profile decodes only its pixels, holds only its
// candidate materials (the compact table's subset at load) and emits events.
//   handheld      ROI at the centre, depth-bin accumulation, partial matching
//                 every frame, reset when the target leaves or jumps
//   segmentation  the full frame, one position (m = 1), per-pixel labels of
//                 a short candidate list, smoothed and cleaned in integers,
//                 the frame split over `threads`
//   sorting       nothing until a trigger; then a burst of frames over the
//                 belt ROI, accumulated and classified once
#pragma once
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "tofmat/core/exemplar_table.hpp"
#include "tofmat/core/frame_decode.hpp"
#include "tofmat/core/session_learner.hpp"
#include "tofmat/daemon/frame.hpp"
#include "tofmat/learn/onnx_classifier.hpp"
#include "tofmat/protocol/messages.hpp"

namespace tofmat::daemon {

enum class Backend { kFixed, kFloat };
Backend parse_backend(const std::string& name);  // "fixed" | "float"; throws std::invalid_argument

// How the handheld and sorting profiles match a region's query: Eq. (12), the
// session-robust matcher (docs/evaluation.md): FixedSessionClassifier on the
// fixed-point backend, SessionClassifier (double) on the float one; or a
// learned model through onnxruntime (docs/learned-models.md). The
// segmentation profile's per-pixel labels are Eq. (12) whatever this says.
enum class Method { kEq12, kSession, kOnnx };
// "eq12" | "session" | "onnx:FILE" (the file is not checked here); throws
// std::invalid_argument.
Method parse_method(const std::string& name);
const char* method_name(Method method);  // "eq12" | "session" | "onnx"

// Method::kOnnx's model and the onnxruntime library that runs it.
struct LearnedModel {
  std::string path;  // the .onnx file (tofmat train)
  std::string library = learn::kDefaultOnnxruntimeLibrary;
};

struct ProfileConfig {
  std::string name = "handheld";
  Backend backend = Backend::kFixed;
  // The session-robust matcher by default, as the SDK's Classifier: it beats
  // Eq. (12) on sweeps of a new session (docs/evaluation.md), and with its
  // NEON kernel a handheld frame keeps within its budget of 1 M aarch64
  // instructions (docs/benchmarks.md).
  Method method = Method::kSession;
  // Open-set rejection (the session matcher's "unknown", docs/evaluation.md):
  // off unless asked for, since its thresholds come from the real curves'
  // session model, which has no target angle: a table recorded at another
  // angle than the sweeps is called unknown.
  bool open_set = false;
  // The session matcher learns how far this session moved from the sweeps
  // it labels (session_learner.hpp, docs/evaluation.md): how far a box's
  // sessions move is not known, and a matcher that assumes the calibration's
  // spread loses to Eq. (12) where they barely move. On by default
  // (--no-session-learning: every sweep on its own); Method::kSession only.
  bool session_learning = true;
  // Not a setting: the session's learner the Pipeline keeps across profile
  // changes (null: the session matcher alone). Method::kSession only.
  std::shared_ptr<SessionLearner> learner;
  LearnedModel model;                   // Method::kOnnx only
  PixelRegion roi{232, 188, 280, 236};  // 48 x 48 at the centre
  std::vector<std::string> candidates;  // empty: every material of the table
  int top_k = 5;                        // ranking entries in a label event
  int burst = 8;                        // sorting: frames per trigger
  double min_valid_fraction = 0.5;      // handheld/sorting: a target fills the ROI
  double jump_mm = 150.0;               // handheld: a depth jump between frames is a new target
  int smooth = 9;                       // segmentation: window side of the features' mean and the labels' majority
  bool region_vote = true;              // segmentation: each depth-continuous surface takes its majority label
  int accumulate = 1;                   // segmentation: frames each pixel's features are averaged over (1: none)
  int threads = 0;                      // segmentation: threads sharing each frame (0: every core)
};

// Throws std::invalid_argument naming what is wrong (unknown profile,
// ROI outside the frame, candidate not in the table).
void validate(const ProfileConfig& config, const ExemplarTable& table);

struct Emitter {
  std::function<void(const protocol::LabelEvent&)> label;
  std::function<void(const protocol::LabelMapEvent&)> label_map;
  std::function<bool(const std::string& kind)> wants_depth;
  std::function<void(const protocol::DepthEvent&)> depth;
};

// What the handheld and sorting profiles' region shows (status's `target`):
// whether a target fills it and whether its depth lies where the table can
// label it. A table whose bins miss the target's depth gives no label; this
// says so, and why.
struct TargetView {
  std::string state = "none";  // "none" (nothing fills the region), "in_range", "out_of_range"
  double depth_mm = 0.0;       // the region's median depth (in_range, out_of_range)
  std::string reason;          // out_of_range: why no label comes
};
// What a region of `pixels` with `valid` decoded ones at median depth
// `median_mm` shows: a target fills it when at least min_valid_fraction of
// its pixels decode, and is in the table's range when its median lies within
// the bins or 50 mm beyond either end (a partial sweep that still reaches
// them); out of range, the reason names the depth and the table's range.
TargetView view_target(std::size_t valid, std::size_t pixels, double median_mm, double min_valid_fraction,
                       const BinSpec& bins);

class Profile {
 public:
  virtual ~Profile() = default;
  // The pixels the next process() reads (its raw samples must be unpacked
  // there); nothing when the next frame is not needed at all (sorting
  // between bursts). Called on the processing thread, like process().
  virtual std::optional<PixelRegion> input_region() const = 0;
  virtual void process(const RawFrame& frame, const Emitter& emit) = 0;
  virtual void reset() = 0;
  // What the region shows (handheld, sorting); nothing for segmentation.
  virtual std::optional<TargetView> target() const { return std::nullopt; }
  // sorting: arm a burst of `burst` frames; returns the trigger's number.
  // Other profiles throw std::logic_error.
  virtual std::uint64_t trigger(int burst);
};

// Throws std::invalid_argument (as validate()).
std::unique_ptr<Profile> make_profile(const ProfileConfig& config, std::shared_ptr<const ExemplarTable> table);

// Candidate names -> table indices (empty -> empty: all). Throws std::invalid_argument.
std::vector<std::uint32_t> candidate_indices(const ExemplarTable& table, const std::vector<std::string>& names);

}  // namespace tofmat::daemon
