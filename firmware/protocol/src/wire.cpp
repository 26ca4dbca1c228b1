// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The wire framing: encoding a message, and MessageReader, which cuts a byte stream into bounded messages.
#include "tofmat/protocol/wire.hpp"

#include <cstring>

namespace tofmat::protocol {
namespace {

void put_u16(std::vector<std::uint8_t>& out, std::uint16_t v) {
  out.push_back(static_cast<std::uint8_t>(v & 0xff));
  out.push_back(static_cast<std::uint8_t>(v >> 8));
}
void put_u32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<std::uint8_t>((v >> (8 * i)) & 0xff));
}
std::uint32_t get_u32(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0]) | static_cast<std::uint32_t>(p[1]) << 8 |
         static_cast<std::uint32_t>(p[2]) << 16 | static_cast<std::uint32_t>(p[3]) << 24;
}

bool known_type(std::uint8_t t) { return t >= 1 && t <= 4; }

}  // namespace

const char* message_type_name(MessageType type) {
  switch (type) {
    case MessageType::kHello: return "hello";
    case MessageType::kRequest: return "request";
    case MessageType::kReply: return "reply";
    case MessageType::kEvent: return "event";
  }
  return "unknown";
}

std::vector<std::uint8_t> encode(const Message& message) {
  if (!message.meta.is_object()) throw ProtocolError("message metadata must be a JSON object");
  return encode_text(message.type, message.meta.dump(-1, ' ', false, Json::error_handler_t::replace), message.blob);
}

std::vector<std::uint8_t> encode_text(MessageType type, std::string_view meta, const std::vector<std::uint8_t>& blob) {
  if (meta.size() > kMaxMetaBytes)
    throw ProtocolError("message metadata is " + std::to_string(meta.size()) + " bytes, more than the " +
                        std::to_string(kMaxMetaBytes) + " allowed");
  const std::size_t payload = 4 + meta.size() + blob.size();
  if (payload > kMaxPayloadBytes)
    throw ProtocolError("message payload is " + std::to_string(payload) + " bytes, more than the " +
                        std::to_string(kMaxPayloadBytes) + " allowed");
  std::vector<std::uint8_t> out;
  out.reserve(kHeaderBytes + payload);
  out.insert(out.end(), kMagic, kMagic + 4);
  put_u16(out, kProtocolVersion);
  out.push_back(static_cast<std::uint8_t>(type));
  out.push_back(0);  // flags, none defined in version 1
  put_u32(out, static_cast<std::uint32_t>(payload));
  put_u32(out, static_cast<std::uint32_t>(meta.size()));
  out.insert(out.end(), meta.begin(), meta.end());
  out.insert(out.end(), blob.begin(), blob.end());
  return out;
}

std::string printable(std::string_view text) {
  static constexpr char kHex[] = "0123456789abcdef";
  std::string out;
  out.reserve(text.size());
  for (const char c : text) {
    const auto b = static_cast<unsigned char>(c);
    if (b >= 0x20 && b < 0x7f && b != '\\') {
      out += c;
    } else {
      out += "\\x";
      out += kHex[b >> 4];
      out += kHex[b & 0xf];
    }
  }
  return out;
}

Json parse_meta(const std::uint8_t* data, std::size_t size) {
  // The callback refuses nesting deeper than kMaxJsonDepth while parsing, so
  // a hostile "[[[[..." costs neither stack nor memory.
  const Json::parser_callback_t limit_depth = [](int depth, Json::parse_event_t event, Json&) {
    if ((event == Json::parse_event_t::object_start || event == Json::parse_event_t::array_start) &&
        depth >= kMaxJsonDepth)
      throw ProtocolError("message metadata nests deeper than " + std::to_string(kMaxJsonDepth));
    return true;
  };
  // nlohmann's lexer takes a NUL byte for the end of the input, so
  // "{...}\0junk" would parse; valid JSON text never holds a raw NUL.
  if (std::memchr(data, 0, size) != nullptr)
    throw ProtocolError("message metadata is not valid JSON: it holds a NUL byte");
  Json meta;
  try {
    meta = Json::parse(data, data + size, limit_depth, /*allow_exceptions=*/true, /*ignore_comments=*/false);
  } catch (const Json::exception& e) {
    // (the parser quotes what it read last: the peer's bytes, escaped before they reach a log or a terminal)
    throw ProtocolError("message metadata is not valid JSON: " + printable(e.what()));
  }
  if (!meta.is_object()) throw ProtocolError("message metadata must be a JSON object");
  return meta;
}

MessageReader::MessageReader(std::size_t max_payload_bytes) : max_payload_(max_payload_bytes) {
  if (max_payload_ > kMaxPayloadBytes) max_payload_ = kMaxPayloadBytes;
}

void MessageReader::feed(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return;
  // Drop the consumed prefix before growing: a connection holds at most one
  // partial message plus one read's worth of bytes.
  if (start_ > 0 && start_ == buffer_.size()) {
    buffer_.clear();
    start_ = 0;
  } else if (start_ > 64 * 1024) {
    buffer_.erase(buffer_.begin(), buffer_.begin() + static_cast<std::ptrdiff_t>(start_));
    start_ = 0;
  }
  buffer_.insert(buffer_.end(), data, data + size);
}

std::optional<Message> MessageReader::next() {
  const std::size_t have = buffer_.size() - start_;
  if (have < kHeaderBytes) {
    // Check the magic as soon as its bytes are here: garbage fails fast.
    if (have > 0 && std::memcmp(buffer_.data() + start_, kMagic, have < 4 ? have : 4) != 0)
      throw ProtocolError("bad magic: not a tofmat protocol stream");
    return std::nullopt;
  }
  const std::uint8_t* h = buffer_.data() + start_;
  if (std::memcmp(h, kMagic, 4) != 0) throw ProtocolError("bad magic: not a tofmat protocol stream");
  const std::uint16_t version = static_cast<std::uint16_t>(h[4] | h[5] << 8);
  if (version != kProtocolVersion)
    throw VersionError("protocol version " + std::to_string(version) + " is not supported (this side speaks " +
                       std::to_string(kProtocolVersion) + ")");
  if (!known_type(h[6])) throw ProtocolError("unknown message type " + std::to_string(h[6]));
  if (h[7] != 0) throw ProtocolError("reserved header flags must be 0");
  const std::uint32_t payload = get_u32(h + 8);
  if (payload < 4 || payload > max_payload_)
    throw ProtocolError("payload length " + std::to_string(payload) + " outside [4, " + std::to_string(max_payload_) +
                        "]");
  if (have < kHeaderBytes + payload) return std::nullopt;
  const std::uint8_t* p = h + kHeaderBytes;
  const std::uint32_t meta_len = get_u32(p);
  if (meta_len > kMaxMetaBytes || meta_len > payload - 4)
    throw ProtocolError("metadata length " + std::to_string(meta_len) + " does not fit the payload of " +
                        std::to_string(payload) + " bytes (at most " + std::to_string(kMaxMetaBytes) + ")");
  Message m;
  m.type = static_cast<MessageType>(h[6]);
  m.meta = parse_meta(p + 4, meta_len);
  m.blob.assign(p + 4 + meta_len, p + payload);
  m.wire_bytes = kHeaderBytes + payload;
  start_ += kHeaderBytes + payload;
  return m;
}

}  // namespace tofmat::protocol
