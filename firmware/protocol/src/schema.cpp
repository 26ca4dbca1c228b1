// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The protocol's event schema (schema.hpp) and the check of an event against it.
#include "tofmat/protocol/schema.hpp"

#include <algorithm>
#include <cmath>

namespace tofmat::protocol {
namespace {

using F = FieldType;
constexpr bool kAlways = true;
constexpr bool kOptional = false;

std::vector<EventSpec> make_schema() {
  // docs/protocol.md, Events: each field here is in its event's table there (a test checks it).
  return {
      {"label",
       {"labels"},
       false,
       {{"frame", F::kUint, kAlways},
        {"timestamp_ns", F::kUint, kAlways},
        {"profile", F::kName, kAlways},
        {"state", F::kName, kAlways},
        {"material", F::kName, kAlways},
        {"index", F::kInt, kAlways},
        {"distance", F::kNumber, kAlways},
        {"valid", F::kUint, kAlways},
        {"bins_covered", F::kUint, kAlways},
        {"ranking", F::kList, kAlways},
        {"trigger", F::kUint, kOptional},
        {"truth", F::kObject, kOptional},
        {"simulated", F::kBool, kOptional},
        {"confidence", F::kNumber, kOptional},
        {"fit", F::kNumber, kOptional}}},
      {"label_map",
       {"label_map"},
       true,
       {{"frame", F::kUint, kAlways},
        {"timestamp_ns", F::kUint, kAlways},
        {"width", F::kUint, kAlways},
        {"height", F::kUint, kAlways},
        {"materials", F::kNames, kAlways},
        {"truth_accuracy", F::kNumber, kOptional},
        {"simulated", F::kBool, kOptional}}},
      {"depth",
       {"depth:80", "depth:16", "depth:120", "depth:combined", "depth:corrected"},
       true,
       {{"frame", F::kUint, kAlways},
        {"timestamp_ns", F::kUint, kAlways},
        {"kind", F::kName, kAlways},
        {"x0", F::kUint, kAlways},
        {"y0", F::kUint, kAlways},
        {"width", F::kUint, kAlways},
        {"height", F::kUint, kAlways},
        {"dtype", F::kName, kAlways},
        {"intrinsics", F::kObject, kOptional}}},
      {"device",
       {"device"},
       false,
       {{"state", F::kName, kAlways}, {"message", F::kText, kAlways}, {"timestamp_ns", F::kUint, kAlways}}},
      {"sort",
       {"sort"},
       false,
       {{"state", F::kName, kAlways},
        {"item", F::kUint, kAlways},
        {"trigger_ns", F::kUint, kAlways},
        {"material", F::kName, kAlways},
        {"distance", F::kNumber, kAlways},
        {"outlet", F::kName, kAlways},
        {"reason", F::kName, kAlways},
        {"decided_ns", F::kUint, kAlways},
        {"fire_ns", F::kUint, kOptional},
        {"margin_ms", F::kNumber, kAlways},
        {"truth", F::kName, kOptional}}},
      {"line",
       {"line"},
       false,
       {{"kind", F::kName, kAlways},
        {"message", F::kText, kAlways},
        {"alarm", F::kBool, kAlways},
        {"timestamp_ns", F::kUint, kAlways}}},
      {"reset", {"reset"}, false, {{"by", F::kName, kAlways}, {"timestamp_ns", F::kUint, kAlways}}},
  };
}

void check_field(const Json& v, const FieldSpec& f) {
  const auto fail = [&](const char* what) {
    throw ProtocolError("field \"" + std::string(f.name) + "\" must be " + what);
  };
  switch (f.type) {
    case F::kName:
    case F::kText: {
      if (!v.is_string()) fail("a string");
      const std::size_t bound = f.type == F::kName ? kMaxNameBytes : kMaxTextBytes;
      if (v.get_ref<const std::string&>().size() > bound)
        throw ProtocolError("field \"" + std::string(f.name) + "\" is longer than " + std::to_string(bound) + " bytes");
      break;
    }
    case F::kUint:
      if (!v.is_number_unsigned() && !(v.is_number_integer() && v.get<std::int64_t>() >= 0))
        fail("a non-negative integer");
      break;
    case F::kInt:
      if (!v.is_number_integer()) fail("an integer");
      break;
    case F::kNumber:
      if (!v.is_number() || !std::isfinite(v.get<double>())) fail("a finite number");
      break;
    case F::kBool:
      if (!v.is_boolean()) fail("true or false");
      break;
    case F::kNames:
      if (!v.is_array() || v.size() > kMaxMaterials) fail("a list of at most 255 names");
      for (const auto& s : v)
        if (!s.is_string() || s.get_ref<const std::string&>().size() > kMaxNameBytes) fail("a list of names");
      break;
    case F::kObject:
      if (!v.is_object()) fail("an object");
      break;
    case F::kList:
      if (!v.is_array() || v.size() > kMaxRanking) fail("a list of at most 64 entries");
      for (const auto& e : v)
        if (!e.is_object()) fail("a list of objects");
      break;
  }
}

}  // namespace

const std::vector<EventSpec>& event_schema() {
  static const std::vector<EventSpec> schema = make_schema();
  return schema;
}

const std::vector<std::string>& stream_names() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> out;
    for (const auto& e : event_schema())
      for (const auto s : e.streams) out.emplace_back(s);
    return out;
  }();
  return names;
}

bool valid_stream(std::string_view stream) {
  const auto& names = stream_names();
  return std::find(names.begin(), names.end(), stream) != names.end();
}

const EventSpec* find_event(std::string_view event) {
  for (const auto& e : event_schema())
    if (e.event == event) return &e;
  return nullptr;
}

bool pollable_stream(std::string_view stream) {
  for (const auto& e : event_schema())
    if (!e.blob && std::find(e.streams.begin(), e.streams.end(), stream) != e.streams.end()) return true;
  return false;
}

const char* field_type_name(FieldType type) {
  switch (type) {
    case F::kName: return "name";
    case F::kText: return "text";
    case F::kUint: return "uint";
    case F::kInt: return "int";
    case F::kNumber: return "number";
    case F::kBool: return "bool";
    case F::kNames: return "names";
    case F::kObject: return "object";
    case F::kList: return "list";
  }
  return "?";
}

void check_event(const Message& m, bool strict) {
  const std::string name = event_name(m);
  const EventSpec* spec = find_event(name);
  if (spec == nullptr) {
    if (strict) throw ProtocolError("event \"" + name + "\" is not in the schema");
    return;
  }
  for (const auto& f : spec->fields) {
    const auto it = m.meta.find(std::string(f.name));
    if (it == m.meta.end()) {
      if (f.always) throw ProtocolError("event \"" + name + "\" has no field \"" + std::string(f.name) + "\"");
      continue;
    }
    check_field(*it, f);
  }
  if (strict) {
    for (const auto& [key, value] : m.meta.items()) {
      if (key == "event") continue;
      const bool known = std::any_of(spec->fields.begin(), spec->fields.end(),
                                     [&, k = std::string_view(key)](const FieldSpec& f) { return f.name == k; });
      if (!known) {
        std::string what = "event \"" + name + "\" has a field the schema lacks: \"";
        what += key;
        what += '"';
        throw ProtocolError(what);
      }
    }
  }
  if (!spec->blob && !m.blob.empty()) throw ProtocolError("event \"" + name + "\" carries no blob");
}

}  // namespace tofmat::protocol
