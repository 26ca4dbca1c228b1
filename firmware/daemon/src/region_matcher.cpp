// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// RegionMatcher: decode, depth-bin accumulation and classification (Eq. (12) or the session matcher) of a pixel
// region on the fixed-point or float path.
#include "tofmat/daemon/region_matcher.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

namespace tofmat::daemon {
namespace {

// The upper median (no average of two: a depth that was measured).
template <typename T>
T median_of(std::vector<T>& v) {
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

constexpr std::int32_t kSurfaceBandQ8 = kSurfaceBandMm * 256;

}  // namespace

RegionMatcher::RegionMatcher(std::shared_ptr<const ExemplarTable> table, std::vector<std::uint32_t> candidates,
                             Backend backend, Method method, bool open_set, const LearnedModel& model,
                             std::shared_ptr<SessionLearner> learner)
    : table_(std::move(table)),
      backend_(backend),
      // A learned model's confidence is its probabilities under the
      // temperatures its metadata holds (1 without them: the model's own);
      // it has no noise model, so nothing is unknown.
      calibration_(method == Method::kOnnx ? tofmat::Calibration{{{1.0, 1.0}}, {}}
                                           : tofmat::Calibration::tuned(method_name(method), *table_)),
      fixed_acc_(table_->bins(), table_->n_rows()),
      float_acc_(table_->bins(), table_->n_rows()) {
  if (!open_set) calibration_.unknown_fits.clear();  // never unknown
  if (method == Method::kOnnx) {
    onnx_ = std::make_shared<const learn::OnnxClassifier>(table_, model.path, std::move(candidates), model.library);
    if (!onnx_->contract().temperatures.empty()) calibration_.temperatures = onnx_->contract().temperatures;
  } else if (method == Method::kSession && learner)
    learner_ = std::move(learner);  // (its scorers are the session classifiers, at each scale)
  else if (method == Method::kSession && backend_ == Backend::kFixed)
    fixed_session_ = std::make_shared<const FixedSessionClassifier>(table_, SessionPrior::tuned(*table_),
                                                                    std::vector<double>{}, std::move(candidates));
  else if (method == Method::kSession)
    session_ = std::make_shared<const SessionClassifier>(table_, SessionPrior::tuned(*table_), std::vector<double>{},
                                                         std::move(candidates));
  else if (backend_ == Backend::kFixed)
    fixed_ = std::make_shared<const FixedClassifier>(table_, std::move(candidates));
  else
    float_ = std::make_shared<const FloatClassifier>(table_, std::move(candidates));
  if (session_)
    vagueness_ = session_->vagueness();
  else if (fixed_session_)
    vagueness_ = fixed_session_->reference().vagueness();
  else if (learner_)  // (its scorers share the tuned prior's noise model: scaling moves only offsets and drift)
    vagueness_ = SessionClassifier(table_, SessionPrior::tuned(*table_)).vagueness();
}

RegionMatcher RegionMatcher::twin() const {
  RegionMatcher t(*this);  // (the classifiers' pointers are shared; they never change)
  t.reset();
  return t;
}

RegionMatcher::Decoded RegionMatcher::decode(const RawFrame& frame, const PixelRegion& region) const {
  Decoded d;
  decode(frame, region, d);
  return d;
}

void RegionMatcher::decode(const RawFrame& frame, const PixelRegion& region, Decoded& d) const {
  d.region = region;
  d.median_mm = std::numeric_limits<double>::quiet_NaN();
  if (backend_ == Backend::kFixed) {
    if (!std::holds_alternative<FixedDecodedFrame>(d.frame)) d.frame = FixedDecodedFrame{};
    auto& f = std::get<FixedDecodedFrame>(d.frame);
    decode_region_fixed(frame.raw.data(), kWidth, kHeight, frame.calibration->fixed_tables, region, f);
    d.pixels = f.pixels;
    // The median in Q8 mm, converted once (exact: the order of the integers is that of the depths).
    std::vector<std::int32_t>& depths = d.depths_q8;
    depths.resize(f.pixels);
    std::size_t n = 0;
    for (std::size_t i = 0; i < f.pixels; ++i) {
      depths[n] = f.combined_q8[i];
      n += f.flags[i] == 0;
    }
    depths.resize(n);
    d.valid = n;
    if (n > 0) d.median_mm = median_of(depths) / 256.0;
  } else {
    auto f = decode_region(frame.raw.data(), kWidth, kHeight, frame.calibration->float_tables, region);
    d.pixels = f.pixels;
    std::vector<double> depths;
    depths.reserve(f.pixels);
    for (std::size_t i = 0; i < f.pixels; ++i)
      if (f.flags[i] == 0) depths.push_back(f.combined_mm[i]);
    d.valid = depths.size();
    if (!depths.empty()) d.median_mm = median_of(depths);
    d.frame = std::move(f);
  }
}

void RegionMatcher::accumulate(const Decoded& d) {
  // One observation a frame: the surface's mean features at its mean depth,
  // as the tables are recorded (FixedSurfaceMean says why not pixel by pixel).
  if (!std::isfinite(d.median_mm)) return;
  if (backend_ == Backend::kFixed) {
    const auto centre = static_cast<std::int32_t>(std::lround(d.median_mm * 256.0));
    fixed_acc_.add_surface(surface_mean(std::get<FixedDecodedFrame>(d.frame), centre, kSurfaceBandQ8));
    return;
  }
  const SurfaceMean s = surface_mean(std::get<DecodedFrame>(d.frame), d.median_mm, kSurfaceBandQ8 / 256.0);
  float_acc_.add_sums(s.depth_mm, s.sum_mm, s.pixels);
}

std::optional<Classification> RegionMatcher::classify() const {
  const std::vector<float> q = backend_ == Backend::kFixed ? fixed_acc_.query() : float_acc_.query();
  if (std::none_of(q.begin(), q.end(), [](float v) { return std::isfinite(v); })) return std::nullopt;
  try {
    if (learner_) return learner_->classify(q.data(), q.size()).mixture;
    if (session_) return session_->classify(q.data(), q.size());
    if (fixed_session_) return fixed_session_->classify(q.data(), q.size());
    if (onnx_) return onnx_->classify(q.data(), q.size());
    return backend_ == Backend::kFixed ? fixed_->classify(q.data(), q.size()) : float_->classify(q.data(), q.size());
  } catch (const std::invalid_argument&) {
    return std::nullopt;  // no candidate shares an observed element yet
  }
}

std::uint32_t RegionMatcher::bins_covered() const {
  return backend_ == Backend::kFixed ? fixed_acc_.bins_covered() : float_acc_.bins_covered();
}

void RegionMatcher::learn_sweep() {
  if (!learner_) return;
  const std::vector<float> q = backend_ == Backend::kFixed ? fixed_acc_.query() : float_acc_.query();
  if (std::none_of(q.begin(), q.end(), [](float v) { return std::isfinite(v); })) return;
  try {
    learner_->learn(learner_->classify(q.data(), q.size(), true));
  } catch (const std::invalid_argument&) {
    // no candidate shares an observed element: nothing to learn from
  }
}

void RegionMatcher::reset() {
  fixed_acc_.reset();
  float_acc_.reset();
}

bool RegionMatcher::unknown(const Classification& c) const { return rejected(c, table_->n_rows(), calibration_); }

protocol::LabelEvent RegionMatcher::label_event(const Classification& c, int top_k) const {
  protocol::LabelEvent e;
  const Verdict v = judge(c, table_->n_rows(), calibration_, vagueness_);
  // by material: a table may hold several exemplars of one (ExemplarTable::materials())
  const std::vector<MaterialRank> ranks = rank_materials(c, v, *table_);
  e.material = v.unknown ? "" : ranks.front().material;
  e.index = v.unknown ? -1 : static_cast<std::int32_t>(c.best().index);
  e.confidence = ranks.front().probability;
  if (std::isfinite(c.best().fit)) e.fit = c.best().fit;
  e.distance = c.best().distance;
  e.valid = c.best().valid;
  e.bins_covered = bins_covered();
  const std::size_t k = std::min(ranks.size(), static_cast<std::size_t>(std::max(top_k, 1)));
  for (std::size_t i = 0; i < k; ++i) e.ranking.push_back({ranks[i].material, c.ranking[ranks[i].position].distance});
  return e;
}

namespace {

// Depth image k (0..2: a frequency's wrapped depth, 3: the combined depth) of a decoded region.
protocol::DepthEvent depth_image(const RegionMatcher::Decoded& d, const RawFrame& frame, int k, const char* kind) {
  protocol::DepthEvent e;
  e.frame = frame.sequence;
  e.timestamp_ns = frame.arrival_ns;
  e.kind = kind;
  e.x0 = d.region.x0;
  e.y0 = d.region.y0;
  e.width = d.region.x1 - d.region.x0;
  e.height = d.region.y1 - d.region.y0;
  if (frame.calibration && frame.calibration->intrinsics) {
    const kinect::DepthParams& c = *frame.calibration->intrinsics;
    e.intrinsics = protocol::Intrinsics{c.fx, c.fy, c.cx, c.cy, c.k1, c.k2, c.k3, c.p1, c.p2};
  }
  e.depth_mm.resize(d.pixels);
  if (const auto* f = std::get_if<FixedDecodedFrame>(&d.frame)) {
    for (std::size_t i = 0; i < d.pixels; ++i) {
      const std::int32_t v = k < 3 ? f->depth_q16[static_cast<std::size_t>(k)][i] : f->combined_q8[i];
      e.depth_mm[i] = v == kFixedInvalid ? std::numeric_limits<float>::quiet_NaN()
                                         : static_cast<float>(k < 3 ? v / 65536.0 : v / 256.0);
    }
  } else {
    const auto& g = std::get<DecodedFrame>(d.frame);
    e.depth_mm = k < 3 ? g.depth_mm[static_cast<std::size_t>(k)] : g.combined_mm;
  }
  return e;
}

}  // namespace

void RegionMatcher::emit_depths(const Decoded& d, const RawFrame& frame, const Emitter& emit) {
  static const char* const kinds[4] = {"80", "16", "120", "combined"};
  for (int k = 0; k < 4; ++k) {
    if (!emit.wants_depth || !emit.wants_depth(kinds[k])) continue;
    emit.depth(depth_image(d, frame, k, kinds[k]));
  }
}

void RegionMatcher::emit_corrected(const Decoded& d, const RawFrame& frame, const Emitter& emit,
                                   const ExemplarTable& table,
                                   const std::function<std::int64_t(std::size_t)>& material_of) {
  if (!emit.wants_depth || !emit.wants_depth("corrected")) return;
  protocol::DepthEvent e = depth_image(d, frame, 3, "corrected");
  for (std::size_t i = 0; i < e.depth_mm.size(); ++i) {
    const std::int64_t m = material_of(i);
    // Eq. (8): the distortion is measured minus true depth, so the true depth is measured less it.
    const double delta = m < 0 ? std::numeric_limits<double>::quiet_NaN()
                               : table.distortion_mm(static_cast<std::size_t>(m), e.depth_mm[i]);
    e.depth_mm[i] = static_cast<float>(e.depth_mm[i] - delta);  // (NaN where either is)
  }
  emit.depth(e);
}

std::optional<protocol::Truth> region_truth(const RawFrame& frame, const PixelRegion& region) {
  if (!frame.truth) return std::nullopt;
  const FrameTruth& t = *frame.truth;
  std::map<std::int16_t, std::pair<std::size_t, double>> seen;  // target -> pixels, depth sum
  std::size_t pixels = 0;
  for (int y = region.y0; y < region.y1; ++y)
    for (int x = region.x0; x < region.x1; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * kWidth + static_cast<std::size_t>(x);
      ++pixels;
      if (t.target[i] < 0 || static_cast<std::size_t>(t.target[i]) >= t.materials.size()) continue;
      auto& s = seen[t.target[i]];
      ++s.first;
      s.second += t.depth_mm[i];
    }
  protocol::Truth out;
  std::size_t best = 0;
  for (const auto& [target, s] : seen)
    if (s.first > best) {
      best = s.first;
      out.material = t.materials[static_cast<std::size_t>(target)];
      out.depth_mm = s.second / static_cast<double>(s.first);
    }
  if (best * 2 < pixels) out = protocol::Truth{};  // no target fills the region
  return out;
}

}  // namespace tofmat::daemon
