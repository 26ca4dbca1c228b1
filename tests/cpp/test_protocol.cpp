// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// tofmatd's protocol codec (firmware/protocol, docs/protocol.md): the framing
// against hand-built bytes, a round trip of every typed message through a
// MessageReader (byte by byte and in one piece), every bound and malformation
// as a ProtocolError, and parse_address.
#include <gtest/gtest.h>
#include <stdlib.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <string>
#include <thread>
#include <vector>

#include "test_util.hpp"
#include "tofmat/protocol/messages.hpp"
#include "tofmat/protocol/socket.hpp"
#include "tofmat/protocol/wire.hpp"

namespace {

using namespace tofmat::protocol;
using tofmat_test::Bytes;
using tofmat_test::error_of;
using tofmat_test::put_le;

// A frame built by hand (never through encode()): header, meta length, meta
// text, blob. payload / meta_len override the lengths the header claims.
Bytes frame(std::uint8_t type, const std::string& meta, const Bytes& blob = {}, std::uint16_t version = 1,
            std::uint8_t flags = 0, std::int64_t payload = -1, std::int64_t meta_len = -1) {
  Bytes b = {'T', 'M', 'A', 'T'};
  put_le(b, version, 2);
  b.push_back(type);
  b.push_back(flags);
  put_le(b, payload >= 0 ? static_cast<std::uint64_t>(payload) : 4 + meta.size() + blob.size(), 4);
  put_le(b, meta_len >= 0 ? static_cast<std::uint64_t>(meta_len) : meta.size(), 4);
  b.insert(b.end(), meta.begin(), meta.end());
  b.insert(b.end(), blob.begin(), blob.end());
  return b;
}

Bytes cat(Bytes a, const Bytes& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

// Every message a reader yields from `bytes`, fed in one piece or byte by byte.
std::vector<Message> read_all(const Bytes& bytes, bool byte_by_byte, std::size_t max_payload = kMaxPayloadBytes) {
  MessageReader r(max_payload);
  std::vector<Message> out;
  if (byte_by_byte) {
    for (std::uint8_t byte : bytes) {
      r.feed(&byte, 1);
      while (auto m = r.next()) out.push_back(std::move(*m));
    }
  } else {
    r.feed(bytes.data(), bytes.size());
    while (auto m = r.next()) out.push_back(std::move(*m));
  }
  EXPECT_EQ(r.buffered(), 0u);
  return out;
}

// The one message read back from `m`'s encoding both ways (and checks the two agree).
Message through_reader(const Message& m) {
  const Bytes bytes = encode(m);
  const auto whole = read_all(bytes, false);
  const auto bytewise = read_all(bytes, true);
  EXPECT_EQ(whole.size(), 1u);
  EXPECT_EQ(bytewise.size(), 1u);
  if (whole.size() != 1 || bytewise.size() != 1) return {};
  EXPECT_EQ(whole[0].type, m.type);
  EXPECT_EQ(whole[0].meta, m.meta);
  EXPECT_EQ(whole[0].blob, m.blob);
  EXPECT_EQ(bytewise[0].type, whole[0].type);
  EXPECT_EQ(bytewise[0].meta, whole[0].meta);
  EXPECT_EQ(bytewise[0].blob, whole[0].blob);
  return whole[0];
}

// The reader's refusal of `bytes` (which must be a ProtocolError).
std::string reader_error(const Bytes& bytes, std::size_t max_payload = kMaxPayloadBytes) {
  return error_of<ProtocolError>([&] {
    MessageReader r(max_payload);
    r.feed(bytes.data(), bytes.size());
    while (r.next()) {
    }
  });
}

std::string meta_error(const std::string& text) {
  return error_of<ProtocolError>([&] { parse_meta(reinterpret_cast<const std::uint8_t*>(text.data()), text.size()); });
}

Message event(const Json& meta, Bytes blob = {}) {
  Message m;
  m.type = MessageType::kEvent;
  m.meta = meta;
  m.blob = std::move(blob);
  return m;
}

std::uint32_t u32_at(const Bytes& b, std::size_t at) {
  return static_cast<std::uint32_t>(b[at]) | static_cast<std::uint32_t>(b[at + 1]) << 8 |
         static_cast<std::uint32_t>(b[at + 2]) << 16 | static_cast<std::uint32_t>(b[at + 3]) << 24;
}

// ---------------------------------------------------------------- framing

TEST(Wire, EncodeWritesTheDocumentedHeader) {
  Message m;
  m.type = MessageType::kReply;
  m.meta = {{"a", 1}};
  m.blob = {7, 8, 9};
  const Bytes b = encode(m);
  const std::string meta = "{\"a\":1}";
  ASSERT_EQ(b.size(), 12u + 4u + meta.size() + 3u);
  EXPECT_EQ(std::string(b.begin(), b.begin() + 4), "TMAT");
  EXPECT_EQ(b[4], 1);  // version 1, little-endian
  EXPECT_EQ(b[5], 0);
  EXPECT_EQ(b[6], 3);  // reply
  EXPECT_EQ(b[7], 0);  // flags
  EXPECT_EQ(u32_at(b, 8), 4u + meta.size() + 3u);
  EXPECT_EQ(u32_at(b, 12), meta.size());
  EXPECT_EQ(std::string(b.begin() + 16, b.begin() + 16 + static_cast<std::ptrdiff_t>(meta.size())), meta);
  EXPECT_EQ(Bytes(b.end() - 3, b.end()), (Bytes{7, 8, 9}));
  // The same bytes built by hand.
  EXPECT_EQ(b, frame(3, meta, {7, 8, 9}));
}

TEST(Wire, ReadsAHandBuiltFrameOfEveryType) {
  for (std::uint8_t type = 1; type <= 4; ++type) {
    SCOPED_TRACE(int{type});
    const auto ms = read_all(frame(type, "{\"k\":[1,\"x\"]}", {0, 255}), false);
    ASSERT_EQ(ms.size(), 1u);
    EXPECT_EQ(static_cast<int>(ms[0].type), int{type});
    EXPECT_EQ(ms[0].meta, Json::parse("{\"k\":[1,\"x\"]}"));
    EXPECT_EQ(ms[0].blob, (Bytes{0, 255}));
  }
  EXPECT_STREQ(message_type_name(MessageType::kHello), "hello");
  EXPECT_STREQ(message_type_name(MessageType::kEvent), "event");
}

TEST(Wire, TwoMessagesInOneFeedAndAPartialThird) {
  const Bytes a = frame(3, "{\"id\":1}"), b = frame(4, "{\"event\":\"x\"}", {1, 2, 3}), c = frame(2, "{\"id\":2}");
  Bytes all = cat(cat(a, b), Bytes(c.begin(), c.begin() + 9));
  MessageReader r;
  r.feed(all.data(), all.size());
  auto m1 = r.next();
  auto m2 = r.next();
  ASSERT_TRUE(m1 && m2);
  EXPECT_EQ(m1->meta["id"], 1);
  EXPECT_EQ(m2->blob, (Bytes{1, 2, 3}));
  EXPECT_FALSE(r.next());
  EXPECT_EQ(r.buffered(), 9u);
  r.feed(c.data() + 9, c.size() - 9);
  auto m3 = r.next();
  ASSERT_TRUE(m3);
  EXPECT_EQ(m3->type, MessageType::kRequest);
  EXPECT_EQ(m3->meta["id"], 2);
  EXPECT_FALSE(r.next());
  EXPECT_EQ(r.buffered(), 0u);
}

TEST(Wire, BufferStaysBoundedOverManyMessages) {
  // 20,000 messages fed in chunks that never line up with them (1000 bytes,
  // so most feeds end inside a message): what is held never exceeds one
  // partial message plus one chunk.
  Bytes stream;
  std::size_t largest = 0;
  for (int i = 0; i < 20000; ++i) {
    const Bytes f =
        frame(4, "{\"event\":\"label\",\"i\":" + std::to_string(i) + "}", Bytes(static_cast<std::size_t>(i % 97)));
    largest = std::max(largest, f.size());
    stream.insert(stream.end(), f.begin(), f.end());
  }
  MessageReader r;
  int count = 0;
  std::size_t most = 0;
  for (std::size_t at = 0; at < stream.size(); at += 1000) {
    const std::size_t n = std::min<std::size_t>(1000, stream.size() - at);
    r.feed(stream.data() + at, n);
    most = std::max(most, r.buffered());
    while (auto m = r.next()) {
      ASSERT_EQ(m->meta["i"], count);
      ++count;
    }
    ASSERT_LT(r.buffered(), largest);
  }
  EXPECT_EQ(count, 20000);
  EXPECT_EQ(r.buffered(), 0u);
  EXPECT_LE(most, largest + 1000);
}

TEST(Wire, BadMagicFailsOnTheFirstByte) {
  EXPECT_CONTAINS(reader_error({'X'}), "magic");
  EXPECT_CONTAINS(reader_error({'T', 'M', 'A', 'X'}), "magic");
  EXPECT_CONTAINS(reader_error({'G', 'E', 'T', ' ', '/', ' ', 'H', 'T', 'T', 'P', '/', '1', '.', '1'}), "magic");
  Bytes f = frame(2, "{}");
  f[3] = 'x';
  EXPECT_CONTAINS(reader_error(f), "magic");
  // A correct prefix waits for more.
  MessageReader r;
  for (char c : std::string("TMA")) {
    const auto byte = static_cast<std::uint8_t>(c);
    r.feed(&byte, 1);
    EXPECT_FALSE(r.next());
  }
}

TEST(Wire, OtherVersionIsAVersionError) {
  for (std::uint16_t v : {std::uint16_t{0}, std::uint16_t{2}, std::uint16_t{0x0100}, std::uint16_t{0xffff}}) {
    SCOPED_TRACE(v);
    const Bytes f = frame(2, "{}", {}, v);
    MessageReader r;
    r.feed(f.data(), f.size());
    EXPECT_THROW(r.next(), VersionError);
    EXPECT_CONTAINS(reader_error(f), "version");  // and a ProtocolError
  }
  // Detected from the header alone.
  Bytes header = frame(2, "{}", {}, 2);
  header.resize(12);
  MessageReader r;
  r.feed(header.data(), header.size());
  EXPECT_THROW(r.next(), VersionError);
}

TEST(Wire, UnknownTypeAndFlagsAreRefused) {
  for (std::uint8_t t : {std::uint8_t{0}, std::uint8_t{5}, std::uint8_t{255}})
    EXPECT_CONTAINS(reader_error(frame(t, "{}")), "unknown message type");
  for (std::uint8_t fl : {std::uint8_t{1}, std::uint8_t{0x80}})
    EXPECT_CONTAINS(reader_error(frame(2, "{}", {}, 1, fl)), "flags");
}

TEST(Wire, PayloadOverTheLimitFailsOnTheHeaderAlone) {
  // A header claiming 4 GiB: refused from its 12 bytes, nothing allocated or awaited.
  Bytes huge = frame(2, "", {}, 1, 0, 0xffffffffLL);
  huge.resize(12);
  for (std::size_t limit : {kMaxRequestPayloadBytes, kMaxPayloadBytes}) {
    MessageReader r(limit);
    r.feed(huge.data(), huge.size());
    EXPECT_THROW(r.next(), ProtocolError);
  }
  // The request limit, one past it, and exactly at it (waits for the payload).
  const auto header_with = [](std::size_t payload) {
    Bytes f = frame(2, "", {}, 1, 0, static_cast<std::int64_t>(payload));
    f.resize(12);
    return f;
  };
  EXPECT_CONTAINS(reader_error(header_with(kMaxRequestPayloadBytes + 1), kMaxRequestPayloadBytes), "payload length");
  {
    MessageReader r(kMaxRequestPayloadBytes);
    const Bytes h = header_with(kMaxRequestPayloadBytes);
    r.feed(h.data(), h.size());
    EXPECT_FALSE(r.next());
  }
  EXPECT_CONTAINS(reader_error(header_with(kMaxPayloadBytes + 1)), "payload length");
  // A limit above kMaxPayloadBytes is clamped to it.
  EXPECT_CONTAINS(reader_error(header_with(kMaxPayloadBytes + 1), std::numeric_limits<std::size_t>::max()),
                  "payload length");
  // A payload too short for its meta length field.
  for (std::int64_t p : {0, 1, 3})
    EXPECT_CONTAINS(reader_error(header_with(static_cast<std::size_t>(p))), "payload length");
}

TEST(Wire, MetaLengthMustFitThePayloadAndItsBound) {
  // Claims 7 bytes of meta in a payload that holds 4 + 5.
  EXPECT_CONTAINS(reader_error(frame(2, "{}xyz", {}, 1, 0, 9, 7)), "metadata length");
  EXPECT_CONTAINS(reader_error(frame(2, "{}", {}, 1, 0, 6, 0xffffffffLL)), "metadata length");
  // Over kMaxMetaBytes although the payload would hold it.
  const std::string big = "{\"s\":\"" + std::string(kMaxMetaBytes, 'x') + "\"}";
  EXPECT_CONTAINS(reader_error(frame(4, big)), "metadata length");
  // An empty meta is not JSON.
  EXPECT_CONTAINS(reader_error(frame(2, "")), "not valid JSON");
}

TEST(Wire, MetaMustBeAJsonObject) {
  for (const char* text : {"[]", "1", "\"s\"", "null", "true", "[{}]"}) {
    SCOPED_TRACE(text);
    EXPECT_CONTAINS(meta_error(text), "must be a JSON object");
    EXPECT_CONTAINS(reader_error(frame(2, text)), "must be a JSON object");
  }
}

TEST(Wire, InvalidJsonIsAProtocolError) {
  for (const std::string& text :
       {std::string("{"), std::string("{\"a\":}"), std::string("{}x"), std::string("{} {}"), std::string("{/*c*/}"),
        std::string("{'a':1}"), std::string("{\"a\":1,}"), std::string("{\"a\":NaN}"), std::string("{\"a\":1e400}"),
        std::string("{\"s\":\"\xff\"}"), std::string("{\"s\":\"a\x01\"}"), std::string("{\"s\":\"\\ud800\"}"),
        std::string("{\"a\":1}\0", 8), std::string("{\"a\":1}\0junk", 12), std::string("{}\0", 3)}) {
    SCOPED_TRACE(text);
    EXPECT_CONTAINS(meta_error(text), "not valid JSON");
    EXPECT_CONTAINS(reader_error(frame(2, text)), "not valid JSON");
  }
}

TEST(Wire, NestingIsLimitedToMaxJsonDepth) {
  // kMaxJsonDepth containers (the object and 7 arrays) parse; one more does not.
  const auto nested = [](int arrays) { return "{\"a\":" + std::string(arrays, '[') + std::string(arrays, ']') + "}"; };
  const std::string ok = nested(kMaxJsonDepth - 1);
  const Json j = parse_meta(reinterpret_cast<const std::uint8_t*>(ok.data()), ok.size());
  EXPECT_TRUE(j["a"].is_array());
  EXPECT_EQ(read_all(frame(2, ok), false).size(), 1u);
  EXPECT_CONTAINS(meta_error(nested(kMaxJsonDepth)), "nests deeper");
  EXPECT_CONTAINS(reader_error(frame(2, nested(kMaxJsonDepth))), "nests deeper");
  std::string objects = "{";
  for (int i = 0; i < kMaxJsonDepth; ++i) objects += "\"o\":{";
  objects += std::string(static_cast<std::size_t>(kMaxJsonDepth) + 1, '}');
  EXPECT_CONTAINS(meta_error(objects), "nests deeper");
  // A hostile depth costs neither stack nor memory: refused at kMaxJsonDepth + 1.
  const std::string hostile = "{\"a\":" + std::string(60000, '[');
  EXPECT_CONTAINS(meta_error(hostile), "nests deeper");
  EXPECT_CONTAINS(reader_error(frame(2, hostile), kMaxRequestPayloadBytes), "nests deeper");
}

TEST(Wire, EncodeRefusesWhatTheReaderWould) {
  Message m;
  m.meta = Json::array();
  EXPECT_CONTAINS(error_of<ProtocolError>([&] { encode(m); }), "JSON object");
  m.meta = nullptr;
  EXPECT_THROW(encode(m), ProtocolError);
  // Metadata exactly kMaxMetaBytes long encodes and is read back by the
  // daemon's request reader; one byte more does not encode.
  const std::size_t overhead = std::string("{\"s\":\"\"}").size();
  m.type = MessageType::kRequest;
  m.meta = {{"s", std::string(kMaxMetaBytes - overhead, 'x')}};
  const Bytes b = encode(m);
  EXPECT_EQ(b.size(), kHeaderBytes + kMaxRequestPayloadBytes);
  EXPECT_EQ(read_all(b, false, kMaxRequestPayloadBytes).size(), 1u);
  m.meta = {{"s", std::string(kMaxMetaBytes - overhead + 1, 'x')}};
  EXPECT_CONTAINS(error_of<ProtocolError>([&] { encode(m); }), "metadata");
  // The whole payload: 4 + meta + blob <= kMaxPayloadBytes.
  m.meta = Json::object();
  m.blob.assign(kMaxPayloadBytes - 4 - 2, 0);
  EXPECT_EQ(encode(m).size(), kHeaderBytes + kMaxPayloadBytes);
  m.blob.push_back(0);
  EXPECT_CONTAINS(error_of<ProtocolError>([&] { encode(m); }), "payload");
}

TEST(Wire, ErrorLeavesNothingUsableButDoesNotCrash) {
  // After a refusal the caller closes the connection; asking again refuses again.
  Bytes f = frame(2, "{}", {}, 1, 1);
  MessageReader r;
  r.feed(f.data(), f.size());
  EXPECT_THROW(r.next(), ProtocolError);
  EXPECT_THROW(r.next(), ProtocolError);
}

// ---------------------------------------------------------- typed messages

void expect_same(const LabelEvent& a, const LabelEvent& b) {
  EXPECT_EQ(a.frame, b.frame);
  EXPECT_EQ(a.timestamp_ns, b.timestamp_ns);
  EXPECT_EQ(a.profile, b.profile);
  EXPECT_EQ(a.state, b.state);
  EXPECT_EQ(a.material, b.material);
  EXPECT_EQ(a.index, b.index);
  EXPECT_EQ(a.distance, b.distance);
  EXPECT_EQ(a.valid, b.valid);
  EXPECT_EQ(a.bins_covered, b.bins_covered);
  ASSERT_EQ(a.ranking.size(), b.ranking.size());
  for (std::size_t i = 0; i < a.ranking.size(); ++i) {
    EXPECT_EQ(a.ranking[i].material, b.ranking[i].material);
    EXPECT_EQ(a.ranking[i].distance, b.ranking[i].distance);
  }
  EXPECT_EQ(a.trigger, b.trigger);
  EXPECT_EQ(a.confidence, b.confidence);
  EXPECT_EQ(a.fit, b.fit);
  ASSERT_EQ(a.truth.has_value(), b.truth.has_value());
  if (a.truth) {
    EXPECT_EQ(a.truth->material, b.truth->material);
    EXPECT_EQ(a.truth->depth_mm, b.truth->depth_mm);
  }
}

LabelEvent full_label() {
  LabelEvent e;
  e.frame = std::numeric_limits<std::uint64_t>::max();
  e.timestamp_ns = 1234567890123456789ull;
  e.profile = "sorting";
  e.state = "final";
  e.material = "Holz \xc3\xbc";  // UTF-8 survives
  e.index = 255;
  e.distance = 0.1 + 1e-13;
  e.valid = 0xffffffffu;
  e.bins_covered = 7;
  for (std::size_t i = 0; i < kMaxRanking; ++i)
    e.ranking.push_back({"m" + std::to_string(i), 1.0 / 3.0 * static_cast<double>(i) - 5e-300});
  e.trigger = 42;
  e.truth = Truth{"cork", 873.25000000000011};
  e.confidence = 0.8125;
  e.fit = -1.0 / 3.0;
  return e;
}

TEST(Messages, HelloRoundTrip) {
  Hello h;
  h.server = "tofmatd 0.1.0";
  h.capabilities = {"labels", "label_map", "depth", std::string(kMaxNameBytes, 'c')};
  h.auth_required = true;
  const Message m = through_reader(encode_hello(h));
  EXPECT_EQ(m.type, MessageType::kHello);
  const Hello d = decode_hello(m);
  EXPECT_EQ(d.protocol, kProtocolVersion);
  EXPECT_EQ(d.minor, kProtocolMinor);
  EXPECT_EQ(d.server, h.server);
  EXPECT_EQ(d.capabilities, h.capabilities);
  EXPECT_TRUE(d.auth_required);
  h.auth_required = false;
  h.capabilities.clear();
  EXPECT_FALSE(decode_hello(through_reader(encode_hello(h))).auth_required);
}

TEST(Messages, AHelloWithoutAMinorIsMinorZeroAndUnknownFieldsAreIgnored) {
  // A daemon that predates minor versions, and one from a later minor with
  // fields this client does not know: both are read.
  Message m = encode_hello(Hello{});
  m.meta.erase("minor");
  m.meta["a_later_field"] = {{"anything", 1}};
  const Hello d = decode_hello(through_reader(m));
  EXPECT_EQ(d.minor, 0u);
  EXPECT_EQ(d.protocol, kProtocolVersion);
  m.meta["minor"] = 999;
  EXPECT_EQ(decode_hello(through_reader(m)).minor, 999u);
  m.meta["minor"] = "four";
  EXPECT_THROW(decode_hello(m), ProtocolError);
}

TEST(Messages, RequestRoundTrip) {
  Request r;
  r.id = 0xffffffffu;
  r.cmd = "set_roi";
  r.args = {{"x0", 1}, {"y0", -2}, {"f", 0.1}, {"n", {{"deep", {1, 2, {{"k", "v"}}}}}}, {"s", "\xc3\xa9"}};
  const Request d = decode_request(through_reader(encode_request(r)));
  EXPECT_EQ(d.id, r.id);
  EXPECT_EQ(d.cmd, r.cmd);
  EXPECT_EQ(d.args, r.args);
  // No args: an empty object, and null args are sent as one.
  r.args = nullptr;
  const Message m = through_reader(encode_request(r));
  EXPECT_EQ(m.meta["args"], Json::object());
  EXPECT_EQ(decode_request(m).args, Json::object());
  // args may be left out by a client.
  EXPECT_EQ(decode_request(read_all(frame(2, "{\"id\":3,\"cmd\":\"status\"}"), true).at(0)).args, Json::object());
}

TEST(Messages, ReplyRoundTrip) {
  Reply ok;
  ok.id = 9;
  ok.result = {{"streams", {"labels"}}, {"x", 1.5}};
  const Reply a = decode_reply(through_reader(encode_reply(ok)));
  EXPECT_EQ(a.id, 9u);
  EXPECT_TRUE(a.ok);
  EXPECT_EQ(a.result, ok.result);
  Reply bad;
  bad.id = 10;
  bad.ok = false;
  bad.code = codes::kInvalidArgument;
  bad.error = std::string(kMaxTextBytes, 'e');
  const Message m = through_reader(encode_reply(bad));
  EXPECT_FALSE(m.meta.contains("result"));
  const Reply b = decode_reply(m);
  EXPECT_FALSE(b.ok);
  EXPECT_EQ(b.code, "invalid_argument");
  EXPECT_EQ(b.error, bad.error);
  // ok without result: an empty object.
  EXPECT_EQ(decode_reply(read_all(frame(3, "{\"id\":1,\"ok\":true}"), false).at(0)).result, Json::object());
}

TEST(Messages, LabelRoundTrip) {
  const LabelEvent full = full_label();
  const Message m = through_reader(encode_label(full));
  EXPECT_EQ(event_name(m), "label");
  expect_same(decode_label(m), full);
  // No target: no ranking, no trigger, no truth.
  LabelEvent none;
  none.profile = "handheld";
  none.state = "no_target";
  const Message n = through_reader(encode_label(none));
  EXPECT_FALSE(n.meta.contains("trigger"));
  EXPECT_FALSE(n.meta.contains("truth"));
  EXPECT_FALSE(n.meta.contains("confidence"));  // absent, never null (minor 7)
  EXPECT_FALSE(n.meta.contains("fit"));
  const LabelEvent d = decode_label(n);
  expect_same(d, none);
  EXPECT_EQ(d.index, -1);
  EXPECT_FALSE(d.trigger);
  EXPECT_FALSE(d.truth);
}

TEST(Messages, LabelMapRoundTrip) {
  LabelMapEvent e;
  e.frame = 3;
  e.timestamp_ns = 4;
  e.width = 5;
  e.height = 3;
  e.materials = {"a", "b", "c"};
  e.labels = {0, 1, 2, kNoLabel, 0, 1, 2, kNoLabel, 0, 1, 2, kNoLabel, 0, 1, 2};
  e.truth_accuracy = 0.75;
  const Message m = through_reader(encode_label_map(e));
  EXPECT_EQ(m.blob, e.labels);  // uint8, row-major
  const LabelMapEvent d = decode_label_map(m);
  EXPECT_EQ(d.frame, 3u);
  EXPECT_EQ(d.timestamp_ns, 4u);
  EXPECT_EQ(d.width, 5);
  EXPECT_EQ(d.height, 3);
  EXPECT_EQ(d.materials, e.materials);
  EXPECT_EQ(d.labels, e.labels);
  EXPECT_EQ(d.truth_accuracy, 0.75);
  // The full Kinect frame, 255 materials, no truth.
  e.width = 512;
  e.height = 424;
  e.materials.clear();
  for (int i = 0; i < 255; ++i) e.materials.push_back(std::string(kMaxNameBytes - 3, 'n') + std::to_string(100 + i));
  e.labels.assign(512u * 424u, 0);
  for (std::size_t i = 0; i < e.labels.size(); ++i) e.labels[i] = static_cast<std::uint8_t>(i % 256);  // 0..254, 255
  e.truth_accuracy.reset();
  const LabelMapEvent f = decode_label_map(through_reader(encode_label_map(e)));
  EXPECT_EQ(f.labels, e.labels);
  EXPECT_EQ(f.materials, e.materials);
  EXPECT_FALSE(f.truth_accuracy);
  // An empty map.
  e.width = e.height = 0;
  e.labels.clear();
  EXPECT_TRUE(decode_label_map(through_reader(encode_label_map(e))).labels.empty());
}

TEST(Messages, DepthRoundTripEveryKind) {
  for (const char* kind : {"80", "16", "120", "combined"}) {
    SCOPED_TRACE(kind);
    DepthEvent e;
    e.frame = 11;
    e.timestamp_ns = 12;
    e.kind = kind;
    e.x0 = 232;
    e.y0 = 188;
    e.width = 4;
    e.height = 2;
    e.depth_mm = {1000.5f,  -0.0f, std::numeric_limits<float>::quiet_NaN(), 1e-38f,
                  4095.25f, 0.0f,  std::numeric_limits<float>::infinity(),  3.0f};
    const Message m = through_reader(encode_depth(e));
    ASSERT_EQ(m.blob.size(), 32u);
    EXPECT_EQ(m.meta["dtype"], "float32");
    // float32 little-endian: 1000.5f is 0x447a2000.
    EXPECT_EQ(u32_at(m.blob, 0), 0x447a2000u);
    const DepthEvent d = decode_depth(m);
    EXPECT_EQ(d.kind, kind);
    EXPECT_EQ(d.x0, 232);
    EXPECT_EQ(d.y0, 188);
    EXPECT_EQ(d.width, 4);
    EXPECT_EQ(d.height, 2);
    ASSERT_EQ(d.depth_mm.size(), 8u);
    const auto bits = [](const std::vector<float>& v) {
      std::vector<std::uint32_t> b(v.size());
      std::memcpy(b.data(), v.data(), v.size() * sizeof(float));
      return b;
    };
    EXPECT_EQ(bits(d.depth_mm), bits(e.depth_mm));  // bit for bit, NaN included
    EXPECT_TRUE(std::isnan(d.depth_mm[2]));
  }
  EXPECT_TRUE(valid_depth_kind("combined"));
  EXPECT_FALSE(valid_depth_kind("depth:80"));
}

TEST(Messages, DeviceEventAndEventName) {
  const Message m =
      through_reader(event({{"event", "device"}, {"state", "streaming"}, {"message", "sim"}, {"timestamp_ns", 5}}));
  EXPECT_EQ(event_name(m), "device");
  Message reply;
  reply.type = MessageType::kReply;
  EXPECT_EQ(event_name(reply), "");
  EXPECT_CONTAINS(error_of<ProtocolError>([] { event_name(event({{"x", 1}})); }), "event");
  EXPECT_THROW(event_name(event({{"event", 5}})), ProtocolError);
  EXPECT_THROW(event_name(event({{"event", std::string(kMaxNameBytes + 1, 'e')}})), ProtocolError);
}

TEST(Messages, WrongMessageTypeOrEventIsRefused) {
  Reply r;
  const Message reply = encode_reply(r);
  EXPECT_CONTAINS(error_of<ProtocolError>([&] { decode_hello(reply); }), "expected a hello");
  EXPECT_CONTAINS(error_of<ProtocolError>([&] { decode_request(reply); }), "expected a request");
  EXPECT_CONTAINS(error_of<ProtocolError>([&] { decode_label(reply); }), "expected a event");
  EXPECT_THROW(decode_reply(encode_request(Request{})), ProtocolError);
  const Message label = encode_label(full_label());
  EXPECT_CONTAINS(error_of<ProtocolError>([&] { decode_label_map(label); }), "label_map");
  EXPECT_THROW(decode_depth(label), ProtocolError);
  Message as_request = label;
  as_request.type = MessageType::kRequest;
  EXPECT_THROW(decode_label(as_request), ProtocolError);
}

TEST(Messages, HelloBounds) {
  const Json good = encode_hello(Hello{}).meta;
  const auto err = [](Json meta) {
    Message m;
    m.type = MessageType::kHello;
    m.meta = std::move(meta);
    return error_of<ProtocolError>([&] { decode_hello(m); });
  };
  for (const char* key : {"protocol", "server", "capabilities", "auth_required"}) {
    Json j = good;
    j.erase(key);
    EXPECT_CONTAINS(err(j), key);
  }
  Json j = good;
  j["protocol"] = 0x10000;
  EXPECT_CONTAINS(err(j), "protocol");
  j = good;
  j["protocol"] = -1;
  EXPECT_CONTAINS(err(j), "protocol");
  j = good;
  j["capabilities"] = std::vector<std::string>(65, "c");
  EXPECT_CONTAINS(err(j), "capabilities");
  j = good;
  j["capabilities"] = {std::string(kMaxNameBytes + 1, 'c')};
  EXPECT_CONTAINS(err(j), "capabilities");
  j = good;
  j["capabilities"] = {1};
  EXPECT_CONTAINS(err(j), "capabilities");
  j = good;
  j["server"] = std::string(kMaxTextBytes + 1, 's');
  EXPECT_CONTAINS(err(j), "server");
  j = good;
  j["auth_required"] = 1;
  EXPECT_CONTAINS(err(j), "auth_required");
}

TEST(Messages, RequestBounds) {
  const auto err = [](const std::string& meta, const Bytes& blob = {}) {
    const auto ms = read_all(frame(2, meta, blob), false, kMaxRequestPayloadBytes);
    EXPECT_EQ(ms.size(), 1u);
    return ms.size() == 1 ? error_of<ProtocolError>([&] { decode_request(ms[0]); }) : std::string();
  };
  EXPECT_CONTAINS(err("{\"cmd\":\"status\"}"), "id");
  EXPECT_CONTAINS(err("{\"id\":-1,\"cmd\":\"status\"}"), "non-negative");
  EXPECT_CONTAINS(err("{\"id\":4294967296,\"cmd\":\"status\"}"), "maximum");
  EXPECT_CONTAINS(err("{\"id\":18446744073709551616,\"cmd\":\"status\"}"), "id");  // 2^64: a float
  EXPECT_CONTAINS(err("{\"id\":1.5,\"cmd\":\"status\"}"), "id");
  EXPECT_CONTAINS(err("{\"id\":\"1\",\"cmd\":\"status\"}"), "id");
  EXPECT_CONTAINS(err("{\"id\":1}"), "cmd");
  EXPECT_CONTAINS(err("{\"id\":1,\"cmd\":7}"), "cmd");
  EXPECT_CONTAINS(err("{\"id\":1,\"cmd\":\"" + std::string(kMaxNameBytes + 1, 'c') + "\"}"), "cmd");
  EXPECT_CONTAINS(err("{\"id\":1,\"cmd\":\"s\",\"args\":[]}"), "args");
  EXPECT_CONTAINS(err("{\"id\":1,\"cmd\":\"s\",\"args\":null}"), "args");
  EXPECT_CONTAINS(err("{\"id\":1,\"cmd\":\"s\"}", {0}), "binary");
  // At the bounds.
  const Request r = decode_request(
      read_all(frame(2, "{\"id\":4294967295,\"cmd\":\"" + std::string(kMaxNameBytes, 'c') + "\"}"), false).at(0));
  EXPECT_EQ(r.id, 4294967295u);
  EXPECT_EQ(r.cmd.size(), kMaxNameBytes);
}

TEST(Messages, ReplyBounds) {
  const auto err = [](const std::string& meta) {
    return error_of<ProtocolError>([&] { decode_reply(read_all(frame(3, meta), false).at(0)); });
  };
  EXPECT_CONTAINS(err("{\"id\":1}"), "ok");
  EXPECT_CONTAINS(err("{\"id\":1,\"ok\":1}"), "ok");
  EXPECT_CONTAINS(err("{\"id\":1,\"ok\":false,\"error\":\"x\"}"), "code");
  EXPECT_CONTAINS(err("{\"id\":1,\"ok\":false,\"code\":\"auth\"}"), "error");
  EXPECT_CONTAINS(
      err("{\"id\":1,\"ok\":false,\"code\":\"" + std::string(kMaxNameBytes + 1, 'c') + "\",\"error\":\"x\"}"), "code");
  EXPECT_CONTAINS(
      err("{\"id\":1,\"ok\":false,\"code\":\"c\",\"error\":\"" + std::string(kMaxTextBytes + 1, 'e') + "\"}"), "error");
  EXPECT_CONTAINS(err("{\"id\":1,\"ok\":true,\"result\":[1]}"), "result");
  EXPECT_CONTAINS(err("{\"id\":1,\"ok\":true,\"result\":null}"), "result");
}

TEST(Messages, LabelBounds) {
  const Json good = encode_label(full_label()).meta;
  const auto err = [](const Json& meta) { return error_of<ProtocolError>([&] { decode_label(event(meta)); }); };
  for (const char* key : {"frame", "timestamp_ns", "profile", "state", "material", "index", "distance", "valid",
                          "bins_covered", "ranking"}) {
    Json j = good;
    j.erase(key);
    EXPECT_CONTAINS(err(j), key);
  }
  Json j = good;
  j["ranking"].push_back({{"material", "x"}, {"distance", 1.0}});  // 65 entries
  EXPECT_CONTAINS(err(j), "ranking");
  j = good;
  j["ranking"] = Json::object();
  EXPECT_CONTAINS(err(j), "ranking");
  j = good;
  j["ranking"][0].erase("distance");
  EXPECT_CONTAINS(err(j), "distance");
  j = good;
  j["ranking"][0] = "wood";
  EXPECT_CONTAINS(err(j), "material");
  // index in [-1, 255].
  for (const Json& bad : {Json(-2), Json(256), Json(std::numeric_limits<std::uint64_t>::max()), Json(1.0), Json("1")}) {
    j = good;
    j["index"] = bad;
    EXPECT_CONTAINS(err(j), "index");
  }
  j = good;
  j["index"] = -1;
  EXPECT_EQ(decode_label(event(j)).index, -1);
  // A confidence is a probability; a fit any number.
  for (const Json& bad : {Json(-0.01), Json(1.5), Json("0.5")}) {
    j = good;
    j["confidence"] = bad;
    EXPECT_CONTAINS(err(j), "confidence");
  }
  j = good;
  j["fit"] = "x";
  EXPECT_CONTAINS(err(j), "fit");
  // Unsigned fields: negative, fractional, beyond their width.
  for (const char* key : {"frame", "timestamp_ns", "valid", "bins_covered", "trigger"}) {
    SCOPED_TRACE(key);
    for (const Json& bad : {Json(-1), Json(0.5), Json(true), Json(nullptr)}) {
      j = good;
      j[key] = bad;
      EXPECT_CONTAINS(err(j), key);
    }
  }
  j = good;
  j["valid"] = 0x100000000ull;
  EXPECT_CONTAINS(err(j), "maximum");
  // Strings over kMaxNameBytes.
  for (const char* key : {"profile", "state", "material"}) {
    j = good;
    j[key] = std::string(kMaxNameBytes + 1, 's');
    EXPECT_CONTAINS(err(j), key);
  }
  j = good;
  j["ranking"][3]["material"] = std::string(kMaxNameBytes + 1, 's');
  EXPECT_CONTAINS(err(j), "material");
  // truth must be an object with both fields.
  j = good;
  j["truth"] = "cork";
  EXPECT_CONTAINS(err(j), "expected an object holding \"material\"");
  j = good;
  j["truth"].erase("depth_mm");
  EXPECT_CONTAINS(err(j), "depth_mm");
  // A number written as a string is not a number.
  j = good;
  j["distance"] = "1.0";
  EXPECT_CONTAINS(err(j), "distance");
}

TEST(Messages, NonFiniteDistancesEncodeAsNullAndDoNotDecode) {
  // JSON has no NaN or infinity: nlohmann writes them as null, so the event
  // encodes but no reader accepts it (the daemon's classifier only emits
  // finite distances).
  const auto sent = [](const Message& m) {
    const auto ms = read_all(encode(m), false);
    EXPECT_EQ(ms.size(), 1u);
    return ms.empty() ? Message{} : ms[0];
  };
  for (const double bad : {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(),
                           -std::numeric_limits<double>::infinity()}) {
    SCOPED_TRACE(bad);
    LabelEvent e = full_label();
    e.distance = bad;
    const Message m = sent(encode_label(e));
    EXPECT_TRUE(m.meta["distance"].is_null());
    EXPECT_CONTAINS(error_of<ProtocolError>([&] { decode_label(m); }), "\"distance\" must be a number");
    e = full_label();
    e.ranking[1].distance = bad;
    EXPECT_CONTAINS(error_of<ProtocolError>([&] { decode_label(sent(encode_label(e))); }), "distance");
    e = full_label();
    e.truth->depth_mm = bad;
    EXPECT_CONTAINS(error_of<ProtocolError>([&] { decode_label(sent(encode_label(e))); }), "depth_mm");
    LabelMapEvent lm;
    lm.truth_accuracy = bad;
    EXPECT_CONTAINS(error_of<ProtocolError>([&] { decode_label_map(sent(encode_label_map(lm))); }), "truth_accuracy");
  }
  // Written by hand: NaN and Infinity are not JSON, 1e400 overflows a double.
  for (const char* v : {"NaN", "Infinity", "-Infinity", "1e400", "-1e400"}) {
    const std::string meta = std::string("{\"event\":\"label\",\"distance\":") + v + "}";
    EXPECT_CONTAINS(reader_error(frame(4, meta)), "not valid JSON");
  }
}

TEST(Messages, LabelMapBounds) {
  LabelMapEvent e;
  e.width = 3;
  e.height = 2;
  e.materials = {"a", "b"};
  e.labels = {0, 1, 255, 1, 0, 255};
  const Message good = encode_label_map(e);
  const auto err = [](const Message& m) { return error_of<ProtocolError>([&] { decode_label_map(m); }); };
  Message m = good;
  m.blob[2] = 2;  // one past the material list
  EXPECT_CONTAINS(err(m), "index beyond");
  m.blob[2] = 254;
  EXPECT_CONTAINS(err(m), "index beyond");
  m = good;
  m.blob.push_back(0);
  EXPECT_CONTAINS(err(m), "carries 7 bytes");
  m = good;
  m.blob.pop_back();
  EXPECT_CONTAINS(err(m), "carries 5 bytes");
  m = good;
  m.meta["width"] = kMaxImageSide + 1;
  EXPECT_CONTAINS(err(m), "width");
  m = good;
  m.meta["height"] = -1;
  EXPECT_CONTAINS(err(m), "height");
  m = good;
  m.meta["width"] = 2.5;
  EXPECT_CONTAINS(err(m), "width");
  m = good;
  m.meta["materials"] = std::vector<std::string>(kMaxMaterials + 1, "m");
  EXPECT_CONTAINS(err(m), "materials");
  m = good;
  m.meta["materials"] = {"a", std::string(kMaxNameBytes + 1, 'b')};
  EXPECT_CONTAINS(err(m), "materials");
  m = good;
  m.meta["truth_accuracy"] = "high";
  EXPECT_CONTAINS(err(m), "truth_accuracy");
  // kMaxImageSide x kMaxImageSide is allowed by the sides, but the blob
  // would have to be 16 MiB: no reader takes such a payload.
  m = good;
  m.meta["width"] = kMaxImageSide;
  m.meta["height"] = kMaxImageSide;
  EXPECT_CONTAINS(err(m), "carries");
  // With no materials only 255 (no label) is allowed.
  m = good;
  m.meta["materials"] = Json::array();
  EXPECT_CONTAINS(err(m), "index beyond");
  m.blob.assign(6, kNoLabel);
  EXPECT_EQ(decode_label_map(m).labels, Bytes(6, kNoLabel));
  // The encoder refuses a map that does not match its size.
  e.labels.pop_back();
  EXPECT_CONTAINS(error_of<ProtocolError>([&] { encode_label_map(e); }), "width x height");
}

TEST(Messages, DepthIntrinsicsRoundTripAndBounds) {
  DepthEvent e;
  e.kind = "combined";
  e.width = 1;
  e.height = 1;
  e.depth_mm = {900.0f};
  EXPECT_FALSE(decode_depth(through_reader(encode_depth(e))).intrinsics);  // none known: none sent
  EXPECT_FALSE(encode_depth(e).meta.contains("intrinsics"));
  e.intrinsics = Intrinsics{365.5, 365.25, 255.5, 211.75, 0.09, -0.27, 0.1, 0.001, -0.002};
  const Message good = through_reader(encode_depth(e));
  const DepthEvent d = decode_depth(good);
  ASSERT_TRUE(d.intrinsics);
  const Intrinsics& k = *d.intrinsics;
  EXPECT_EQ(std::vector<double>({k.fx, k.fy, k.cx, k.cy, k.k1, k.k2, k.k3, k.p1, k.p2}),
            std::vector<double>({365.5, 365.25, 255.5, 211.75, 0.09, -0.27, 0.1, 0.001, -0.002}));
  const auto err = [](const Message& m) { return error_of<ProtocolError>([&] { decode_depth(m); }); };
  Message m = good;
  m.meta["intrinsics"] = 3;
  EXPECT_CONTAINS(err(m), "intrinsics");
  for (const char* key : {"fx", "fy", "cx", "cy", "k1", "k2", "k3", "p1", "p2"}) {
    m = good;
    m.meta["intrinsics"].erase(key);
    EXPECT_CONTAINS(err(m), key);
    m = good;
    m.meta["intrinsics"][key] = "x";
    EXPECT_CONTAINS(err(m), key);
  }
  for (const char* key : {"fx", "fy"}) {
    m = good;
    m.meta["intrinsics"][key] = 0.0;
    EXPECT_CONTAINS(err(m), "focal");
  }
  m = good;
  m.meta["intrinsics"]["later"] = 1;  // a later minor's field: ignored
  EXPECT_TRUE(decode_depth(m).intrinsics);
}

TEST(Messages, DepthBounds) {
  DepthEvent e;
  e.kind = "combined";
  e.width = 2;
  e.height = 2;
  e.depth_mm = {1, 2, 3, 4};
  const Message good = encode_depth(e);
  const auto err = [](const Message& m) { return error_of<ProtocolError>([&] { decode_depth(m); }); };
  Message m = good;
  m.blob.pop_back();
  EXPECT_CONTAINS(err(m), "carries 15 bytes");
  m = good;
  m.blob.resize(20);
  EXPECT_CONTAINS(err(m), "carries 20 bytes");
  m = good;
  m.meta["kind"] = "";
  EXPECT_CONTAINS(err(m), "depth kind");
  m = good;
  m.meta["kind"] = "corrected";  // a kind of a later minor version: a name like any other
  EXPECT_EQ(decode_depth(m).kind, "corrected");
  m = good;
  m.meta["dtype"] = "float64";
  EXPECT_CONTAINS(err(m), "dtype");
  m = good;
  m.meta.erase("dtype");
  EXPECT_CONTAINS(err(m), "dtype");
  for (const char* key : {"x0", "y0", "width", "height"}) {
    m = good;
    m.meta[key] = -1;
    EXPECT_CONTAINS(err(m), key);
    m.meta[key] = kMaxImageSide + 1;
    EXPECT_CONTAINS(err(m), key);
  }
  e.depth_mm.push_back(5);
  EXPECT_CONTAINS(error_of<ProtocolError>([&] { encode_depth(e); }), "width x height");
}

TEST(Messages, FieldReaders) {
  const Json j = {{"u", 5},   {"neg", -5},  {"big", std::numeric_limits<std::uint64_t>::max()},
                  {"f", 2.5}, {"s", "abc"}, {"list", {"a", "b"}},
                  {"b", true}};
  EXPECT_EQ(get_uint(j, "u", 5), 5u);
  EXPECT_CONTAINS(error_of<ProtocolError>([&] { get_uint(j, "u", 4); }), "maximum");
  EXPECT_THROW(get_uint(j, "neg", 10), ProtocolError);
  EXPECT_EQ(get_uint(j, "big", std::numeric_limits<std::uint64_t>::max()), std::numeric_limits<std::uint64_t>::max());
  EXPECT_EQ(get_int(j, "neg", -5, 0), -5);
  EXPECT_THROW(get_int(j, "neg", -4, 0), ProtocolError);
  EXPECT_THROW(get_int(j, "big", 0, std::numeric_limits<std::int64_t>::max()), ProtocolError);
  EXPECT_THROW(get_int(j, "f", 0, 10), ProtocolError);
  EXPECT_EQ(get_number(j, "u"), 5.0);
  EXPECT_EQ(get_number(j, "f"), 2.5);
  EXPECT_THROW(get_number(j, "b"), ProtocolError);
  EXPECT_THROW(get_number(j, "s"), ProtocolError);
  EXPECT_EQ(get_string(j, "s", 3), "abc");
  EXPECT_THROW(get_string(j, "s", 2), ProtocolError);
  EXPECT_EQ(get_string_list(j, "list", 2, 1), (std::vector<std::string>{"a", "b"}));
  EXPECT_THROW(get_string_list(j, "list", 1, 1), ProtocolError);
  EXPECT_THROW(get_string_list(j, "s", 5, 5), ProtocolError);
  EXPECT_CONTAINS(error_of<ProtocolError>([&] { get_string(j, "missing", 5); }), "missing field \"missing\"");
  EXPECT_THROW(get_string(Json::array(), "s", 5), ProtocolError);
}

// ---------------------------------------------------------------- addresses

TEST(Address, PathsAndUnixPrefix) {
  Address a = parse_address("/run/tofmat/tofmatd.sock");
  EXPECT_FALSE(a.tcp);
  EXPECT_EQ(a.path, "/run/tofmat/tofmatd.sock");
  EXPECT_EQ(a.describe(), "/run/tofmat/tofmatd.sock");
  a = parse_address("tofmatd.sock");
  EXPECT_FALSE(a.tcp);
  EXPECT_EQ(a.path, "tofmatd.sock");
  a = parse_address("unix:/tmp/with:colon");
  EXPECT_FALSE(a.tcp);
  EXPECT_EQ(a.path, "/tmp/with:colon");
  a = parse_address("unix:relative:1");
  EXPECT_FALSE(a.tcp);
  EXPECT_EQ(a.path, "relative:1");
  // A slash makes it a path even with a colon.
  a = parse_address("./sock:1");
  EXPECT_FALSE(a.tcp);
  EXPECT_EQ(a.path, "./sock:1");
  EXPECT_THROW(parse_address(""), std::invalid_argument);
  EXPECT_THROW(parse_address("unix:"), std::invalid_argument);
}

TEST(Address, HostAndPort) {
  Address a = parse_address("127.0.0.1:7700");
  EXPECT_TRUE(a.tcp);
  EXPECT_EQ(a.host, "127.0.0.1");
  EXPECT_EQ(a.port, 7700);
  EXPECT_EQ(a.describe(), "127.0.0.1:7700");
  a = parse_address("localhost:1");
  EXPECT_TRUE(a.tcp);
  EXPECT_EQ(a.host, "localhost");
  EXPECT_EQ(a.port, 1);
  a = parse_address(":65535");
  EXPECT_TRUE(a.tcp);
  EXPECT_EQ(a.host, "127.0.0.1");  // no host: loopback
  EXPECT_EQ(a.port, 65535);
  for (const char* bad : {"host:", "host:0", "host:65536", "host:99999999999999999999", "host:-1", "host:abc",
                          "host:12x", "a:b:c", "host:1.5"}) {
    SCOPED_TRACE(bad);
    EXPECT_THROW(parse_address(bad), std::invalid_argument);
  }
}

TEST(Sockets, AUnixClientWaitsForAFullBacklogUntilItsTimeout) {
  // A Unix connect with the listener's backlog full: the server is busy (or
  // paces its accepts, as tofmatd does under a connect loop), not gone.
  // connect_to waits for room until its timeout, then fails with ETIMEDOUT;
  // never a socket that was not connected.
  char tmpl[] = "/tmp/tofmat-backlog-XXXXXX";
  ASSERT_NE(::mkdtemp(tmpl), nullptr);
  const std::string path = std::string(tmpl) + "/s.sock";
  Fd server(::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0));
  sockaddr_un sa{};
  sa.sun_family = AF_UNIX;
  std::strncpy(sa.sun_path, path.c_str(), sizeof sa.sun_path - 1);
  ASSERT_EQ(::bind(server.get(), reinterpret_cast<const sockaddr*>(&sa), sizeof sa), 0);
  ASSERT_EQ(::listen(server.get(), 0), 0);
  std::vector<Fd> queued;  // fill the backlog: connections nobody accepts
  for (int k = 0; k < 8; ++k) {
    Fd c(::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0));
    if (::connect(c.get(), reinterpret_cast<const sockaddr*>(&sa), sizeof sa) != 0) break;
    queued.push_back(std::move(c));
  }
  ASSERT_FALSE(queued.empty());
  const auto t0 = std::chrono::steady_clock::now();
  try {
    connect_to(parse_address(path), 200);
    ADD_FAILURE() << "connected to a full backlog";
  } catch (const SocketError& e) {
    EXPECT_EQ(e.os_error(), ETIMEDOUT) << e.what();
  }
  EXPECT_GE(std::chrono::steady_clock::now() - t0, std::chrono::milliseconds(200));
  // Room made while it waits: it connects, to a connection the server accepts.
  std::thread server_side([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    for (std::size_t k = 0; k < queued.size(); ++k) Fd(::accept(server.get(), nullptr, nullptr));
  });
  Fd c = connect_to(parse_address(path), 5000);
  server_side.join();
  Fd accepted(::accept(server.get(), nullptr, nullptr));
  EXPECT_TRUE(accepted);
  const char byte = 'x';
  EXPECT_EQ(::send(c.get(), &byte, 1, MSG_NOSIGNAL), 1);
  char got = 0;
  EXPECT_EQ(::recv(accepted.get(), &got, 1, 0), 1);
  EXPECT_EQ(got, 'x');
  std::filesystem::remove_all(tmpl);
}

}  // namespace
