// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// One ONNX model's session in onnxruntime (internal to tofmat_learn).
#pragma once

#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include "tofmat/learn/model_contract.hpp"

namespace tofmat::learn {

class OnnxSession {
 public:
  // Reads and checks the model (the contract, a float input "query" of
  // [batch, elements] and a float output "probabilities" of [batch, M]).
  OnnxSession(const std::string& model_path, const std::string& library, std::size_t elements);
  OnnxSession(OnnxSession&&) noexcept;
  ~OnnxSession();
  // The output for a batch of one query of `n` elements.
  std::vector<float> run(const float* query, std::size_t n) const;
  const ModelContract& contract() const { return contract_; }

 private:
  struct State;
  std::unique_ptr<State> state_;
  ModelContract contract_;
};

}  // namespace tofmat::learn
