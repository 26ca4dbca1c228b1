// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The Kinect v2 command protocol codec (firmware/kinect/command.hpp) against
// the documented layouts (shared/docs/kinect2-protocol.md 1.4-1.6, 3.1).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <vector>

#include "test_util.hpp"
#include "tofmat/core/error.hpp"
#include "tofmat/kinect/command.hpp"

namespace {

using namespace tofmat::kinect;
using Bytes = std::vector<std::uint8_t>;

std::uint32_t word(const Bytes& b, std::size_t k) {
  return static_cast<std::uint32_t>(b[4 * k]) | (static_cast<std::uint32_t>(b[4 * k + 1]) << 8) |
         (static_cast<std::uint32_t>(b[4 * k + 2]) << 16) | (static_cast<std::uint32_t>(b[4 * k + 3]) << 24);
}

template <typename F>
std::string format_error(F&& f) {
  try {
    f();
  } catch (const tofmat::FormatError& e) {
    return e.what();
  }
  return {};
}

TEST(Command, EncodesTheDocumentedWords) {
  const Bytes b = encode_command(cmd_read_data_page(kPageP0Tables), 7);
  ASSERT_EQ(b.size(), 24u);
  EXPECT_EQ(word(b, 0), 0x06022009u);
  EXPECT_EQ(word(b, 1), 7u);
  EXPECT_EQ(word(b, 2), 0x1C0000u);
  EXPECT_EQ(word(b, 3), 0x22u);
  EXPECT_EQ(word(b, 4), 0u);
  EXPECT_EQ(word(b, 5), 2u);
  EXPECT_EQ(encode_command(cmd_init_streams(), 1).size(), 20u);
  const Bytes m = encode_command(cmd_set_mode(true, 0x00640064), 9);
  ASSERT_EQ(m.size(), 36u);
  EXPECT_EQ(word(m, 3), 0x4Bu);
  EXPECT_EQ(word(m, 5), 1u);
  EXPECT_EQ(word(m, 6), 0x00640064u);
  EXPECT_EQ(encode_command(cmd_read_data_page(kPageSerial), 0).at(8), 0x80);
  EXPECT_EQ(word(encode_command(cmd_read_status(), 0), 5), 0x090000u);
  EXPECT_EQ(word(encode_command(cmd_read_firmware_versions(), 0), 2), 0x200u);
  EXPECT_THROW(encode_command(Command{CommandId::kSetMode, 0, {1, 2}}, 0), std::invalid_argument);
}

TEST(Command, DecodeIsTheInverseAndRejectsWrongSizesAndMagic) {
  for (const Command& c : {cmd_read_data_page(3), cmd_init_streams(), cmd_set_mode(false)}) {
    const Bytes b = encode_command(c, 4242);
    const DecodedCommand d = decode_command(b.data(), b.size());
    EXPECT_EQ(d.sequence, 4242u);
    EXPECT_EQ(d.id, static_cast<std::uint32_t>(c.id));
    EXPECT_EQ(d.max_response, c.max_response);
    EXPECT_EQ(d.params, c.params);
  }
  Bytes b = encode_command(cmd_init_streams(), 1);
  EXPECT_CONTAINS(format_error([&] { decode_command(b.data(), 19); }), "20, 24 or 36");
  b[0] ^= 1;
  EXPECT_CONTAINS(format_error([&] { decode_command(b.data(), b.size()); }), "magic");
}

TEST(Completion, RoundTripAndChecks) {
  const Bytes c = encode_completion(99);
  ASSERT_EQ(c.size(), 16u);
  EXPECT_EQ(word(c, 0), 0x0A6FE000u);
  EXPECT_EQ(parse_completion(c.data(), c.size()).sequence, 99u);
  EXPECT_TRUE(looks_like_completion(c.data(), c.size()));
  EXPECT_CONTAINS(format_error([&] { parse_completion(c.data(), 15); }), "16");
  Bytes bad = c;
  bad[3] = 0;
  EXPECT_CONTAINS(format_error([&] { parse_completion(bad.data(), bad.size()); }), "magic");
  EXPECT_FALSE(looks_like_completion(bad.data(), bad.size()));
  const Bytes status{1, 0, 0, 0};
  EXPECT_FALSE(looks_like_completion(status.data(), status.size()));
}

TEST(Responses, FirmwareVersionsSerialStatus) {
  Bytes fw(16 * 8, 0);
  const auto put = [&](std::size_t off, std::uint32_t v) { std::memcpy(fw.data() + off, &v, 4); };
  put(3 * 16, (2u << 16) | 3u);
  put(3 * 16 + 4, 4);
  put(3 * 16 + 8, 5);
  const auto v = parse_firmware_versions(fw.data(), fw.size());
  ASSERT_EQ(v.size(), 7u);  // at most 7 records are read
  EXPECT_EQ(v[3].to_string(), "2.3.4.5");
  EXPECT_CONTAINS(format_error([&] { parse_firmware_versions(fw.data(), 15); }), "16-byte");
  EXPECT_EQ(parse_firmware_versions(fw.data(), 20).size(), 1u);

  const Bytes serial{'5', 0, '0', 0, '1', 0, 0, 0, 'x', 0};
  EXPECT_EQ(parse_serial(serial.data(), serial.size()), "501");
  EXPECT_EQ(parse_serial(serial.data(), 3), "50");  // odd length: bounded by the size
  const Bytes empty{0, 0};
  EXPECT_CONTAINS(format_error([&] { parse_serial(empty.data(), empty.size()); }), "empty");
  const Bytes binary{'a', 0, 7, 0};
  EXPECT_CONTAINS(format_error([&] { parse_serial(binary.data(), binary.size()); }), "printable");

  const Bytes st{0x01, 0x00, 0x00, 0x00};
  EXPECT_EQ(parse_status(st.data(), st.size()), 1u);
  EXPECT_CONTAINS(format_error([&] { parse_status(st.data(), 3); }), '4');
}

TEST(Responses, DepthParamsRoundTripAndValidate) {
  DepthParams p;
  p.fx = 365.5f;
  p.fy = 365.25f;
  p.cx = 255.5f;
  p.cy = 211.75f;
  p.k1 = 0.09f;
  p.k2 = -0.27f;
  p.k3 = 0.1f;
  const Bytes b = encode_depth_params(p);
  ASSERT_EQ(b.size(), kDepthParamsBytes);
  const DepthParams q = parse_depth_params(b.data(), b.size());
  EXPECT_EQ(q.fx, p.fx);
  EXPECT_EQ(q.cy, p.cy);
  EXPECT_EQ(q.k2, p.k2);
  EXPECT_CONTAINS(format_error([&] { parse_depth_params(b.data(), 91); }), "92");
  Bytes nan = b;
  const float bad = std::nanf("");
  std::memcpy(nan.data(), &bad, 4);
  EXPECT_CONTAINS(format_error([&] { parse_depth_params(nan.data(), nan.size()); }), "finite");
  Bytes zero = b;
  std::memset(zero.data(), 0, 4);
  EXPECT_CONTAINS(format_error([&] { parse_depth_params(zero.data(), zero.size()); }), "focal");
  for (float DepthParams::*field :
       {&DepthParams::k1, &DepthParams::k2, &DepthParams::k3, &DepthParams::p1, &DepthParams::p2}) {
    DepthParams wild = p;
    wild.*field = 10.5f;
    const Bytes w = encode_depth_params(wild);
    EXPECT_CONTAINS(format_error([&] { parse_depth_params(w.data(), w.size()); }), "distortion");
    wild.*field = -10.0f;  // at the bound: kept
    EXPECT_NO_THROW(check_depth_params(wild));
  }
}

TEST(Responses, P0TablesLayoutAndPhase) {
  P0Tables t;
  for (std::size_t g = 0; g < 3; ++g) {
    t.raw[g].resize(512 * 424);
    for (std::size_t i = 0; i < t.raw[g].size(); ++i) t.raw[g][i] = static_cast<std::uint16_t>(i * (g + 1) + 11);
  }
  const Bytes b = encode_p0_tables(t);
  ASSERT_EQ(b.size(), 1302572u);
  // Table k starts at byte 34 + 434,180 k.
  for (std::size_t k = 0; k < 3; ++k) {
    const std::size_t off = 34 + 434180 * k;
    EXPECT_EQ(b[off] | (b[off + 1] << 8), t.raw[k][0]) << k;
  }
  const P0Tables back = parse_p0_tables(b.data(), b.size());
  for (std::size_t g = 0; g < 3; ++g) EXPECT_EQ(back.raw[g], t.raw[g]);
  const auto p0 = back.p0_rad();
  EXPECT_FLOAT_EQ(p0[512 * 424 + 5], static_cast<float>(-(5.0 * 2 + 11) * 0.000031 * M_PI));
  EXPECT_CONTAINS(format_error([&] { parse_p0_tables(b.data(), b.size() - 1); }), "1302572");

  // p0_table_value inverts p0 = -P0 * 0.000031 pi within half a step, wrapping any phase.
  for (double want : {0.0, -0.5, -3.0, -6.2, 0.7, 12.0, -100.0}) {
    const double got = -p0_table_value(want) * 0.000031 * M_PI;
    EXPECT_NEAR(std::remainder(got - want, 2 * M_PI), 0.0, 0.5 * 0.000031 * M_PI + 1e-12) << want;
  }
}

}  // namespace
