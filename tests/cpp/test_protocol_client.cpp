// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The C++ client (firmware/protocol/client.hpp) against a scripted daemon on
// a socketpair: what it keeps while a command waits is bounded, a peer that
// never stops sending cannot hold a command past its timeout, a hello reply of
// another major is refused, and errors quoting the peer's bytes are printable.
#include <gtest/gtest.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <string>
#include <thread>
#include <vector>

#include "test_util.hpp"
#include "tofmat/protocol/client.hpp"
#include "tofmat/protocol/socket.hpp"
#include "tofmat/protocol/wire.hpp"

namespace {

using namespace tofmat::protocol;
using Bytes = std::vector<std::uint8_t>;
using Clock = std::chrono::steady_clock;

Bytes frame(MessageType type, const Json& meta, std::size_t blob_bytes = 0) {
  Message m;
  m.type = type;
  m.meta = meta;
  m.blob.assign(blob_bytes, 0);
  return encode(m);
}

// A frame whose metadata is the given bytes as they are (not necessarily JSON or UTF-8).
Bytes raw_frame(MessageType type, const std::string& meta) {
  Bytes out = {'T', 'M', 'A', 'T', 1, 0, static_cast<std::uint8_t>(type), 0};
  const auto put_u32 = [&](std::uint32_t v) {
    for (int i = 0; i < 4; ++i) out.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
  };
  put_u32(static_cast<std::uint32_t>(4 + meta.size()));
  put_u32(static_cast<std::uint32_t>(meta.size()));
  out.insert(out.end(), meta.begin(), meta.end());
  return out;
}

const Json kHello = {
    {"protocol", 1}, {"minor", 10}, {"server", "scripted"}, {"capabilities", Json::array()}, {"auth_required", false}};
const Json kHelloReply = {{"id", 1}, {"ok", true}, {"result", {{"protocol", 1}, {"minor", 10}, {"role", "control"}}}};

// The daemon's side of a socketpair, sending from a thread: first `script`, then `repeat` over
// and over until the client's side goes away or stop is set; it reads and drops what the client sends.
struct ScriptedDaemon {
  Fd daemon_side, client_side;
  std::atomic<bool> stop{false};
  std::atomic<std::uint64_t> repeats{0};
  std::thread sender, sink;

  ScriptedDaemon(Bytes script, Bytes repeat) {
    int ends[2];
    if (::socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, ends) != 0) throw std::runtime_error("socketpair");
    daemon_side = Fd(ends[0]);
    client_side = Fd(ends[1]);
    sender = std::thread([this, script = std::move(script), repeat = std::move(repeat)] {
      if (!send_all(script)) return;
      while (!repeat.empty() && !stop && send_all(repeat)) ++repeats;
    });
    sink = std::thread([this] {
      char buf[4096];
      while (::recv(daemon_side.get(), buf, sizeof buf, 0) > 0) {
      }
    });
  }
  ~ScriptedDaemon() {
    stop = true;
    ::shutdown(daemon_side.get(), SHUT_RDWR);
    sender.join();
    sink.join();
  }
  bool send_all(const Bytes& bytes) {
    std::size_t sent = 0;
    while (sent < bytes.size()) {
      const ssize_t n = ::send(daemon_side.get(), bytes.data() + sent, bytes.size() - sent, MSG_NOSIGNAL);
      if (n <= 0) return false;
      sent += static_cast<std::size_t>(n);
    }
    return true;
  }
};

Bytes concat(std::initializer_list<Bytes> parts) {
  Bytes out;
  for (const auto& p : parts) out.insert(out.end(), p.begin(), p.end());
  return out;
}

Address scripted_address() {
  Address a;
  a.path = "scripted";
  return a;
}

const Json kDepthEvent = {{"event", "depth"}, {"frame", 1}, {"timestamp_ns", 1}, {"kind", "combined"},
                          {"x0", 0},          {"y0", 0},    {"width", 512},      {"height", 424}};

TEST(ProtocolClient, EventsThatNeverEndCannotGrowTheClientOrHoldACommandPastItsTimeout) {
  // A "daemon" that answers the hello, then streams 868 KB depth events and never answers "status".
  ScriptedDaemon d(concat({frame(MessageType::kHello, kHello), frame(MessageType::kReply, kHelloReply)}),
                   frame(MessageType::kEvent, kDepthEvent, 512 * 424 * 4));
  ClientOptions o;
  o.timeout_ms = 1500;
  o.max_pending_bytes = 8u << 20;  // (about 10 of the images: reached under qemu and the sanitizers too)
  Client c(std::move(d.client_side), scripted_address(), o);
  const auto t0 = Clock::now();
  try {
    (void)c.request("status");
    FAIL() << "a status nobody answers must time out";
  } catch (const ClientError& e) {
    EXPECT_EQ(e.kind(), ClientErrorKind::kTimeout) << e.what();
  }
  const double waited = std::chrono::duration<double>(Clock::now() - t0).count();
  EXPECT_LT(waited, 4.0) << "the flood held the command past its 1.5 s timeout";
  EXPECT_GT(d.repeats.load(), 10u) << "the scripted daemon did not send past the bound";
  EXPECT_LE(c.pending_bytes(), o.max_pending_bytes);
  EXPECT_GE(c.pending_events(), 1u);
  EXPECT_GT(c.dropped_events(), 0u);
  // What was kept is handed out, oldest first, and the count goes down with it.
  const std::size_t kept = c.pending_events();
  ASSERT_TRUE(c.next_event(0).has_value());
  EXPECT_EQ(c.pending_events(), kept - 1);
}

TEST(ProtocolClient, TheEventCountIsBoundedToo) {
  const Json label = {{"event", "reset"}, {"by", "command"}, {"timestamp_ns", 1}};
  ScriptedDaemon d(concat({frame(MessageType::kHello, kHello), frame(MessageType::kReply, kHelloReply)}),
                   frame(MessageType::kEvent, label));
  ClientOptions o;
  o.timeout_ms = 1000;
  o.max_pending_events = 100;
  Client c(std::move(d.client_side), scripted_address(), o);
  EXPECT_THROW((void)c.request("status"), ClientError);
  EXPECT_EQ(c.pending_events(), 100u);
  EXPECT_GT(c.dropped_events(), 0u);
}

TEST(ProtocolClient, RepliesNobodyWaitsForDoNotHoldAnEventWaitPastItsTimeout) {
  const Json stray = {{"id", 77}, {"ok", true}, {"result", Json::object()}};
  ScriptedDaemon d(concat({frame(MessageType::kHello, kHello), frame(MessageType::kReply, kHelloReply)}),
                   frame(MessageType::kReply, stray));
  ClientOptions o;
  o.timeout_ms = 1000;
  Client c(std::move(d.client_side), scripted_address(), o);
  const auto t0 = Clock::now();
  EXPECT_FALSE(c.next_event(500).has_value());
  EXPECT_LT(std::chrono::duration<double>(Clock::now() - t0).count(), 3.0);
}

TEST(ProtocolClient, AHelloReplyOfAnotherMajorIsRefused) {
  for (const Json& claimed : {Json(99), Json("1"), Json(-1), Json(1.5)}) {
    const Json reply = {{"id", 1}, {"ok", true}, {"result", {{"protocol", claimed}}}};
    ScriptedDaemon d(concat({frame(MessageType::kHello, kHello), frame(MessageType::kReply, reply)}), {});
    try {
      Client c(std::move(d.client_side), scripted_address(), ClientOptions{});
      FAIL() << "a hello reply claiming protocol " << claimed.dump() << " was accepted";
    } catch (const ClientError& e) {
      EXPECT_EQ(e.kind(), ClientErrorKind::kVersion) << e.what();
      EXPECT_CONTAINS(e.what(), "protocol version");
    }
  }
}

TEST(ProtocolClient, ErrorsQuotingThePeersBytesArePrintable) {
  // Metadata that is not UTF-8: the parser's message quotes it; the client's error escapes it.
  ScriptedDaemon d(
      concat({frame(MessageType::kHello, kHello), frame(MessageType::kReply, kHelloReply),
              raw_frame(MessageType::kReply, "{\"id\":2,\"ok\":true,\"result\":{\"x\":\"\xff\xfe\x1b[2J\"}}")}),
      {});
  Client c(std::move(d.client_side), scripted_address(), ClientOptions{});
  try {
    (void)c.request("status");
    FAIL() << "metadata that is not UTF-8 was accepted";
  } catch (const ClientError& e) {
    EXPECT_EQ(e.kind(), ClientErrorKind::kProtocol);
    for (const char ch : std::string(e.what())) {
      const auto b = static_cast<unsigned char>(ch);
      EXPECT_TRUE(b >= 0x20 && b < 0x7f) << "byte " << int(b) << " in: " << e.what();
    }
  }
}

TEST(ProtocolClient, ACommandErrorsTextIsEscaped) {
  const Json reply = {{"id", 2}, {"ok", false}, {"code", "failed"}, {"error", "no\x1b[31m red\nline"}};
  ScriptedDaemon d(concat({frame(MessageType::kHello, kHello), frame(MessageType::kReply, kHelloReply),
                           frame(MessageType::kReply, reply)}),
                   {});
  Client c(std::move(d.client_side), scripted_address(), ClientOptions{});
  try {
    (void)c.request("status");
    FAIL();
  } catch (const ClientError& e) {
    EXPECT_EQ(e.kind(), ClientErrorKind::kCommand);
    EXPECT_EQ(std::string(e.what()), "status: no\\x1b[31m red\\x0aline");
  }
}

TEST(Printable, KeepsPrintableAsciiAndEscapesTheRest) {
  EXPECT_EQ(printable("cork 900 mm"), "cork 900 mm");
  EXPECT_EQ(printable(std::string("a\0b", 3)), "a\\x00b");
  EXPECT_EQ(printable("\xff\x7f\\"), "\\xff\\x7f\\x5c");
}

}  // namespace
