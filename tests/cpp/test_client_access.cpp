// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// ClientAccess (firmware/daemon/client_access.hpp): tofmatd's roles, slots
// and token throttling, without sockets (the server tests run them over real
// ones).
#include <gtest/gtest.h>
#include <unistd.h>

#include <string>

#include "tofmat/daemon/client_access.hpp"

namespace {

using tofmat::daemon::AccessOptions;
using tofmat::daemon::ClientAccess;
using tofmat::daemon::Peer;
using tofmat::daemon::RateBucket;
using tofmat::daemon::Role;
using Verdict = ClientAccess::Verdict;

constexpr std::uint64_t kMs = 1'000'000ull;

Peer unix_peer(uid_t uid, gid_t gid = 100) {
  Peer p;
  p.uid = uid;
  p.gid = gid;
  return p;
}
Peer tcp_peer(const std::string& address) {
  Peer p;
  p.tcp = true;
  p.address = address;
  return p;
}

AccessOptions options() {
  AccessOptions o;
  o.max_unix = 5;
  o.max_tcp = 3;
  o.max_per_peer = 2;
  o.read_token = "read-token-0123456789";
  o.control_token = "control-token-0123456789";
  o.owner_uid = 4242;
  return o;
}

TEST(ClientAccess, ReadingAndControlCommands) {
  for (const char* cmd : {"hello", "subscribe", "unsubscribe", "status", "server_status"})
    EXPECT_TRUE(tofmat::daemon::is_reading_command(cmd)) << cmd;
  for (const char* cmd : {"set_profile", "set_roi", "set_candidates", "trigger", "reset", "load_table", "", "x"})
    EXPECT_FALSE(tofmat::daemon::is_reading_command(cmd)) << cmd;
}

TEST(ClientAccess, SlotsPerKindAndPerPeer) {
  ClientAccess a(options());
  EXPECT_EQ(a.admit(unix_peer(1), Role::kControl), "");
  EXPECT_EQ(a.admit(unix_peer(1), Role::kControl), "");
  EXPECT_NE(a.admit(unix_peer(1), Role::kControl).find("uid 1 has 2"), std::string::npos);  // its share
  EXPECT_EQ(a.admit(unix_peer(2), Role::kControl), "");
  EXPECT_EQ(a.admit(unix_peer(2), Role::kControl), "");
  EXPECT_EQ(a.admit(unix_peer(3), Role::kControl), "");
  EXPECT_NE(a.admit(unix_peer(4), Role::kControl).find("5 Unix clients"), std::string::npos);  // the Unix slots
  // TCP counts apart: the Unix slots are full, TCP's are not.
  EXPECT_EQ(a.admit(tcp_peer("10.0.0.1"), Role::kRead), "");
  EXPECT_EQ(a.admit(tcp_peer("10.0.0.1"), Role::kRead), "");
  EXPECT_NE(a.admit(tcp_peer("10.0.0.1"), Role::kRead), "");
  EXPECT_EQ(a.admit(tcp_peer("10.0.0.2"), Role::kRead), "");
  EXPECT_NE(a.admit(tcp_peer("10.0.0.3"), Role::kRead).find("3 TCP clients"), std::string::npos);
  EXPECT_EQ(a.unix_clients(), 5u);
  EXPECT_EQ(a.tcp_clients(), 3u);
  // Released slots come back, to the peer and the kind.
  a.release(unix_peer(1), Role::kControl);
  EXPECT_EQ(a.unix_clients(), 4u);
  EXPECT_EQ(a.admit(unix_peer(1), Role::kControl), "");
  a.release(tcp_peer("10.0.0.2"), Role::kRead);
  EXPECT_EQ(a.admit(tcp_peer("10.0.0.3"), Role::kRead), "");
}

TEST(ClientAccess, ReadersLeaveTheLastUnixSlotsToControl) {
  // (issue 33) Local users who may only read cannot hold every Unix slot: the daemon's own user,
  // root and the control group always find one.
  AccessOptions o = options();
  o.max_unix = 64;
  o.max_per_peer = 16;
  ClientAccess a(o);
  EXPECT_EQ(a.control_reserve(), 4u);
  for (uid_t uid = 1; uid <= 4; ++uid)
    for (int i = 0; i < 16; ++i) {
      const std::string why = a.admit(unix_peer(uid), Role::kRead);
      if (uid < 4 || i < 12) {
        EXPECT_EQ(why, "") << uid << " " << i;
      } else {
        EXPECT_NE(why.find("kept for control"), std::string::npos) << why;
      }
    }
  EXPECT_EQ(a.unix_readers(), 60u);
  for (int i = 0; i < 4; ++i) EXPECT_EQ(a.admit(unix_peer(4242), Role::kControl), "");
  EXPECT_NE(a.admit(unix_peer(4242), Role::kControl).find("64 Unix clients"), std::string::npos);
  // A reader that leaves frees a reader's slot; control's are still control's.
  a.release(unix_peer(1), Role::kRead);
  EXPECT_EQ(a.unix_readers(), 59u);
  EXPECT_EQ(a.admit(unix_peer(5), Role::kRead), "");
  EXPECT_NE(a.admit(unix_peer(6), Role::kRead), "");
  // Small limits keep a share for each: 2 slots, 1 for control; 1 slot, none kept.
  o.max_unix = 2;
  ClientAccess two(o);
  EXPECT_EQ(two.admit(unix_peer(1), Role::kRead), "");
  EXPECT_NE(two.admit(unix_peer(2), Role::kRead), "");
  EXPECT_EQ(two.admit(unix_peer(4242), Role::kControl), "");
  o.max_unix = 1;
  ClientAccess one(o);
  EXPECT_EQ(one.admit(unix_peer(1), Role::kRead), "");
}

TEST(ClientAccess, TcpReadersLeaveTheLastSlotsToTheControlToken) {
  AccessOptions o = options();
  o.max_tcp = 16;
  ClientAccess a(o);  // (a control token is set)
  for (int i = 0; i < 12; ++i) EXPECT_EQ(a.admit_tcp_reader(), "") << i;
  EXPECT_NE(a.admit_tcp_reader().find("kept for the control token"), std::string::npos);
  EXPECT_EQ(a.tcp_readers(), 12u);
  a.release_tcp_reader();
  EXPECT_EQ(a.admit_tcp_reader(), "");
  // Without a control token nobody controls over TCP: readers may take every slot.
  o.control_token.clear();
  ClientAccess none(o);
  for (int i = 0; i < 16; ++i) EXPECT_EQ(none.admit_tcp_reader(), "") << i;
}

TEST(ClientAccess, UnixRoles) {
  AccessOptions o = options();
  ClientAccess a(o);
  EXPECT_EQ(a.unix_role(unix_peer(4242)), Role::kControl);  // the daemon's user
  EXPECT_EQ(a.unix_role(unix_peer(0)), Role::kControl);     // root
  EXPECT_EQ(a.unix_role(unix_peer(1000, 555)), Role::kRead);
  o.control_gid = 555;
  ClientAccess g(o);
  EXPECT_EQ(g.unix_role(unix_peer(1000, 555)), Role::kControl);  // its primary group
  EXPECT_EQ(g.unix_role(unix_peer(1000, 556)), Role::kRead);
}

TEST(ClientAccess, SupplementaryGroupsCount) {
  // root (uid 0) is in the database everywhere; its primary group is 0.
  EXPECT_TRUE(tofmat::daemon::user_in_group(0, 0, 0));
  EXPECT_FALSE(tofmat::daemon::user_in_group(0, 0, 54321));
  // A uid with no entry has only the primary group it connected with.
  EXPECT_FALSE(tofmat::daemon::user_in_group(987654, 987654, 0));
  EXPECT_TRUE(tofmat::daemon::user_in_group(987654, 987654, 987654));
}

TEST(ClientAccess, TokensGiveTheirRoles) {
  ClientAccess a(options());
  std::uint64_t wait = 0;
  EXPECT_EQ(a.check_token("1.2.3.4", "read-token-0123456789", 0, wait), Verdict::kRead);
  EXPECT_EQ(a.check_token("1.2.3.4", "control-token-0123456789", 0, wait), Verdict::kControl);
  EXPECT_EQ(a.check_token("1.2.3.5", "", 0, wait), Verdict::kWrong);
  AccessOptions no_control = options();
  no_control.control_token.clear();
  ClientAccess b(no_control);
  EXPECT_EQ(b.check_token("1.2.3.4", "", 0, wait), Verdict::kWrong);  // an empty token never matches an empty one
}

TEST(ClientAccess, EachWrongTokenDoublesTheWait) {
  ClientAccess a(options());
  std::uint64_t now = 1'000 * kMs, wait = 0;
  std::uint64_t expected = ClientAccess::kFirstDelayMs;
  for (int k = 0; k < 12; ++k) {
    SCOPED_TRACE(k);
    ASSERT_EQ(a.check_token("1.2.3.4", "guess", now, wait), Verdict::kWrong);
    // Until the wait is over nothing is looked at, not even the right token.
    EXPECT_EQ(a.check_token("1.2.3.4", "read-token-0123456789", now + 1, wait), Verdict::kThrottled);
    EXPECT_EQ(wait, expected);
    EXPECT_EQ(a.check_token("1.2.3.4", "guess", now + expected * kMs - kMs, wait), Verdict::kThrottled);
    // Other addresses are not held up.
    EXPECT_EQ(a.check_token("5.6.7.8", "read-token-0123456789", now + 1, wait), Verdict::kRead);
    now += expected * kMs;
    expected = std::min(expected * 2, ClientAccess::kMaxDelayMs);
  }
  EXPECT_EQ(expected, ClientAccess::kMaxDelayMs);  // (the cap was reached)
  // The right token after the wait clears the count: the next wrong one waits the first delay again.
  EXPECT_EQ(a.check_token("1.2.3.4", "read-token-0123456789", now, wait), Verdict::kRead);
  EXPECT_EQ(a.check_token("1.2.3.4", "guess", now, wait), Verdict::kWrong);
  EXPECT_EQ(a.check_token("1.2.3.4", "guess", now + 1, wait), Verdict::kThrottled);
  EXPECT_EQ(wait, ClientAccess::kFirstDelayMs);
}

TEST(ClientAccess, ALongQuietForgetsTheFailures) {
  ClientAccess a(options());
  std::uint64_t now = 0, wait = 0;
  for (int k = 0; k < 5; ++k) {
    a.check_token("1.2.3.4", "guess", now, wait);
    now += 60'000 * kMs;
  }
  now += 3'600'000 * kMs;  // an hour later
  EXPECT_EQ(a.check_token("1.2.3.4", "guess", now, wait), Verdict::kWrong);
  EXPECT_EQ(a.check_token("1.2.3.4", "guess", now + 1, wait), Verdict::kThrottled);
  EXPECT_EQ(wait, ClientAccess::kFirstDelayMs);
}

TEST(ClientAccess, RemembersABoundedNumberOfAddresses) {
  ClientAccess a(options());
  std::uint64_t wait = 0;
  for (std::size_t k = 0; k < ClientAccess::kMaxThrottled + 500; ++k)
    a.check_token(
        "10." + std::to_string(k / 65536) + "." + std::to_string(k / 256 % 256) + "." + std::to_string(k % 256),
        "guess", k, wait);
  EXPECT_LE(a.throttled_addresses(), ClientAccess::kMaxThrottled);
  EXPECT_GT(a.throttled_addresses(), ClientAccess::kMaxThrottled / 2);
}

TEST(ClientAccess, RequestsAtThePeersRate) {
  AccessOptions o = options();
  o.requests_per_second = 100;
  ClientAccess a(o);
  const Peer flooder = unix_peer(1), other = unix_peer(2);
  std::uint64_t now = 5'000 * kMs, wait = 0;
  int taken = 0;
  while (a.may_request(flooder, now, wait)) {
    a.count_request(flooder);
    ++taken;
  }
  EXPECT_EQ(taken, 100);          // the burst: a second's worth
  EXPECT_EQ(wait, 10 * kMs + 1);  // then one every 10 ms
  EXPECT_FALSE(a.may_request(flooder, now + 9 * kMs, wait));
  EXPECT_TRUE(a.may_request(flooder, now + 10 * kMs, wait));
  EXPECT_TRUE(a.may_request(other, now, wait));  // every peer has its own
  // Over a minute of trying as fast as it can, the rate holds.
  taken = 0;
  for (std::uint64_t t = now; t < now + 60'000 * kMs; t += kMs)
    if (a.may_request(flooder, t, wait)) {
      a.count_request(flooder);
      ++taken;
    }
  EXPECT_NEAR(taken, 6000, 2);
}

TEST(ClientAccess, ConnectionsAtThePeersRate) {
  AccessOptions o = options();
  o.connects_per_second = 10;
  ClientAccess a(o);
  const std::uint64_t now = 5'000 * kMs;
  int taken = 0;
  for (int k = 0; k < 100; ++k) taken += a.take_connect(tcp_peer("10.0.0.9"), now) ? 1 : 0;
  EXPECT_EQ(taken, 20);  // twice the rate at once
  EXPECT_FALSE(a.take_connect(tcp_peer("10.0.0.9"), now + 99 * kMs));
  EXPECT_TRUE(a.take_connect(tcp_peer("10.0.0.9"), now + 100 * kMs));
  EXPECT_TRUE(a.take_connect(tcp_peer("10.0.0.10"), now));
  EXPECT_TRUE(a.take_connect(unix_peer(7), now));
}

TEST(RateBucket, StartsFullRefillsAtItsRateAndSaysHowLongToWait) {
  RateBucket b;
  const std::uint64_t now = 7'000 * kMs;
  ASSERT_TRUE(b.refill(100, 4, now));  // full: 4 at once
  EXPECT_EQ(b.wait_ns(100), 0u);
  b.tokens -= 4;
  EXPECT_FALSE(b.refill(100, 4, now));
  EXPECT_NEAR(static_cast<double>(b.wait_ns(100)), 10.0 * kMs, 1.0);  // one in 1/100 s
  EXPECT_FALSE(b.refill(100, 4, now + 9 * kMs));
  EXPECT_TRUE(b.refill(100, 4, now + 10 * kMs));
  b.tokens -= 1;
  EXPECT_FALSE(b.refill(100, 4, now)) << "an earlier time does not refill it again";
  EXPECT_TRUE(b.refill(100, 4, now + 10'000 * kMs));
  EXPECT_DOUBLE_EQ(b.tokens, 4.0) << "never more than the burst";
}

TEST(ClientAccess, RememberedRatesAreBounded) {
  ClientAccess a(options());
  for (std::size_t k = 0; k < ClientAccess::kMaxThrottled + 100; ++k)
    a.take_connect(unix_peer(static_cast<uid_t>(k)), k * kMs);
  EXPECT_LE(a.rated_peers(), ClientAccess::kMaxThrottled);
}

}  // namespace
