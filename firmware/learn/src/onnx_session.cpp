// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// OnnxSession through onnxruntime's C API, its library opened with dlopen().
// The headers are 1.21's (C API version 21); the C API only ever appends, so
// GetApi(21) of any newer library returns a table these headers describe
// (../shared/docs/onnxruntime.md).
#include "onnx_session.hpp"

#include <dlfcn.h>
#include <onnxruntime_c_api.h>

#include <map>
#include <mutex>
#include <stdexcept>

#include "tofmat/core/file_io.hpp"
#include "tofmat/learn/onnx_classifier.hpp"

namespace tofmat::learn {
namespace {

// The library and one OrtEnv per process (onnxruntime wants one environment;
// the library is never closed: onnxruntime does not support unloading).
struct Runtime {
  std::string library;
  const OrtApi* api = nullptr;
  OrtEnv* env = nullptr;
};

const Runtime& runtime(const std::string& library) {
  static std::mutex mutex;
  static Runtime rt;
  const std::lock_guard<std::mutex> lock(mutex);
  if (rt.api) {
    if (library != rt.library)
      throw std::runtime_error("onnxruntime: \"" + rt.library + "\" is already loaded; cannot also load \"" + library +
                               "\"");
    return rt;
  }
  void* handle = dlopen(library.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (!handle) {
    const char* why = dlerror();  // NOLINT(concurrency-mt-unsafe): under the runtime's mutex
    throw std::runtime_error("onnxruntime: cannot load \"" + library + "\" (" + (why ? why : "unknown error") +
                             "); install onnxruntime 1.21 or later, or name its library with --onnxruntime-library");
  }
  using GetApiBase = const OrtApiBase* (*)();
  auto* get_base = reinterpret_cast<GetApiBase>(dlsym(handle, "OrtGetApiBase"));
  const OrtApiBase* base = get_base ? get_base() : nullptr;
  const OrtApi* api = base ? base->GetApi(ORT_API_VERSION) : nullptr;
  if (!api)
    throw std::runtime_error("onnxruntime: \"" + library + "\" does not offer C API version " +
                             std::to_string(ORT_API_VERSION) + " (onnxruntime 1.21 or later is needed; it is " +
                             (base ? base->GetVersionString() : "not onnxruntime") + ")");
  OrtEnv* env = nullptr;
  if (OrtStatus* s = api->CreateEnv(ORT_LOGGING_LEVEL_WARNING, "tofmat", &env)) {
    const std::string why = api->GetErrorMessage(s);
    api->ReleaseStatus(s);
    throw std::runtime_error("onnxruntime: " + why);
  }
  rt.library = library;
  rt.api = api;
  rt.env = env;
  return rt;
}

}  // namespace

struct OnnxSession::State {
  const OrtApi* api = nullptr;
  OrtSession* session = nullptr;
  OrtMemoryInfo* memory = nullptr;
  std::size_t elements = 0;

  ~State() {
    if (memory) api->ReleaseMemoryInfo(memory);
    if (session) api->ReleaseSession(session);
  }
  void check(OrtStatus* s, const std::string& what) const {
    if (!s) return;
    const std::string why = api->GetErrorMessage(s);
    api->ReleaseStatus(s);
    throw std::runtime_error("onnxruntime: " + what + ": " + why);
  }
  std::string name(bool input, std::size_t i) const {
    OrtAllocator* alloc = nullptr;
    check(api->GetAllocatorWithDefaultOptions(&alloc), "allocator");
    char* raw = nullptr;
    check(
        input ? api->SessionGetInputName(session, i, alloc, &raw) : api->SessionGetOutputName(session, i, alloc, &raw),
        "a name of the model's");
    std::string out = raw ? raw : "";
    check(api->AllocatorFree(alloc, raw), "free");
    return out;
  }
  // The element type and shape of input or output i.
  std::pair<ONNXTensorElementDataType, std::vector<std::int64_t>> shape(bool input, std::size_t i) const {
    OrtTypeInfo* info = nullptr;
    check(input ? api->SessionGetInputTypeInfo(session, i, &info) : api->SessionGetOutputTypeInfo(session, i, &info),
          "the model's types");
    struct Release {  // the type info, however this returns
      const OrtApi* api;
      OrtTypeInfo* info;
      ~Release() { api->ReleaseTypeInfo(info); }
    } release{api, info};
    const OrtTensorTypeAndShapeInfo* tensor = nullptr;
    ONNXTensorElementDataType type = ONNX_TENSOR_ELEMENT_DATA_TYPE_UNDEFINED;
    check(api->CastTypeInfoToTensorInfo(info, &tensor), "the model's types");
    if (!tensor) throw std::invalid_argument("the model's input and output must be tensors");
    check(api->GetTensorElementType(tensor, &type), "the model's types");
    std::size_t n = 0;
    check(api->GetDimensionsCount(tensor, &n), "the model's types");
    if (n > 8) throw std::invalid_argument("the model's tensors have too many dimensions");
    std::vector<std::int64_t> dims(n);
    check(api->GetDimensions(tensor, dims.data(), n), "the model's types");
    return {type, dims};
  }
  std::map<std::string, std::string> metadata() const {
    OrtModelMetadata* md = nullptr;
    check(api->SessionGetModelMetadata(session, &md), "the model's metadata");
    OrtAllocator* alloc = nullptr;
    std::map<std::string, std::string> out;
    try {
      check(api->GetAllocatorWithDefaultOptions(&alloc), "allocator");
      for (const char* key : {kKeyContract, kKeyMaterials, kKeyRows, kKeyBins, kKeyTemperatures, kKeyCurves}) {
        char* value = nullptr;
        check(api->ModelMetadataLookupCustomMetadataMap(md, alloc, key, &value), "the model's metadata");
        if (value) {
          out[key] = value;
          check(api->AllocatorFree(alloc, value), "free");
        }
      }
    } catch (...) {
      api->ReleaseModelMetadata(md);
      throw;
    }
    api->ReleaseModelMetadata(md);
    return out;
  }
};

OnnxSession::OnnxSession(const std::string& model_path, const std::string& library, std::size_t elements)
    : state_(std::make_unique<State>()) {
  const Runtime& rt = runtime(library);
  State& s = *state_;
  s.api = rt.api;
  s.elements = elements;
  const std::vector<std::uint8_t> bytes = read_file_bounded(model_path, kMaxModelBytes);
  OrtSessionOptions* options = nullptr;
  s.check(s.api->CreateSessionOptions(&options), "session options");
  try {
    // One thread: the daemon's profiles already keep the cores busy, and a
    // classification must not wait for a thread pool.
    s.check(s.api->SetIntraOpNumThreads(options, 1), "session options");
    s.check(s.api->SetInterOpNumThreads(options, 1), "session options");
    s.check(s.api->SetSessionGraphOptimizationLevel(options, ORT_ENABLE_ALL), "session options");
    s.check(s.api->CreateSessionFromArray(rt.env, bytes.data(), bytes.size(), options, &s.session),
            "cannot load the model " + model_path);
  } catch (...) {
    s.api->ReleaseSessionOptions(options);
    throw;
  }
  s.api->ReleaseSessionOptions(options);
  s.check(s.api->CreateCpuMemoryInfo(OrtArenaAllocator, OrtMemTypeDefault, &s.memory), "memory info");

  contract_ = parse_contract(s.metadata());
  std::size_t inputs = 0;
  s.check(s.api->SessionGetInputCount(s.session, &inputs), "the model's inputs");
  std::size_t outputs = 0;
  s.check(s.api->SessionGetOutputCount(s.session, &outputs), "the model's outputs");
  if (inputs != 1 || s.name(true, 0) != kInputName)
    throw std::invalid_argument(model_path + ": the model must have one input, \"" + std::string(kInputName) + "\"");
  bool has_output = false;
  for (std::size_t i = 0; i < outputs; ++i) has_output |= s.name(false, i) == kOutputName;
  if (!has_output) throw std::invalid_argument(model_path + ": the model has no output \"" + kOutputName + "\"");
  const auto [in_type, in_dims] = s.shape(true, 0);
  if (in_type != ONNX_TENSOR_ELEMENT_DATA_TYPE_FLOAT || in_dims.size() != 2 ||
      in_dims[1] != static_cast<std::int64_t>(elements))
    throw std::invalid_argument(model_path + ": the input \"query\" must be float [batch, " + std::to_string(elements) +
                                "]");
}

OnnxSession::OnnxSession(OnnxSession&&) noexcept = default;
OnnxSession::~OnnxSession() = default;

std::vector<float> OnnxSession::run(const float* query, std::size_t n) const {
  const State& s = *state_;
  std::vector<float> input(query, query + n);
  const std::int64_t shape[2] = {1, static_cast<std::int64_t>(n)};
  OrtValue* in = nullptr;
  s.check(s.api->CreateTensorWithDataAsOrtValue(s.memory, input.data(), input.size() * sizeof(float), shape, 2,
                                                ONNX_TENSOR_ELEMENT_DATA_TYPE_FLOAT, &in),
          "the query tensor");
  const char* in_names[1] = {kInputName};
  const char* out_names[1] = {kOutputName};
  OrtValue* out = nullptr;
  OrtStatus* status = s.api->Run(s.session, nullptr, in_names, &in, 1, out_names, 1, &out);
  s.api->ReleaseValue(in);
  s.check(status, "running the model");
  std::vector<float> result;
  try {
    OrtTensorTypeAndShapeInfo* info = nullptr;
    s.check(s.api->GetTensorTypeAndShape(out, &info), "the model's output");
    std::size_t dims = 0;
    std::int64_t d[2] = {0, 0};
    OrtStatus* st = s.api->GetDimensionsCount(info, &dims);
    if (!st && dims == 2) st = s.api->GetDimensions(info, d, 2);
    ONNXTensorElementDataType type = ONNX_TENSOR_ELEMENT_DATA_TYPE_UNDEFINED;
    if (!st) st = s.api->GetTensorElementType(info, &type);
    s.api->ReleaseTensorTypeAndShapeInfo(info);
    s.check(st, "the model's output");
    if (dims != 2 || d[0] != 1 || d[1] < 1 || d[1] > static_cast<std::int64_t>(kMaxMaterials) ||
        type != ONNX_TENSOR_ELEMENT_DATA_TYPE_FLOAT)
      throw std::runtime_error("onnxruntime: the model's output is not float [1, materials]");
    void* data = nullptr;
    s.check(s.api->GetTensorMutableData(out, &data), "the model's output");
    const auto* p = static_cast<const float*>(data);
    result.assign(p, p + d[1]);
  } catch (...) {
    s.api->ReleaseValue(out);
    throw;
  }
  s.api->ReleaseValue(out);
  return result;
}

bool onnxruntime_built() { return true; }
std::string unavailable_reason() { return {}; }

}  // namespace tofmat::learn
