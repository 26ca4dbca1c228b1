// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// libFuzzer target: tofmatd's protocol codec (firmware/protocol) on arbitrary
// bytes, as the daemon meets them from a client: a MessageReader with the
// request limit (kMaxRequestPayloadBytes), and every typed decoder on every
// message it yields. The only acceptable refusal is ProtocolError.
//
// Oracles:
//  - the reader gives the same messages (and the same refusal, after as
//    many messages) whether the bytes come in one piece or in small chunks;
//  - whatever a typed decoder accepts re-encodes without throwing, and those
//    bytes read back and decode to the same encoding again. One refusal is
//    allowed: a request's args or a reply's result is free JSON, and its
//    re-serialisation may be longer than what was received ("1e5" comes back
//    as "100000.0"), so it may exceed kMaxMetaBytes.
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "tofmat/protocol/messages.hpp"
#include "tofmat/protocol/schema.hpp"
#include "tofmat/protocol/wire.hpp"

namespace {

using namespace tofmat::protocol;
using Bytes = std::vector<std::uint8_t>;

struct Outcome {
  std::vector<Message> messages;
  bool refused = false;
  bool version = false;
};

Outcome read_messages(const std::uint8_t* data, std::size_t size, std::size_t chunk) {
  Outcome out;
  MessageReader reader(kMaxRequestPayloadBytes);
  try {
    for (std::size_t at = 0; at < size; at += chunk) {
      reader.feed(data + at, chunk < size - at ? chunk : size - at);
      while (auto m = reader.next()) out.messages.push_back(std::move(*m));
    }
    if (reader.buffered() >= kHeaderBytes + kMaxRequestPayloadBytes) __builtin_trap();
  } catch (const VersionError&) {
    out.refused = out.version = true;
  } catch (const ProtocolError&) {
    out.refused = true;
  }
  return out;
}

bool open_json_too_long(const Message& m) {
  return m.meta.dump(-1, ' ', false, Json::error_handler_t::replace).size() > kMaxMetaBytes;
}

// encode(to_message(value)) must work (or be the allowed refusal), and read
// back and decoded again it must encode to the same bytes.
template <typename T, typename Encode, typename Decode>
void check_reencode(const T& value, Encode to_message, Decode from_message, bool open_json) {
  const Message m = to_message(value);
  Bytes bytes;
  try {
    bytes = encode(m);
  } catch (const ProtocolError&) {
    if (open_json && open_json_too_long(m)) return;
    __builtin_trap();
  }
  MessageReader back(kMaxPayloadBytes);
  back.feed(bytes.data(), bytes.size());
  std::optional<Message> again = back.next();  // a ProtocolError here escapes: a finding
  if (!again || back.buffered() != 0) __builtin_trap();
  const Bytes twice = encode(to_message(from_message(*again)));
  if (twice != bytes) __builtin_trap();
}

template <typename Decode, typename Encode>
void try_decoder(const Message& m, Decode decode, Encode to_message, bool open_json = false) {
  using T = decltype(decode(m));
  std::optional<T> value;
  try {
    value.emplace(decode(m));
  } catch (const ProtocolError&) {
    return;
  }
  check_reencode(*value, to_message, decode, open_json);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const Outcome whole = read_messages(data, size, size > 0 ? size : 1);
  const Outcome pieces = read_messages(data, size, 1 + size % 7);
  if (whole.refused != pieces.refused || whole.version != pieces.version ||
      whole.messages.size() != pieces.messages.size())
    __builtin_trap();
  for (std::size_t i = 0; i < whole.messages.size(); ++i) {
    const Message& a = whole.messages[i];
    const Message& b = pieces.messages[i];
    if (a.type != b.type || a.meta != b.meta || a.blob != b.blob) __builtin_trap();
  }
  for (const Message& m : whole.messages) {
    if (!m.meta.is_object() || m.blob.size() > kMaxRequestPayloadBytes) __builtin_trap();
    try_decoder(m, decode_hello, encode_hello);
    try_decoder(m, decode_request, encode_request, true);
    try_decoder(m, decode_reply, encode_reply, true);
    try_decoder(m, decode_label, encode_label);
    // The daemon's direct label encoding writes what the tree does, for any label a peer could send.
    try {
      const LabelEvent e = decode_label(m);
      std::optional<Bytes> tree, direct;
      try {
        tree = encode(encode_label(e));
      } catch (const ProtocolError&) {
      }
      try {
        direct = encode_label_wire(e);
      } catch (const ProtocolError&) {
      }
      if (tree != direct) __builtin_trap();
    } catch (const ProtocolError&) {
    }
    try_decoder(m, decode_label_map, encode_label_map);
    try_decoder(m, decode_depth, encode_depth);
    try {
      event_name(m);
    } catch (const ProtocolError&) {
    }
    // The schema's check (what both clients run on every event) refuses or passes, never crashes;
    // what it passes strictly, it passes leniently too.
    if (m.type == MessageType::kEvent) {
      bool strict_ok = false;
      try {
        check_event(m, true);
        strict_ok = true;
      } catch (const ProtocolError&) {
      }
      try {
        check_event(m, false);
      } catch (const ProtocolError&) {
        if (strict_ok) __builtin_trap();
      }
    }
  }
  return 0;
}
