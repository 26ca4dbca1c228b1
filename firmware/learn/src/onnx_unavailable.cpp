// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// OnnxSession in a build without onnxruntime's C API headers: every model is
// refused, saying why and how to get them.
#include <stdexcept>

#include "onnx_session.hpp"
#include "tofmat/learn/onnx_classifier.hpp"

namespace tofmat::learn {

struct OnnxSession::State {};

OnnxSession::OnnxSession(const std::string&, const std::string&, std::size_t) {
  throw std::runtime_error(unavailable_reason());
}
OnnxSession::OnnxSession(OnnxSession&&) noexcept = default;
OnnxSession::~OnnxSession() = default;
std::vector<float> OnnxSession::run(const float*, std::size_t) const { throw std::runtime_error(unavailable_reason()); }

bool onnxruntime_built() { return false; }
std::string unavailable_reason() {
  return "this build of tofmat has no onnxruntime support: onnxruntime's C API headers were not found when it was "
         "built (run mk/fetch-deps.sh onnxruntime, or install libonnxruntime-dev, and rebuild)";
}

}  // namespace tofmat::learn
