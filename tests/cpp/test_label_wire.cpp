// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// protocol::encode_label_wire, the label event written without a JSON tree:
// byte for byte what encode(encode_label(e)) writes, for every optional field
// present and absent, for the doubles the float formatter treats specially,
// for strings that need escaping or hold UTF-8 (valid or not), and for
// thousands of random events; and what it writes decodes to the event.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "tofmat/protocol/messages.hpp"
#include "tofmat/protocol/wire.hpp"

namespace {

using namespace tofmat::protocol;

std::vector<std::uint8_t> tree_bytes(const LabelEvent& e) { return encode(encode_label(e)); }

std::string as_text(const std::vector<std::uint8_t>& b) { return std::string(b.begin(), b.end()); }

void expect_same_bytes(const LabelEvent& e) {
  const auto want = tree_bytes(e);
  const auto got = encode_label_wire(e);
  EXPECT_EQ(as_text(got), as_text(want));  // (text, so a failure shows where they part)
}

LabelEvent full() {
  LabelEvent e;
  e.frame = 18446744073709551615ULL;
  e.timestamp_ns = 1234567890123456789ULL;
  e.profile = "handheld";
  e.state = "tracking";
  e.material = "cork";
  e.index = 7;
  e.distance = 0.123456789012345678;
  e.valid = 4294967295u;
  e.bins_covered = 9;
  e.ranking = {{"cork", 0.5}, {"paper", 1.25}, {"wood", 3.0}, {"pvc", 1e-7}, {"alumi", 12345.678}};
  e.trigger = 42;
  e.truth = Truth{"cork", 901.5};
  e.simulated = true;
  e.confidence = 0.97;
  e.fit = -1.5;
  return e;
}

TEST(LabelWire, EveryOptionalFieldPresentAndAbsent) {
  const LabelEvent all = full();
  expect_same_bytes(all);
  for (int mask = 0; mask < 64; ++mask) {
    LabelEvent e = all;
    if (mask & 1) e.trigger.reset();
    if (mask & 2) e.truth.reset();
    if (mask & 4) e.simulated = false;
    if (mask & 8) e.confidence.reset();
    if (mask & 16) e.fit.reset();
    if (mask & 32) e.ranking.clear();
    expect_same_bytes(e);
  }
  LabelEvent none;  // no target: defaults, index -1, empty strings
  none.profile = "handheld";
  none.state = "no_target";
  expect_same_bytes(none);
  expect_same_bytes(LabelEvent{});
}

TEST(LabelWire, DoublesAsTheSerializerFormatsThem) {
  const double inf = std::numeric_limits<double>::infinity();
  const std::vector<double> values = {0.0,
                                      -0.0,
                                      1.0,
                                      -1.0,
                                      100.0,
                                      0.1,
                                      1.0 / 3.0,
                                      1e-5,
                                      1e-300,
                                      1e300,
                                      1e15,
                                      1e16,
                                      1e21,
                                      123456789012345678.0,
                                      std::numeric_limits<double>::denorm_min(),
                                      std::numeric_limits<double>::min(),
                                      std::numeric_limits<double>::max(),
                                      std::numeric_limits<double>::lowest(),
                                      std::numeric_limits<double>::epsilon(),
                                      inf,
                                      -inf,
                                      std::nan("")};
  for (const double v : values) {
    LabelEvent e = full();
    e.distance = v;
    e.confidence = v;
    e.fit = v;
    e.truth->depth_mm = v;
    e.ranking[2].distance = v;
    SCOPED_TRACE(v);
    expect_same_bytes(e);
  }
}

TEST(LabelWire, StringsThatNeedEscapingOrHoldUtf8) {
  const std::vector<std::string> names = {"",
                                          "a\"b",
                                          "back\\slash",
                                          "tab\there",
                                          "new\nline",
                                          std::string("nul\0byte", 8),
                                          "\x01\x1f",
                                          "del\x7f",
                                          "caf\xc3\xa9",                // valid UTF-8
                                          "\xe6\x9d\xbf",               // a CJK character
                                          "bad\xff utf8",               // invalid: replaced
                                          "cut\xc3",                    // truncated sequence
                                          std::string(64, 'x'),         // a name at its bound
                                          "/ slash and space {}[]:,"};  // JSON punctuation, not escaped
  for (const auto& s : names) {
    SCOPED_TRACE(as_text(std::vector<std::uint8_t>(s.begin(), s.end())));
    LabelEvent e = full();
    e.material = s;
    e.profile = s;
    e.state = s;
    e.ranking[0].material = s;
    e.truth->material = s;
    expect_same_bytes(e);
  }
}

TEST(LabelWire, RandomEventsByteForByteAndDecoded) {
  std::mt19937_64 rng(20261207);
  std::uniform_int_distribution<int> coin(0, 1);
  std::uniform_int_distribution<int> len(0, 12);
  std::uniform_int_distribution<int> byte(0x20, 0x7e);
  auto name = [&] {
    std::string s(static_cast<std::size_t>(len(rng)), ' ');
    for (auto& c : s) c = static_cast<char>(byte(rng));
    return s;
  };
  auto real = [&] {  // any bit pattern: NaNs, infinities, denormals and all
    const std::uint64_t bits = rng();
    double v;
    std::memcpy(&v, &bits, sizeof v);
    return coin(rng) ? v : std::ldexp(static_cast<double>(rng() % 1000000), static_cast<int>(rng() % 40) - 20);
  };
  for (int i = 0; i < 3000; ++i) {
    LabelEvent e;
    e.frame = rng();
    e.timestamp_ns = rng();
    e.profile = name();
    e.state = name();
    e.material = name();
    e.index = static_cast<std::int32_t>(rng() % 300) - 1;
    e.distance = real();
    e.valid = static_cast<std::uint32_t>(rng());
    e.bins_covered = static_cast<std::uint32_t>(rng() % 200);
    const std::size_t k = rng() % (kMaxRanking + 1);
    for (std::size_t j = 0; j < k; ++j) e.ranking.push_back({name(), real()});
    if (coin(rng)) e.trigger = rng();
    if (coin(rng)) e.truth = Truth{name(), real()};
    e.simulated = coin(rng) != 0;
    if (coin(rng)) e.confidence = real();
    if (coin(rng)) e.fit = real();
    const auto got = encode_label_wire(e);
    ASSERT_EQ(as_text(got), as_text(tree_bytes(e))) << "event " << i;
  }
  // What it writes is a label event the reader takes back field for field.
  const LabelEvent e = full();
  MessageReader reader;
  const auto bytes = encode_label_wire(e);
  reader.feed(bytes.data(), bytes.size());
  const auto m = reader.next();
  ASSERT_TRUE(m);
  EXPECT_EQ(reader.buffered(), 0u);
  const LabelEvent d = decode_label(*m);
  EXPECT_EQ(d.frame, e.frame);
  EXPECT_EQ(d.timestamp_ns, e.timestamp_ns);
  EXPECT_EQ(d.material, e.material);
  EXPECT_EQ(d.distance, e.distance);
  ASSERT_EQ(d.ranking.size(), e.ranking.size());
  EXPECT_EQ(d.ranking[3].distance, e.ranking[3].distance);
  EXPECT_EQ(d.trigger, e.trigger);
  EXPECT_EQ(d.truth->depth_mm, e.truth->depth_mm);
  EXPECT_EQ(d.confidence, e.confidence);
  EXPECT_EQ(d.fit, e.fit);
  EXPECT_TRUE(d.simulated);
}

TEST(LabelWire, RefusesWhatEncodeRefuses) {
  LabelEvent e = full();
  e.material = std::string(kMaxMetaBytes, 'x');  // the metadata over its bound
  EXPECT_THROW(tree_bytes(e), ProtocolError);
  EXPECT_THROW(encode_label_wire(e), ProtocolError);
}

}  // namespace
