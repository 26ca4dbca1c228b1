// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The label event's wire bytes written straight from its fields. It is the
// one event of every frame, and building it as a JSON tree first (a node and
// a string allocation a field, a copy for `latest`, then a walk to dump it)
// cost a tenth of a handheld frame's instructions on the board. The text is
// Json::dump's to the byte: its keys in their sorted order, its own float
// formatting (the serializer's grisu2, called here), strings that need
// escaping escaped by nlohmann itself. The tests hold it to
// encode(encode_label(e)) byte for byte, every optional field and odd string.
#include <charconv>
#include <cmath>
#include <string>
#include <string_view>

#include "tofmat/protocol/messages.hpp"

namespace tofmat::protocol {
namespace {

// Appends one object's members, each key one of ours (plain ASCII).
class MetaText {
 public:
  explicit MetaText(std::string& out) : out_(out) {}

  MetaText& open() { return put('{'); }
  MetaText& close() { return put('}'); }
  MetaText& put(char c) {
    out_ += c;
    return *this;
  }
  MetaText& key(std::string_view k) {
    if (out_.back() != '{') out_ += ',';
    out_ += '"';
    out_ += k;
    out_ += "\":";
    return *this;
  }
  MetaText& text(const std::string& s) {
    bool plain = true;
    for (const char c : s) {
      const auto b = static_cast<unsigned char>(c);
      if (b < 0x20 || b > 0x7e || b == '"' || b == '\\') {
        plain = false;
        break;
      }
    }
    if (plain) {
      out_ += '"';
      out_ += s;
      out_ += '"';
    } else {  // (escapes, UTF-8 and its replacement: rare, and nlohmann's own rules)
      out_ += Json(s).dump(-1, ' ', false, Json::error_handler_t::replace);
    }
    return *this;
  }
  MetaText& number(double v) {
    if (!std::isfinite(v)) {  // (as the serializer writes them)
      out_ += "null";
      return *this;
    }
    char buf[64];
    const char* end = ::nlohmann::detail::to_chars(buf, buf + sizeof buf, v);
    out_.append(buf, static_cast<std::size_t>(end - buf));
    return *this;
  }
  template <typename Int>
  MetaText& integer(Int v) {
    char buf[24];
    const auto r = std::to_chars(buf, buf + sizeof buf, v);
    out_.append(buf, static_cast<std::size_t>(r.ptr - buf));
    return *this;
  }

 private:
  std::string& out_;
};

}  // namespace

std::vector<std::uint8_t> encode_label_wire(const LabelEvent& e) {
  // Kept per thread: grown once, after which the text allocates nothing.
  thread_local std::string text;
  text.clear();
  MetaText m(text);
  m.open();
  m.key("bins_covered").integer(e.bins_covered);
  if (e.confidence) m.key("confidence").number(*e.confidence);
  m.key("distance").number(e.distance);
  m.key("event").text("label");
  if (e.fit) m.key("fit").number(*e.fit);
  m.key("frame").integer(e.frame);
  m.key("index").integer(e.index);
  m.key("material").text(e.material);
  m.key("profile").text(e.profile);
  m.key("ranking").put('[');
  for (std::size_t i = 0; i < e.ranking.size(); ++i) {
    if (i > 0) m.put(',');
    m.open().key("distance").number(e.ranking[i].distance).key("material").text(e.ranking[i].material).close();
  }
  m.put(']');
  if (e.simulated) m.key("simulated").put('t').put('r').put('u').put('e');
  m.key("state").text(e.state);
  m.key("timestamp_ns").integer(e.timestamp_ns);
  if (e.trigger) m.key("trigger").integer(*e.trigger);
  if (e.truth)
    m.key("truth").open().key("depth_mm").number(e.truth->depth_mm).key("material").text(e.truth->material).close();
  m.key("valid").integer(e.valid);
  m.close();
  return encode_text(MessageType::kEvent, text);
}

}  // namespace tofmat::protocol
