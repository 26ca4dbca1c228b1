// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// A learned classifier (an ONNX model trained by `tofmat train`) run through
// onnxruntime's C API. The library is opened at run time (dlopen), so a box
// without onnxruntime runs every other classifier; the build needs only the C
// API's headers (mk/fetch-deps.sh onnxruntime), and without them this class
// exists but says it is unavailable.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "tofmat/core/classifier.hpp"
#include "tofmat/core/exemplar_table.hpp"
#include "tofmat/learn/model_contract.hpp"

namespace tofmat::learn {

// The library dlopen() looks for when none is named: the soname of
// onnxruntime 1.x, found through the loader's usual search.
inline constexpr const char* kDefaultOnnxruntimeLibrary = "libonnxruntime.so.1";
// A model file larger than this is refused before it is read.
inline constexpr std::size_t kMaxModelBytes = std::size_t{64} << 20;
// A query element beyond +-this (mm) is refused: a row of the table is a few
// hundred mm at most, and past about 1e19 the features' squares overflow
// float32 and the model's probabilities become NaN.
inline constexpr double kMaxQueryMm = 1e6;

// Whether this build can run ONNX models at all; when not, why
// (unavailable_reason() is empty when it can).
bool onnxruntime_built();
std::string unavailable_reason();

class OnnxClassifier {
 public:
  // Loads `library` (once per process; later calls must name the same one),
  // reads the model (at most kMaxModelBytes), checks its contract against the
  // table and its input and output against the contract, runs it once on
  // each material's own curve (an output per material, each a probability,
  // summing to 1), and runs it on one thread. `candidates`: indices into the table to rank; empty means all.
  // Throws std::runtime_error when onnxruntime is unavailable or fails, and
  // std::invalid_argument when the model or a candidate does not fit.
  OnnxClassifier(std::shared_ptr<const ExemplarTable> table, const std::string& model_path,
                 std::vector<std::uint32_t> candidates = {}, const std::string& library = kDefaultOnnxruntimeLibrary);
  ~OnnxClassifier();
  OnnxClassifier(const OnnxClassifier&) = delete;
  OnnxClassifier& operator=(const OnnxClassifier&) = delete;

  // The model's probability for every material of the table, for one query
  // (n_rows x n_bins, C order, NaN = missing). Throws std::invalid_argument on
  // a wrong size, an element beyond +-kMaxQueryMm (infinite ones too) or a
  // query with no valid element.
  std::vector<float> probabilities(const float* query, std::size_t n) const;

  // The candidates ranked by the model's probability, renormalised over them:
  // Match::distance is -ln p (lower is better, as every matcher's; at most
  // 103.3, where float32's probability is 0), valid the
  // query's valid elements, fit NaN (no noise model: never unknown). Ties go
  // to the lower table index.
  Classification classify(const float* query, std::size_t n) const;

  const ModelContract& contract() const;
  const ExemplarTable& table() const { return *table_; }

 private:
  // The load's probe: throws std::invalid_argument naming the model and the material.
  void probe(const std::string& model_path) const;
  // The query's checks (probabilities()'s), its valid elements, and the model's output.
  std::vector<float> run(const float* query, std::size_t n, std::uint32_t& valid) const;

  struct Impl;
  std::shared_ptr<const ExemplarTable> table_;
  std::vector<std::uint32_t> candidates_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tofmat::learn
