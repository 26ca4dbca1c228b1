// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Classifier for Python: Eq. (12) nearest neighbour (float or fixed point) or the
// session-robust matcher (float) over an exemplar table, single queries and batches,
// with the GIL released.
#include <pybind11/stl.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <optional>

#include "bindings.hpp"
#include "tofmat/core/classifier.hpp"
#include "tofmat/core/compact_table.hpp"
#include "tofmat/core/confidence.hpp"
#include "tofmat/core/fixed_classifier.hpp"
#include "tofmat/core/fixed_session_classifier.hpp"
#include "tofmat/core/session_classifier.hpp"
#include "tofmat/core/session_learner.hpp"

namespace tofmat::py {

namespace {

// What Python sees: names resolved, best match flattened onto the result.
struct RankedMatch {
  std::string material;
  std::uint32_t index;
  double distance;
  std::uint32_t valid;
  double fit;
  double probability;
};

struct Result {
  std::vector<RankedMatch> ranking;
  bool unknown = false;
};

Result to_result(const ExemplarTable& table, const Classification& c, const Calibration& calibration,
                 const std::vector<double>& vagueness) {
  const Verdict v = judge(c, table.n_rows(), calibration, vagueness);
  Result r;
  r.unknown = v.unknown;
  // by material: a table may hold several exemplars of one, each material ranked by its best
  const std::vector<MaterialRank> ranks = rank_materials(c, v, table);
  r.ranking.reserve(ranks.size());
  for (const MaterialRank& k : ranks) {
    const Match& m = c.ranking[k.position];
    r.ranking.push_back({k.material, m.index, m.distance, m.valid, m.fit, k.probability});
  }
  return r;
}

std::string match_repr(const RankedMatch& m) {
  return "material='" + m.material + "', index=" + std::to_string(m.index) +
         ", distance=" + std::to_string(m.distance) + ", valid=" + std::to_string(m.valid);
}

// The Python Classifier: backend selection and candidate names over the core classifiers.
class Classifier {
 public:
  Classifier(std::shared_ptr<ExemplarTable> table, const std::string& backend,
             const std::optional<std::vector<std::string>>& materials, const std::string& method,
             const std::optional<SessionPrior>& prior, const pyb::handle& noise_mm,
             const std::optional<Calibration>& calibration, bool open_set, bool learning)
      : table_(std::move(table)) {
    if (backend != "float" && backend != "fixed") {
      throw pyb::value_error("unknown backend '" + backend + "': available backends are 'fixed' and 'float'");
    }
    if (method != "eq12" && method != "session") {
      throw pyb::value_error("unknown method '" + method + "': available methods are 'eq12' and 'session'");
    }
    if (method != "session" && (prior || !noise_mm.is_none())) {
      throw pyb::value_error("prior and noise_mm are settings of method='session'");
    }
    backend_ = backend;
    method_ = method;
    query_limit_mm_ = fixed_query_limit_mm(*table_);
    calibration_ = calibration ? *calibration : Calibration::tuned(method, *table_);
    if (learning && method != "session") {
      throw pyb::value_error("learning needs method='session': it learns the session prior's scale");
    }
    if (open_set && method != "session") {
      throw pyb::value_error("open_set needs method='session': Eq. (12) has no noise model to judge a fit");
    }
    if (!open_set) calibration_.unknown_fits.clear();  // never unknown
    std::vector<std::uint32_t> candidates;
    if (materials) {
      if (materials->empty()) throw pyb::value_error("materials: give at least one candidate, or None for all");
      try {
        candidates = candidate_names_to_indices(*table_, *materials);
      } catch (const std::invalid_argument& e) {
        throw pyb::value_error(std::string("materials: ") + e.what());
      }
    }
    // (FormatError, a ValueError: a material import and tofmatd refuse too; a table built in memory may
    // have constant rows)
    check_measured(*table_, "the table", {}, /*rows_must_vary=*/false);
    if (method == "session") {
      std::vector<double> noise;
      if (!noise_mm.is_none()) {
        auto a = as_float32(
            noise_mm, {static_cast<pyb::ssize_t>(table_->n_materials()), static_cast<pyb::ssize_t>(table_->n_rows())},
            "noise_mm");
        noise.assign(a.data(), a.data() + a.size());
      }
      const SessionPrior chosen = prior ? *prior : SessionPrior::tuned(*table_);
      if (learning) learner_ = SessionLearner::make(table_, chosen, backend == "fixed", noise, candidates);
      if (backend == "fixed") {
        fixed_session_ =
            std::make_unique<FixedSessionClassifier>(table_, chosen, std::move(noise), std::move(candidates));
      } else {
        session_ = std::make_unique<SessionClassifier>(table_, chosen, std::move(noise), std::move(candidates));
      }
    } else if (backend == "fixed") {
      fixed_ = std::make_unique<FixedClassifier>(table_, std::move(candidates));
    } else {
      float_ = std::make_unique<FloatClassifier>(table_, std::move(candidates));
    }
  }

  // A query value beyond the fixed-point range (32767 steps of the table) saturates in the fixed
  // backend, which then ranks the clamped value where the float backend (the reference) ranks the
  // value itself: near float32's limits they answer different materials. The fixed backend says so
  // with a RuntimeWarning (docs/numerics.md, the headroom).
  void check_range(const float* q, std::size_t n, const std::string& what) const {
    if (backend_ != "fixed") return;
    std::size_t saturated = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const float a = std::fabs(q[i]);  // (NaN: missing; infinite: the core refuses it)
      if (a > query_limit_mm_ && !std::isinf(a)) ++saturated;
    }
    if (saturated == 0) return;
    const std::string warning = what + ": " + std::to_string(saturated) + " value(s) beyond +-" +
                                std::to_string(query_limit_mm_) +
                                " mm saturate in the fixed-point backend (32767 steps of this table): its ranking "
                                "may differ from the float backend's";
    if (PyErr_WarnEx(PyExc_RuntimeWarning, warning.c_str(), 1) != 0) throw pyb::error_already_set();
  }

  Result classify(const pyb::handle& query) const {
    auto q = as_float32(query, shape(), "query");
    check_range(q.data(), static_cast<std::size_t>(q.size()), "query");
    Classification c;
    {
      pyb::gil_scoped_release nogil;
      c = core_classify(q.data(), static_cast<std::size_t>(q.size()));
    }
    return to_result(*table_, c, calibration_, vagueness());
  }

  // A finished sweep's whole query moves the learned session (learning=True only).
  void learn(const pyb::handle& query) {
    SessionLearner& learner = require_learning();
    auto q = as_float32(query, shape(), "query");
    check_range(q.data(), static_cast<std::size_t>(q.size()), "query");
    pyb::gil_scoped_release nogil;
    learner.learn(learner.classify(q.data(), static_cast<std::size_t>(q.size()), true));
  }
  void reset_session() { require_learning().reset(); }
  std::optional<pyb::dict> session() const {
    if (!learner_) return std::nullopt;
    const auto s = learner_->state();
    pyb::dict d;
    d["scales"] = s.scales;
    d["weights"] = s.weights;
    d["scale"] = s.scale;
    d["sweeps"] = s.sweeps;
    if (!s.offsets_mm.empty()) {
      d["offsets_mm"] = s.offsets_mm;
      d["drift_mm"] = s.drift_mm;
    }
    return d;
  }

  std::vector<Result> classify_batch(const pyb::handle& queries) const {
    auto s = shape();
    s.insert(s.begin(), -1);
    auto q = as_float32(queries, s, "queries");
    const auto n = static_cast<std::size_t>(q.shape(0));
    const std::size_t len = table_->elements_per_material();
    for (std::size_t i = 0; i < n; ++i) check_range(q.data() + i * len, len, "queries[" + std::to_string(i) + "]");
    std::vector<Classification> cs(n);
    {
      pyb::gil_scoped_release nogil;
      for (std::size_t i = 0; i < n; ++i) {
        try {
          cs[i] = core_classify(q.data() + i * len, len);
        } catch (const std::invalid_argument& e) {
          throw std::invalid_argument("queries[" + std::to_string(i) + "]: " + e.what());
        }
      }
    }
    std::vector<Result> out;
    out.reserve(n);
    const auto& vague = vagueness();
    for (const auto& c : cs) out.push_back(to_result(*table_, c, calibration_, vague));
    return out;
  }

  std::vector<std::string> materials() const {
    std::vector<std::string> out;
    const auto& c = session_         ? session_->candidates()
                    : fixed_session_ ? fixed_session_->candidates()
                    : fixed_         ? fixed_->candidates()
                                     : float_->candidates();
    for (auto i : c) out.push_back(table_->materials()[i]);
    return out;
  }
  const std::string& backend() const { return backend_; }
  const std::string& method() const { return method_; }
  const SessionClassifier* session_reference() const {
    return session_ ? session_.get() : fixed_session_ ? &fixed_session_->reference() : nullptr;
  }
  std::optional<SessionPrior> prior() const {
    const auto* s = session_reference();
    return s ? std::optional<SessionPrior>(s->prior()) : std::nullopt;
  }
  std::optional<pyb::array_t<double>> noise_mm() const {
    const auto* s = session_reference();
    if (!s) return std::nullopt;
    pyb::array_t<double> a(
        {static_cast<pyb::ssize_t>(table_->n_materials()), static_cast<pyb::ssize_t>(table_->n_rows())});
    std::copy(s->noise_mm().begin(), s->noise_mm().end(), a.mutable_data());
    return a;
  }
  std::shared_ptr<ExemplarTable> table() const { return table_; }
  const Calibration& calibration() const { return calibration_; }
  // The session matcher's candidate_vagueness() per table material (empty for eq12); a learner's
  // scorers share its noise model.
  const std::vector<double>& vagueness() const {
    static const std::vector<double> none;
    const auto* s = session_reference();
    return s ? s->vagueness() : none;
  }
  std::optional<pyb::array_t<double>> vagueness_array() const {
    if (!session_reference()) return std::nullopt;
    const auto& v = vagueness();
    pyb::array_t<double> a(static_cast<pyb::ssize_t>(v.size()));
    std::copy(v.begin(), v.end(), a.mutable_data());
    return a;
  }

 private:
  std::vector<pyb::ssize_t> shape() const {
    return {static_cast<pyb::ssize_t>(table_->n_rows()), static_cast<pyb::ssize_t>(table_->n_bins())};
  }

  SessionLearner& require_learning() const {
    if (!learner_) throw pyb::value_error("this classifier does not learn its session: make it with learning=True");
    return *learner_;
  }

  Classification core_classify(const float* q, std::size_t n) const {
    if (learner_) return learner_->classify(q, n).mixture;
    if (session_) return session_->classify(q, n);
    if (fixed_session_) return fixed_session_->classify(q, n);
    return fixed_ ? fixed_->classify(q, n) : float_->classify(q, n);
  }

  std::shared_ptr<ExemplarTable> table_;
  std::string backend_, method_;
  double query_limit_mm_ = 0.0;  // fixed_query_limit_mm: the fixed backend saturates beyond it
  Calibration calibration_;
  std::unique_ptr<FloatClassifier> float_;  // one of the four, by method and backend
  std::unique_ptr<FixedClassifier> fixed_;
  std::unique_ptr<SessionClassifier> session_;
  std::unique_ptr<FixedSessionClassifier> fixed_session_;
  std::shared_ptr<SessionLearner> learner_;  // learning=True: the mixture of scaled priors (session_learner.hpp)
};

}  // namespace

void register_classifier(pyb::module_& m) {
  pyb::class_<RankedMatch>(m, "RankedMatch",
                           "One material of a ranking (a table with several exemplars of a material, entries "
                           "named MATERIAL@TAG, ranks the material once, by its best exemplar).")
      .def_readonly("material", &RankedMatch::material, "The material (an entry 'cork@30' is one of 'cork').")
      .def_readonly("index", &RankedMatch::index, "Index of the material's best exemplar into table.materials.")
      .def_readonly("distance", &RankedMatch::distance,
                    "Eq. (12) distance, mm^2; for method='session' the score (negative log-likelihood).")
      .def_readonly("valid", &RankedMatch::valid, "Elements valid in both the query and the exemplar.")
      .def_readonly("fit", &RankedMatch::fit,
                    "How well it explains the query under the session matcher's noise model, a standard normal "
                    "deviate (large: worse than noise allows); NaN for method='eq12'.")
      .def_readonly("probability", &RankedMatch::probability,
                    "Calibrated probability that the query is this material, given that it is one of the "
                    "candidates (softmax of the scores at the sweep length's temperature, summed over the "
                    "material's exemplars).")
      .def("__repr__", [](const RankedMatch& r) { return "RankedMatch(" + match_repr(r) + ")"; });

  pyb::class_<Result>(m, "ClassificationResult", "The label of a query and the full ranking, best first.")
      .def_property_readonly(
          "material",
          [](const Result& r) { return r.unknown ? std::string(kUnknownLabel) : r.ranking.front().material; },
          "The label: the best match's material, or 'unknown' when no candidate explains the query.")
      .def_property_readonly(
          "index", [](const Result& r) { return r.unknown ? std::int64_t{-1} : std::int64_t{r.ranking.front().index}; },
          "Index of the label's best exemplar into table.materials; -1 when unknown.")
      .def_property_readonly("distance", [](const Result& r) { return r.ranking.front().distance; })
      .def_property_readonly("valid", [](const Result& r) { return r.ranking.front().valid; })
      .def_property_readonly(
          "fit", [](const Result& r) { return r.ranking.front().fit; }, "The best match's fit (RankedMatch.fit).")
      .def_property_readonly(
          "confidence", [](const Result& r) { return r.ranking.front().probability; },
          "The label's calibrated probability among the candidates (summed over its exemplars).")
      .def_readonly("unknown", &Result::unknown,
                    "True when the classifier was made with open_set=True and the best match's fit exceeds "
                    "the calibration's threshold at the sweep's length.")
      .def_property_readonly(
          "nearest", [](const Result& r) { return r.ranking.front().material; },
          "The best match's material, even when the label is 'unknown'.")
      .def_readonly("ranking", &Result::ranking)
      .def("__repr__", [](const Result& r) {
        return "ClassificationResult(" + match_repr(r.ranking.front()) + (r.unknown ? ", unknown=True" : "") +
               ", confidence=" + std::to_string(r.ranking.front().probability) + ")";
      });

  pyb::class_<Calibration>(m, "Calibration",
                           "Confidence and open-set settings (docs/evaluation.md): temperatures by sweep length "
                           "and the fit beyond which a label is 'unknown'.")
      .def(pyb::init([](std::vector<std::pair<double, double>> temperatures,
                        std::vector<std::pair<double, double>> unknown_fits) {
             Calibration c;
             c.temperatures = std::move(temperatures);
             c.unknown_fits = std::move(unknown_fits);
             c.validate();
             return c;
           }),
           pyb::arg("temperatures"), pyb::arg("unknown_fits") = std::vector<std::pair<double, double>>{},
           "temperatures: (sweep length in bins, T) knots, lengths increasing; unknown_fits: (sweep length in "
           "bins, fit) knots of the open-set threshold (empty: never unknown). Both are interpolated linearly in "
           "log length and held beyond the ends.")
      .def_static("tuned", pyb::overload_cast<const std::string&>(&Calibration::tuned), pyb::arg("method"),
                  "What docs/evaluation.md fitted for 'eq12' or 'session'.")
      .def_readonly("temperatures", &Calibration::temperatures)
      .def_readonly("unknown_fits", &Calibration::unknown_fits)
      .def("temperature", &Calibration::temperature, pyb::arg("bins"), "T at a sweep length in bins.")
      .def("unknown_fit", &Calibration::unknown_fit, pyb::arg("bins"),
           "The open-set threshold at a sweep length in bins (inf: never unknown).")
      .def("__repr__", [](const Calibration& c) {
        std::string t;
        for (const auto& [b, v] : c.temperatures)
          t += (t.empty() ? "(" : ", (") + std::to_string(b) + ", " + std::to_string(v) + ")";
        std::string u;
        for (const auto& [b, v] : c.unknown_fits)
          u += (u.empty() ? "(" : ", (") + std::to_string(b) + ", " + std::to_string(v) + ")";
        return "Calibration(temperatures=[" + t + "], unknown_fits=[" + u + "])";
      });

  pyb::class_<SessionPrior>(m, "SessionPrior",
                            "Settings of the session-robust matcher (docs/evaluation.md): the priors of a row's "
                            "offset and drift, the noise model and the outliers' threshold.")
      .def(pyb::init([](const std::vector<double>& offset_sd_mm, double drift1_sd_mm, double drift2_sd_mm,
                        double noise_scale, double floor_mm, double huber_k, int iterations) {
             SessionPrior p;
             p.offset_sd_mm = offset_sd_mm;
             p.drift1_sd_mm = drift1_sd_mm;
             p.drift2_sd_mm = drift2_sd_mm;
             p.noise_scale = noise_scale;
             p.floor_mm = floor_mm;
             p.huber_k = huber_k;
             p.iterations = iterations;
             p.validate(static_cast<std::uint32_t>(offset_sd_mm.size()));
             return p;
           }),
           pyb::arg("offset_sd_mm"), pyb::arg("drift1_sd_mm") = 5.0, pyb::arg("drift2_sd_mm") = 3.0,
           pyb::arg("noise_scale") = 1.4142135623730951, pyb::arg("floor_mm") = 0.5, pyb::arg("huber_k") = 3.0,
           pyb::arg("iterations") = 3)
      .def_static("tuned", &SessionPrior::tuned, pyb::arg("table"),
                  "The settings docs/evaluation.md tuned, for this table's rows.")
      .def_readonly("offset_sd_mm", &SessionPrior::offset_sd_mm, "Prior sd of each row's offset, mm.")
      .def_readonly("drift1_sd_mm", &SessionPrior::drift1_sd_mm, "Prior sd of the drift's degree-1 term, mm.")
      .def_readonly("drift2_sd_mm", &SessionPrior::drift2_sd_mm, "Prior sd of the drift's degree-2 term, mm.")
      .def_readonly("noise_scale", &SessionPrior::noise_scale, "Element noise in units of a material's noise.")
      .def_readonly("floor_mm", &SessionPrior::floor_mm, "Noise floor combined with it, mm.")
      .def_readonly("huber_k", &SessionPrior::huber_k, "Outlier threshold in noise units (inf: Gaussian).")
      .def_readonly("iterations", &SessionPrior::iterations, "Reweighting passes.")
      .def("__repr__", [](const SessionPrior& p) {
        std::string o;
        for (double v : p.offset_sd_mm) o += (o.empty() ? "" : ", ") + std::to_string(v);
        return "SessionPrior(offset_sd_mm=[" + o + "], drift1_sd_mm=" + std::to_string(p.drift1_sd_mm) +
               ", drift2_sd_mm=" + std::to_string(p.drift2_sd_mm) + ", noise_scale=" + std::to_string(p.noise_scale) +
               ", floor_mm=" + std::to_string(p.floor_mm) + ", huber_k=" + std::to_string(p.huber_k) +
               ", iterations=" + std::to_string(p.iterations) + ")";
      });

  m.def(
      "curve_roughness",
      [](const ExemplarTable& t) {
        const std::vector<double> r = curve_roughness(t);
        pyb::array_t<double> a({static_cast<pyb::ssize_t>(t.n_materials()), static_cast<pyb::ssize_t>(t.n_rows())});
        std::copy(r.begin(), r.end(), a.mutable_data());
        return a;
      },
      pyb::arg("table"),
      "Each material's bin noise per row (n_materials, n_rows), mm: 1.4826 MAD of its second differences / "
      "sqrt(6); NaN for a row of fewer than 5 elements.");

  pyb::class_<Classifier>(m, "Classifier",
                          "Nearest-neighbour classifier with partial matching: the session-robust matcher "
                          "(method='session', the default: docs/evaluation.md), or the paper's Eq. (12) "
                          "(method='eq12').")
      .def(pyb::init<std::shared_ptr<ExemplarTable>, const std::string&, const std::optional<std::vector<std::string>>&,
                     const std::string&, const std::optional<SessionPrior>&, const pyb::handle&,
                     const std::optional<Calibration>&, bool, bool>(),
           pyb::arg("table"), pyb::arg("backend") = "float", pyb::arg("materials") = pyb::none(),
           pyb::arg("method") = "session", pyb::arg("prior") = pyb::none(), pyb::arg("noise_mm") = pyb::none(),
           pyb::arg("calibration") = pyb::none(), pyb::arg("open_set") = false, pyb::arg("learning") = false)
      .def("classify", &Classifier::classify, pyb::arg("query"),
           "query: float array (n_rows, n_bins), NaN = missing. Raises ValueError if no element is valid.")
      .def("classify_batch", &Classifier::classify_batch, pyb::arg("queries"),
           "queries: float array (n, n_rows, n_bins). Returns a list of results.")
      .def("learn", &Classifier::learn, pyb::arg("query"),
           "learning=True: a finished sweep's whole query (n_rows, n_bins) teaches the classifier how far this "
           "session moved, and where (docs/evaluation.md). Raises ValueError without learning or if no element is "
           "valid.")
      .def("reset_session", &Classifier::reset_session,
           "learning=True: a new session (the prior weights again, no offsets learned).")
      .def_property_readonly("session", &Classifier::session,
                             "learning=True: the learned session {'scales', 'weights', 'scale' (the weights' "
                             "mean), 'sweeps', 'offsets_mm' (per row), 'drift_mm' (per row, Legendre degrees "
                             "1 and 2)}; None otherwise.")
      .def_property_readonly("materials", &Classifier::materials, "Candidate materials searched.")
      .def_property_readonly("backend", &Classifier::backend)
      .def_property_readonly("method", &Classifier::method, "'eq12' or 'session'.")
      .def_property_readonly("prior", &Classifier::prior, "The session matcher's settings (None for eq12).")
      .def_property_readonly("noise_mm", &Classifier::noise_mm,
                             "The session matcher's noise per material and row, mm (None for eq12).")
      .def_property_readonly("vagueness", &Classifier::vagueness_array,
                             "Per table material, how much noisier than the table's typical candidate its "
                             "noise model is (>= 1; tofmat::candidate_vagueness): a best match's fit is judged "
                             "at the typical noise by this factor before it tempers the confidence (None for eq12).")
      .def_property_readonly("calibration", &Classifier::calibration,
                             "Confidence and open-set settings in effect (default: Calibration.tuned(method), its "
                             "thresholds only with open_set=True).")
      .def_property_readonly("table", &Classifier::table);
}

}  // namespace tofmat::py
