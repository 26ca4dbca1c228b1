// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// OnnxClassifier's parts that do not touch onnxruntime: the query's checks
// and the ranking. The session is in onnx_session.cpp (or onnx_unavailable.cpp
// in a build without the C API's headers).
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "onnx_session.hpp"
#include "tofmat/learn/onnx_classifier.hpp"

namespace tofmat::learn {
namespace {
constexpr double kSmallestShare = 1.401298464324817e-45;  // the smallest float32 (2^-149)
}  // namespace

struct OnnxClassifier::Impl {
  OnnxSession session;
};

OnnxClassifier::OnnxClassifier(std::shared_ptr<const ExemplarTable> table, const std::string& model_path,
                               std::vector<std::uint32_t> candidates, const std::string& library)
    : table_(std::move(table)), candidates_(std::move(candidates)) {
  if (!table_) throw std::invalid_argument("OnnxClassifier: no table");
  for (const auto c : candidates_)
    if (c >= table_->n_materials())
      throw std::invalid_argument("OnnxClassifier: candidate " + std::to_string(c) + " is not in the table");
  if (candidates_.empty())
    for (std::uint32_t i = 0; i < table_->n_materials(); ++i) candidates_.push_back(i);
  impl_ = std::make_unique<Impl>(Impl{OnnxSession(model_path, library, table_->elements_per_material())});
  check_table(impl_->session.contract(), *table_);
  probe(model_path);
}

void OnnxClassifier::probe(const std::string& model_path) const {
  // Once at load, on each material's own curve: a model whose output has the
  // wrong count, or values that are not probabilities, is refused here
  // rather than failing every frame after a start that looked fine.
  for (std::size_t m = 0; m < table_->n_materials(); ++m) {
    if (table_->valid_count(m) == 0) continue;  // (no query to make of it)
    const std::string on = model_path + ": on material \"" + table_->materials()[m] + "\"'s own curve the model gave ";
    std::vector<float> p;
    try {
      p = impl_->session.run(table_->material_values(m), table_->elements_per_material());
    } catch (const std::runtime_error& e) {
      throw std::invalid_argument(on + "no usable output: " + e.what());
    }
    if (p.size() != table_->n_materials())
      throw std::invalid_argument(on + std::to_string(p.size()) + " outputs for the table's " +
                                  std::to_string(table_->n_materials()) + " materials");
    double total = 0.0;
    for (const float v : p) {
      if (!(v >= 0.0F && v <= 1.0F))
        throw std::invalid_argument(on + "the value " + std::to_string(v) + ": not a probability in [0, 1]");
      total += v;
    }
    if (std::fabs(total - 1.0) > 1e-3)
      throw std::invalid_argument(on + "probabilities summing to " + std::to_string(total) + ", not 1");
  }
}

OnnxClassifier::~OnnxClassifier() = default;

const ModelContract& OnnxClassifier::contract() const { return impl_->session.contract(); }

std::vector<float> OnnxClassifier::probabilities(const float* query, std::size_t n) const {
  std::uint32_t valid = 0;
  return run(query, n, valid);
}

std::vector<float> OnnxClassifier::run(const float* query, std::size_t n, std::uint32_t& valid) const {
  if (n != table_->elements_per_material())
    throw std::invalid_argument("OnnxClassifier: a query of " + std::to_string(n) + " elements, the table's have " +
                                std::to_string(table_->elements_per_material()));
  valid = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (std::fabs(query[i]) > kMaxQueryMm)  // (NaN compares false: a missing element)
      throw std::invalid_argument("OnnxClassifier: a query element beyond +-1e6 mm (" + std::to_string(query[i]) + ")");
    if (!std::isnan(query[i])) ++valid;
  }
  if (valid == 0) throw std::invalid_argument("OnnxClassifier: the query has no valid element");
  std::vector<float> p = impl_->session.run(query, n);
  if (p.size() != table_->n_materials())
    throw std::runtime_error("OnnxClassifier: the model gave " + std::to_string(p.size()) + " probabilities for " +
                             std::to_string(table_->n_materials()) + " materials");
  return p;
}

Classification OnnxClassifier::classify(const float* query, std::size_t n) const {
  std::uint32_t valid = 0;
  const std::vector<float> p = run(query, n, valid);
  double total = 0.0;
  for (const auto c : candidates_) {
    const double v = p[c];
    if (!(v >= 0.0) || !std::isfinite(v))
      throw std::runtime_error("OnnxClassifier: the model gave a probability not in [0, 1]");
    total += v;
  }
  Classification out;
  for (const auto c : candidates_) {
    Match m;
    m.index = c;
    // -ln p over the candidates. A probability of 0 (float32's softmax underflows past e^-103)
    // counts as the smallest float32, so that every distance is finite (the protocol's numbers
    // are): ln(2^-149) = -103.3.
    const double share =
        total > 0.0 ? static_cast<double>(p[c]) / total : 1.0 / static_cast<double>(candidates_.size());
    m.distance = -std::log(std::max(share, kSmallestShare));
    m.valid = valid;
    out.ranking.push_back(m);
  }
  rank(out);
  return out;
}

}  // namespace tofmat::learn
