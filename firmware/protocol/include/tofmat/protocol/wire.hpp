// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The framing of tofmatd's socket protocol (docs/protocol.md): every message
// is a 12-byte header (magic "TMAT", version, type, payload length) and a
// payload of a JSON object (the metadata) followed by an optional binary blob
// (label maps, depth images). Every length read from the wire is checked
// against a bound before anything is allocated, and anything malformed is a
// ProtocolError: the connection it came from is closed, nothing else is.
#pragma once
#include <cstddef>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

namespace tofmat::protocol {

using Json = nlohmann::json;

// The protocol's major version, in every message's header: a client and a
// daemon of different majors refuse each other at hello.
inline constexpr std::uint16_t kProtocolVersion = 1;
// Its minor version, in the hello and the hello's reply: each minor only
// adds (fields, events, streams, commands, values), and clients ignore what
// they do not know, so a client of any minor talks to a daemon of any other
// (docs/protocol.md, Versions; its change list says what each one added).
inline constexpr std::uint16_t kProtocolMinor = 12;
inline constexpr char kMagic[4] = {'T', 'M', 'A', 'T'};
inline constexpr std::size_t kHeaderBytes = 12;
// The metadata of any message (the largest, a hello or status with 255
// material names of 64 bytes, is ~20 KiB: 64 KiB leaves room without
// letting a peer make us parse megabytes of JSON).
inline constexpr std::size_t kMaxMetaBytes = 64 * 1024;
// A whole payload from the daemon: a 512 x 424 float32 depth image is
// 868,352 bytes.
inline constexpr std::size_t kMaxPayloadBytes = 4 * 1024 * 1024;
// What the daemon accepts from a client: requests carry no blob.
inline constexpr std::size_t kMaxRequestPayloadBytes = 4 + kMaxMetaBytes;
// JSON nesting the parser accepts (requests are at most 3 deep).
inline constexpr int kMaxJsonDepth = 8;

enum class MessageType : std::uint8_t {
  kHello = 1,    // daemon -> client, first message of a connection
  kRequest = 2,  // client -> daemon: {"id", "cmd", "args"}
  kReply = 3,    // daemon -> client: {"id", "ok", "error"?, "code"?, "result"?}
  kEvent = 4,    // daemon -> client: {"event": "label" | "label_map" | "depth" | "device" | "status", ...}
};
const char* message_type_name(MessageType type);

struct Message {
  MessageType type = MessageType::kEvent;
  Json meta = Json::object();
  std::vector<std::uint8_t> blob;
  // What a reader took it from: header + payload bytes (0 for a message built here).
  std::size_t wire_bytes = 0;
};

class ProtocolError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};
// The peer frames its messages with another protocol version.
class VersionError : public ProtocolError {
 public:
  using ProtocolError::ProtocolError;
};

// Header + payload. Throws ProtocolError if meta is not an object or the
// message would exceed kMaxMetaBytes / kMaxPayloadBytes.
std::vector<std::uint8_t> encode(const Message& message);
// The same for metadata that is already JSON text, one object as Json::dump
// writes it (encode() is this after its dump; encode_label_wire writes its
// text without a JSON tree). Throws ProtocolError on the same bounds.
std::vector<std::uint8_t> encode_text(MessageType type, std::string_view meta,
                                      const std::vector<std::uint8_t>& blob = {});

// Incremental decoder of a byte stream: feed() what the socket gave, then
// take messages with next() until it returns nothing. Throws ProtocolError on
// a bad magic, version, type, length, or payload; after that the stream
// cannot be resynchronised and the connection must be closed.
class MessageReader {
 public:
  explicit MessageReader(std::size_t max_payload_bytes = kMaxPayloadBytes);
  void feed(const std::uint8_t* data, std::size_t size);
  std::optional<Message> next();
  // Bytes held that do not yet make a whole message.
  std::size_t buffered() const { return buffer_.size() - start_; }

 private:
  std::size_t max_payload_;
  std::vector<std::uint8_t> buffer_;
  std::size_t start_ = 0;  // consumed prefix of buffer_
};

// Text that came from a peer or a file, fit for a log line, a terminal or a
// Python str: printable ASCII as it is, every other byte (and the backslash)
// as \xNN, so an error that quotes hostile bytes is still one valid line.
std::string printable(std::string_view text);

// The payload's JSON object, parsed with a depth limit (no exceptions escape
// but ProtocolError). Exposed for the fuzz target.
Json parse_meta(const std::uint8_t* data, std::size_t size);

}  // namespace tofmat::protocol
