// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Classifier for Python: Eq. (12) nearest neighbour (float or fixed point) over an exemplar
// table, single queries and batches, with the GIL released.
#include <pybind11/stl.h>

#include <algorithm>
#include <memory>
#include <optional>

#include "bindings.hpp"
#include "tofmat/core/classifier.hpp"
#include "tofmat/core/fixed_classifier.hpp"

namespace tofmat::py {

namespace {

// What Python sees: names resolved, best match flattened onto the result.
struct RankedMatch {
  std::string material;
  std::uint32_t index;
  double distance;
  std::uint32_t valid;
};

struct Result {
  std::vector<RankedMatch> ranking;
};

Result to_result(const ExemplarTable& table, const Classification& c) {
  Result r;
  r.ranking.reserve(c.ranking.size());
  for (const Match& m : c.ranking) r.ranking.push_back({table.materials()[m.index], m.index, m.distance, m.valid});
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
             const std::optional<std::vector<std::string>>& materials)
      : table_(std::move(table)) {
    if (backend != "float" && backend != "fixed") {
      throw pyb::value_error("unknown backend '" + backend + "': available backends are 'fixed' and 'float'");
    }
    backend_ = backend;
    std::vector<std::uint32_t> candidates;
    if (materials) {
      if (materials->empty()) throw pyb::value_error("materials: give at least one candidate, or None for all");
      for (const auto& name : *materials) {
        const auto i = table_->index_of(name);
        if (i < 0) throw pyb::value_error("materials: '" + name + "' is not in the table");
        candidates.push_back(static_cast<std::uint32_t>(i));
      }
    }
    if (backend == "fixed") {
      fixed_ = std::make_unique<FixedClassifier>(table_, std::move(candidates));
    } else {
      float_ = std::make_unique<FloatClassifier>(table_, std::move(candidates));
    }
  }

  Result classify(const pyb::handle& query) const {
    auto q = as_float32(query, shape(), "query");
    Classification c;
    {
      pyb::gil_scoped_release nogil;
      c = core_classify(q.data(), static_cast<std::size_t>(q.size()));
    }
    return to_result(*table_, c);
  }

  std::vector<Result> classify_batch(const pyb::handle& queries) const {
    auto s = shape();
    s.insert(s.begin(), -1);
    auto q = as_float32(queries, s, "queries");
    const auto n = static_cast<std::size_t>(q.shape(0));
    const std::size_t len = table_->elements_per_material();
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
    for (const auto& c : cs) out.push_back(to_result(*table_, c));
    return out;
  }

  std::vector<std::string> materials() const {
    std::vector<std::string> out;
    for (auto i : fixed_ ? fixed_->candidates() : float_->candidates()) out.push_back(table_->materials()[i]);
    return out;
  }
  const std::string& backend() const { return backend_; }
  std::shared_ptr<ExemplarTable> table() const { return table_; }

 private:
  std::vector<pyb::ssize_t> shape() const {
    return {static_cast<pyb::ssize_t>(table_->n_rows()), static_cast<pyb::ssize_t>(table_->n_bins())};
  }

  Classification core_classify(const float* q, std::size_t n) const {
    return fixed_ ? fixed_->classify(q, n) : float_->classify(q, n);
  }

  std::shared_ptr<ExemplarTable> table_;
  std::string backend_;
  std::unique_ptr<FloatClassifier> float_;  // one of the two, by backend
  std::unique_ptr<FixedClassifier> fixed_;
};

}  // namespace

void register_classifier(pyb::module_& m) {
  pyb::class_<RankedMatch>(m, "RankedMatch", "One candidate of a ranking.")
      .def_readonly("material", &RankedMatch::material)
      .def_readonly("index", &RankedMatch::index, "Index into table.materials.")
      .def_readonly("distance", &RankedMatch::distance, "Eq. (12) distance, mm^2.")
      .def_readonly("valid", &RankedMatch::valid, "Elements valid in both the query and the exemplar.")
      .def("__repr__", [](const RankedMatch& r) { return "RankedMatch(" + match_repr(r) + ")"; });

  pyb::class_<Result>(m, "ClassificationResult", "The label of a query and the full ranking, best first.")
      .def_property_readonly("material", [](const Result& r) { return r.ranking.front().material; })
      .def_property_readonly("index", [](const Result& r) { return r.ranking.front().index; })
      .def_property_readonly("distance", [](const Result& r) { return r.ranking.front().distance; })
      .def_property_readonly("valid", [](const Result& r) { return r.ranking.front().valid; })
      .def_readonly("ranking", &Result::ranking)
      .def("__repr__", [](const Result& r) { return "ClassificationResult(" + match_repr(r.ranking.front()) + ")"; });

  pyb::class_<Classifier>(m, "Classifier", "Nearest-neighbour classifier with partial matching (Eq. 12).")
      .def(pyb::init<std::shared_ptr<ExemplarTable>, const std::string&,
                     const std::optional<std::vector<std::string>>&>(),
           pyb::arg("table"), pyb::arg("backend") = "float", pyb::arg("materials") = pyb::none())
      .def("classify", &Classifier::classify, pyb::arg("query"),
           "query: float array (n_rows, n_bins), NaN = missing. Raises ValueError if no element is valid.")
      .def("classify_batch", &Classifier::classify_batch, pyb::arg("queries"),
           "queries: float array (n, n_rows, n_bins). Returns a list of results.")
      .def_property_readonly("materials", &Classifier::materials, "Candidate materials searched.")
      .def_property_readonly("backend", &Classifier::backend)
      .def_property_readonly("table", &Classifier::table);
}

}  // namespace tofmat::py
