// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Decode of a pixel region, depth-bin accumulation of its Eq. (10) features
// and partial matching (Eq. (12), or the session-robust matcher), on the
// fixed-point path (the default) or the float reference: what the handheld
// and sorting profiles share.
#pragma once
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <variant>
#include <vector>

#include "tofmat/core/classifier.hpp"
#include "tofmat/core/confidence.hpp"
#include "tofmat/core/depth_bins.hpp"
#include "tofmat/core/fixed_classifier.hpp"
#include "tofmat/core/fixed_decode.hpp"
#include "tofmat/core/fixed_depth_bins.hpp"
#include "tofmat/core/fixed_session_classifier.hpp"
#include "tofmat/core/session_classifier.hpp"
#include "tofmat/core/session_learner.hpp"
#include "tofmat/daemon/profile.hpp"

namespace tofmat::daemon {

class RegionMatcher {
 public:
  // open_set: label a query no candidate explains "unknown" (the session matcher only).
  // model: Method::kOnnx's (loaded and checked against the table here: throws
  // std::runtime_error or std::invalid_argument saying why it cannot run).
  // learner: Method::kSession's learner of the session (null: the session
  // matcher alone); its scorers must be this table's, candidates and backend.
  RegionMatcher(std::shared_ptr<const ExemplarTable> table, std::vector<std::uint32_t> candidates, Backend backend,
                Method method = Method::kEq12, bool open_set = false, const LearnedModel& model = {},
                std::shared_ptr<SessionLearner> learner = nullptr);

  // A matcher of the same table, candidates and method with an accumulation
  // of its own, sharing this one's classifier (a learned model is loaded once).
  RegionMatcher twin() const;

  struct Decoded {
    std::variant<DecodedFrame, FixedDecodedFrame> frame;
    PixelRegion region;
    std::size_t pixels = 0, valid = 0;
    double median_mm = 0.0;               // combined depth of the valid pixels (NaN if none)
    std::vector<std::int32_t> depths_q8;  // (the median's work, kept with the frame's buffers)
  };
  Decoded decode(const RawFrame& frame, const PixelRegion& region) const;
  // The same into `into`, reusing its buffers on the fixed-point backend (a
  // profile that decodes its ROI every frame and keeps no frame past it).
  void decode(const RawFrame& frame, const PixelRegion& region, Decoded& into) const;
  // Adds the region's surface (its valid pixels near the median depth) as one
  // observation at its mean depth (FixedSurfaceMean says why not pixel by pixel).
  void accumulate(const Decoded& d);
  // The method's match of the query so far; nothing while no bin holds an observation.
  std::optional<Classification> classify() const;
  std::uint32_t bins_covered() const;
  void reset();
  // The sweep so far is finished: the session's learner (if any) learns from
  // its whole query. Call before reset() when a target leaves or a burst ends.
  void learn_sweep();
  // The label event of a classification (ranking cut to top_k), with its
  // calibrated confidence and fit (confidence.hpp); when no candidate explains
  // the query (unknown) its material is "" and index -1, the ranking kept.
  protocol::LabelEvent label_event(const Classification& c, int top_k) const;
  // Whether the open set rejects the classification (the session matcher only).
  bool unknown(const Classification& c) const;
  // Depth images of a decoded region for the subscribers that want them.
  static void emit_depths(const Decoded& d, const RawFrame& frame, const Emitter& emit);
  // The corrected depth image (kind "corrected") of a decoded region for its
  // subscribers: the combined depth less the distortion of the material
  // `material_of(pixel)` gives (a table index, -1: none) for each pixel of the
  // region (row-major), from the table's depth distortion (Eq. (8)); NaN where
  // a pixel has no depth, no label, or its material no distortion there.
  static void emit_corrected(const Decoded& d, const RawFrame& frame, const Emitter& emit, const ExemplarTable& table,
                             const std::function<std::int64_t(std::size_t)>& material_of);

 private:
  std::shared_ptr<const ExemplarTable> table_;
  Backend backend_;
  tofmat::Calibration calibration_;  // (the confidence's, not the camera's)
  std::vector<double> vagueness_;    // the session matcher's candidate_vagueness() (empty: none)
  // The method's classifier (one of them; immutable, so a twin shares it).
  std::shared_ptr<const FixedClassifier> fixed_;
  std::shared_ptr<const FloatClassifier> float_;
  std::shared_ptr<const SessionClassifier> session_;             // Method::kSession, the float backend
  std::shared_ptr<const FixedSessionClassifier> fixed_session_;  // Method::kSession, the fixed-point backend
  std::shared_ptr<const learn::OnnxClassifier> onnx_;            // Method::kOnnx, either backend's query
  std::shared_ptr<SessionLearner> learner_;  // Method::kSession learning its session: shared by the session's matchers
  FixedDepthBinAccumulator fixed_acc_;
  DepthBinAccumulator float_acc_;
};

// Ground truth of a region for a simulated frame: the material most of the
// region's target pixels show and their mean true depth (nothing if no truth).
std::optional<protocol::Truth> region_truth(const RawFrame& frame, const PixelRegion& region);

}  // namespace tofmat::daemon
