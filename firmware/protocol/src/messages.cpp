// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Encoding and bounded decoding of the protocol's typed messages (hello, requests, replies and events).
#include "tofmat/protocol/messages.hpp"

#include <cmath>
#include <cstring>

namespace tofmat::protocol {
namespace {

const Json& field(const Json& obj, const char* key) {
  if (!obj.is_object()) throw ProtocolError(std::string("expected an object holding \"") + key + "\"");
  const auto it = obj.find(key);
  if (it == obj.end()) throw ProtocolError(std::string("missing field \"") + key + "\"");
  return *it;
}

void expect(const Message& m, MessageType type, const char* what) {
  if (m.type != type)
    throw ProtocolError(std::string("expected a ") + what + " message, got " + message_type_name(m.type));
}

void expect_event(const Message& m, const char* name) {
  expect(m, MessageType::kEvent, "event");
  if (event_name(m) != name) throw ProtocolError(std::string("expected a ") + name + " event");
}

Json encode_ranking(const std::vector<RankEntry>& ranking) {
  Json out = Json::array();
  for (const auto& r : ranking) out.push_back({{"material", r.material}, {"distance", r.distance}});
  return out;
}

int get_side(const Json& obj, const char* key) { return static_cast<int>(get_int(obj, key, 0, kMaxImageSide)); }

}  // namespace

std::string get_string(const Json& obj, const char* key, std::size_t max_bytes) {
  const Json& v = field(obj, key);
  if (!v.is_string()) throw ProtocolError(std::string("field \"") + key + "\" must be a string");
  const auto& s = v.get_ref<const std::string&>();
  if (s.size() > max_bytes)
    throw ProtocolError(std::string("field \"") + key + "\" is longer than " + std::to_string(max_bytes) + " bytes");
  return s;
}

std::uint64_t get_uint(const Json& obj, const char* key, std::uint64_t max_value) {
  const Json& v = field(obj, key);
  if (!v.is_number_unsigned() && !(v.is_number_integer() && v.get<std::int64_t>() >= 0))
    throw ProtocolError(std::string("field \"") + key + "\" must be a non-negative integer");
  const auto x = v.get<std::uint64_t>();
  if (x > max_value)
    throw ProtocolError(std::string("field \"") + key + "\" is above its maximum " + std::to_string(max_value));
  return x;
}

std::int64_t get_int(const Json& obj, const char* key, std::int64_t min_value, std::int64_t max_value) {
  const Json& v = field(obj, key);
  if (!v.is_number_integer()) throw ProtocolError(std::string("field \"") + key + "\" must be an integer");
  if (v.is_number_unsigned() && v.get<std::uint64_t>() > static_cast<std::uint64_t>(max_value))
    throw ProtocolError(std::string("field \"") + key + "\" is above its maximum " + std::to_string(max_value));
  const auto x = v.get<std::int64_t>();
  if (x < min_value || x > max_value)
    throw ProtocolError(std::string("field \"") + key + "\" must lie in [" + std::to_string(min_value) + ", " +
                        std::to_string(max_value) + "]");
  return x;
}

double get_number(const Json& obj, const char* key) {
  const Json& v = field(obj, key);
  if (!v.is_number()) throw ProtocolError(std::string("field \"") + key + "\" must be a number");
  const double x = v.get<double>();
  if (!std::isfinite(x)) throw ProtocolError(std::string("field \"") + key + "\" must be finite");
  return x;
}

bool get_bool(const Json& obj, const char* key) {
  const Json& v = field(obj, key);
  if (!v.is_boolean()) throw ProtocolError(std::string("field \"") + key + "\" must be true or false");
  return v.get<bool>();
}

std::vector<std::string> get_string_list(const Json& obj, const char* key, std::size_t max_items,
                                         std::size_t max_bytes) {
  const Json& v = field(obj, key);
  if (!v.is_array()) throw ProtocolError(std::string("field \"") + key + "\" must be a list of strings");
  if (v.size() > max_items)
    throw ProtocolError(std::string("field \"") + key + "\" has more than " + std::to_string(max_items) + " items");
  std::vector<std::string> out;
  for (const auto& s : v) {
    if (!s.is_string() || s.get_ref<const std::string&>().size() > max_bytes)
      throw ProtocolError(std::string("field \"") + key + "\" must hold strings of at most " +
                          std::to_string(max_bytes) + " bytes");
    out.push_back(s.get<std::string>());
  }
  return out;
}

std::string event_name(const Message& m) {
  if (m.type != MessageType::kEvent) return "";
  return get_string(m.meta, "event", kMaxNameBytes);
}

bool valid_depth_kind(const std::string& kind) {
  return kind == "80" || kind == "16" || kind == "120" || kind == "combined" || kind == "corrected";
}

Message encode_hello(const Hello& h) {
  Message m;
  m.type = MessageType::kHello;
  m.meta = {{"protocol", h.protocol},
            {"minor", h.minor},
            {"server", h.server},
            {"capabilities", h.capabilities},
            {"auth_required", h.auth_required}};
  return m;
}

Hello decode_hello(const Message& m) {
  expect(m, MessageType::kHello, "hello");
  Hello h;
  h.protocol = static_cast<std::uint32_t>(get_uint(m.meta, "protocol", 0xffff));
  h.minor = m.meta.contains("minor") ? static_cast<std::uint32_t>(get_uint(m.meta, "minor", 0xffff)) : 0;
  h.server = get_string(m.meta, "server", kMaxTextBytes);
  h.capabilities = get_string_list(m.meta, "capabilities", 64, kMaxNameBytes);
  h.auth_required = get_bool(m.meta, "auth_required");
  return h;
}

Message encode_request(const Request& r) {
  Message m;
  m.type = MessageType::kRequest;
  m.meta = {{"id", r.id}, {"cmd", r.cmd}, {"args", r.args.is_null() ? Json::object() : r.args}};
  return m;
}

Request decode_request(const Message& m) {
  expect(m, MessageType::kRequest, "request");
  Request r;
  r.id = static_cast<std::uint32_t>(get_uint(m.meta, "id", 0xffffffffu));
  r.cmd = get_string(m.meta, "cmd", kMaxNameBytes);
  const auto it = m.meta.find("args");
  if (it != m.meta.end()) {
    if (!it->is_object()) throw ProtocolError("field \"args\" must be an object");
    r.args = *it;
  }
  if (!m.blob.empty()) throw ProtocolError("a request carries no binary data");
  return r;
}

Message encode_reply(const Reply& r) {
  Message m;
  m.type = MessageType::kReply;
  m.meta = {{"id", r.id}, {"ok", r.ok}};
  if (!r.ok) {
    m.meta["code"] = r.code;
    m.meta["error"] = r.error;
  } else {
    m.meta["result"] = r.result.is_null() ? Json::object() : r.result;
  }
  return m;
}

Reply decode_reply(const Message& m) {
  expect(m, MessageType::kReply, "reply");
  Reply r;
  r.id = static_cast<std::uint32_t>(get_uint(m.meta, "id", 0xffffffffu));
  r.ok = get_bool(m.meta, "ok");
  if (!r.ok) {
    r.code = get_string(m.meta, "code", kMaxNameBytes);
    r.error = get_string(m.meta, "error", kMaxTextBytes);
  } else if (m.meta.contains("result")) {
    r.result = m.meta["result"];
    if (!r.result.is_object()) throw ProtocolError("field \"result\" must be an object");
  }
  return r;
}

Message encode_label(const LabelEvent& e) {
  Message m;
  m.meta = {{"event", "label"},
            {"frame", e.frame},
            {"timestamp_ns", e.timestamp_ns},
            {"profile", e.profile},
            {"state", e.state},
            {"material", e.material},
            {"index", e.index},
            {"distance", e.distance},
            {"valid", e.valid},
            {"bins_covered", e.bins_covered},
            {"ranking", encode_ranking(e.ranking)}};
  if (e.trigger) m.meta["trigger"] = *e.trigger;
  if (e.truth) m.meta["truth"] = {{"material", e.truth->material}, {"depth_mm", e.truth->depth_mm}};
  if (e.simulated) m.meta["simulated"] = true;
  if (e.confidence) m.meta["confidence"] = *e.confidence;
  if (e.fit) m.meta["fit"] = *e.fit;
  return m;
}

LabelEvent decode_label(const Message& m) {
  expect_event(m, "label");
  const Json& j = m.meta;
  LabelEvent e;
  e.frame = get_uint(j, "frame", UINT64_MAX);
  e.timestamp_ns = get_uint(j, "timestamp_ns", UINT64_MAX);
  e.profile = get_string(j, "profile", kMaxNameBytes);
  e.state = get_string(j, "state", kMaxNameBytes);
  e.material = get_string(j, "material", kMaxNameBytes);
  e.index = static_cast<std::int32_t>(get_int(j, "index", -1, static_cast<std::int64_t>(kMaxMaterials)));
  e.distance = get_number(j, "distance");
  e.valid = static_cast<std::uint32_t>(get_uint(j, "valid", 0xffffffffu));
  e.bins_covered = static_cast<std::uint32_t>(get_uint(j, "bins_covered", 0xffffffffu));
  const Json& ranking = field(j, "ranking");
  if (!ranking.is_array() || ranking.size() > kMaxRanking)
    throw ProtocolError("field \"ranking\" must be a list of at most " + std::to_string(kMaxRanking) + " entries");
  for (const auto& r : ranking)
    e.ranking.push_back({get_string(r, "material", kMaxNameBytes), get_number(r, "distance")});
  if (j.contains("trigger")) e.trigger = get_uint(j, "trigger", UINT64_MAX);
  if (j.contains("truth")) {
    const Json& t = j["truth"];
    e.truth = Truth{get_string(t, "material", kMaxNameBytes), get_number(t, "depth_mm")};
  }
  e.simulated = j.contains("simulated") && get_bool(j, "simulated");
  if (j.contains("confidence")) {
    e.confidence = get_number(j, "confidence");
    if (!(*e.confidence >= 0.0 && *e.confidence <= 1.0)) throw ProtocolError("field \"confidence\" must be 0..1");
  }
  if (j.contains("fit")) e.fit = get_number(j, "fit");
  return e;
}

Message encode_label_map(const LabelMapEvent& e) {
  if (e.labels.size() != static_cast<std::size_t>(e.width) * static_cast<std::size_t>(e.height))
    throw ProtocolError("label map size does not match width x height");
  Message m;
  m.meta = {{"event", "label_map"}, {"frame", e.frame},   {"timestamp_ns", e.timestamp_ns},
            {"width", e.width},     {"height", e.height}, {"materials", e.materials}};
  if (e.truth_accuracy) m.meta["truth_accuracy"] = *e.truth_accuracy;
  if (e.simulated) m.meta["simulated"] = true;
  m.blob = e.labels;
  return m;
}

LabelMapEvent decode_label_map(const Message& m) {
  expect_event(m, "label_map");
  LabelMapEvent e;
  e.frame = get_uint(m.meta, "frame", UINT64_MAX);
  e.timestamp_ns = get_uint(m.meta, "timestamp_ns", UINT64_MAX);
  e.width = get_side(m.meta, "width");
  e.height = get_side(m.meta, "height");
  e.materials = get_string_list(m.meta, "materials", kMaxMaterials, kMaxNameBytes);
  if (m.blob.size() != static_cast<std::size_t>(e.width) * static_cast<std::size_t>(e.height))
    throw ProtocolError("label map carries " + std::to_string(m.blob.size()) + " bytes for " + std::to_string(e.width) +
                        " x " + std::to_string(e.height) + " pixels");
  for (std::uint8_t v : m.blob)
    if (v != kNoLabel && v >= e.materials.size())
      throw ProtocolError("label map holds an index beyond its material list");
  if (m.meta.contains("truth_accuracy")) e.truth_accuracy = get_number(m.meta, "truth_accuracy");
  e.simulated = m.meta.contains("simulated") && get_bool(m.meta, "simulated");
  e.labels = m.blob;
  return e;
}

Message encode_depth(const DepthEvent& e) {
  if (e.depth_mm.size() != static_cast<std::size_t>(e.width) * static_cast<std::size_t>(e.height))
    throw ProtocolError("depth image size does not match width x height");
  Message m;
  m.meta = {{"event", "depth"}, {"frame", e.frame},   {"timestamp_ns", e.timestamp_ns},
            {"kind", e.kind},   {"x0", e.x0},         {"y0", e.y0},
            {"width", e.width}, {"height", e.height}, {"dtype", "float32"}};
  if (e.intrinsics) {
    const Intrinsics& k = *e.intrinsics;
    m.meta["intrinsics"] = {{"fx", k.fx}, {"fy", k.fy}, {"cx", k.cx}, {"cy", k.cy}, {"k1", k.k1},
                            {"k2", k.k2}, {"k3", k.k3}, {"p1", k.p1}, {"p2", k.p2}};
  }
  m.blob.resize(e.depth_mm.size() * sizeof(float));
  if (!m.blob.empty()) std::memcpy(m.blob.data(), e.depth_mm.data(), m.blob.size());  // little-endian hosts
  return m;
}

DepthEvent decode_depth(const Message& m) {
  expect_event(m, "depth");
  DepthEvent e;
  e.frame = get_uint(m.meta, "frame", UINT64_MAX);
  e.timestamp_ns = get_uint(m.meta, "timestamp_ns", UINT64_MAX);
  // (Any kind name: a later minor version may add kinds, and a client takes
  // them as names. The daemon sends and serves only valid_depth_kind's.)
  e.kind = get_string(m.meta, "kind", kMaxNameBytes);
  if (e.kind.empty()) throw ProtocolError("depth kind must not be empty");
  e.x0 = get_side(m.meta, "x0");
  e.y0 = get_side(m.meta, "y0");
  e.width = get_side(m.meta, "width");
  e.height = get_side(m.meta, "height");
  if (get_string(m.meta, "dtype", kMaxNameBytes) != "float32") throw ProtocolError("depth dtype must be float32");
  const std::size_t n = static_cast<std::size_t>(e.width) * static_cast<std::size_t>(e.height);
  if (m.blob.size() != n * sizeof(float))
    throw ProtocolError("depth image carries " + std::to_string(m.blob.size()) + " bytes for " + std::to_string(n) +
                        " pixels");
  e.depth_mm.resize(n);
  if (n) std::memcpy(e.depth_mm.data(), m.blob.data(), m.blob.size());
  if (m.meta.contains("intrinsics")) {
    const Json& j = m.meta["intrinsics"];
    if (!j.is_object()) throw ProtocolError("field \"intrinsics\" must be an object");
    Intrinsics k;
    k.fx = get_number(j, "fx");
    k.fy = get_number(j, "fy");
    k.cx = get_number(j, "cx");
    k.cy = get_number(j, "cy");
    k.k1 = get_number(j, "k1");
    k.k2 = get_number(j, "k2");
    k.k3 = get_number(j, "k3");
    k.p1 = get_number(j, "p1");
    k.p2 = get_number(j, "p2");
    if (!(k.fx > 0 && k.fy > 0)) throw ProtocolError("intrinsics: focal lengths must be > 0");
    e.intrinsics = k;
  }
  return e;
}

}  // namespace tofmat::protocol
