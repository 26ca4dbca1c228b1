// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Who a client of tofmatd is and what it may do (issue 16): its peer (the
// uid behind a Unix connection, from SO_PEERCRED; the address of a TCP one),
// its role, the connection slots it may hold, and how often a TCP address
// may try a token.
//
// Roles: every client may read (subscribe, status); what changes what every
// other client gets (profile, ROI, candidates, trigger, reset, load_table)
// needs control. On the Unix socket control is the daemon's own user, root,
// and the members of the control group when one is configured; on TCP it is
// the control token (the shared token reads only).
//
// Slots: Unix and TCP have separate counts, so connections nobody
// authenticated cannot take the local clients' places, and every peer has
// its own bound within them. The last few Unix slots are kept for control
// (control_reserve()): however many local users connect to read, the
// daemon's own user, root and the control group can still get in. On TCP
// the role is known at the hello: with a control token, a reading hello
// past max_tcp less the same reserve is refused, so the control token gets in.
//
// Rates: every peer has a bucket of requests and one of new connections
// (a rate per second, and as many at once), so that one user or address
// flooding requests or connecting in a loop takes a bounded share of the
// server thread whatever it does.
//
// Tokens: each wrong token from an address doubles the time that address
// must wait before its next token is looked at (refused unchecked until
// then), from kFirstDelayMs up to kMaxDelayMs; a right token clears it.
#pragma once
#include <sys/types.h>

#include <cstddef>
#include <cstdint>
#include <map>
#include <string>

namespace tofmat::daemon {

enum class Role { kRead, kControl };
const char* role_name(Role role);

// The commands a reading client may send; any other needs control.
bool is_reading_command(const std::string& cmd);

struct Peer {
  bool tcp = false;
  uid_t uid = 0;  // Unix
  gid_t gid = 0;
  std::string address;      // TCP: the remote IPv4 address
  std::string key() const;  // what per-peer limits count by: "uid 1000", "tcp 10.0.0.5"
};
// The peer of a connected socket (SO_PEERCRED or getpeername). Throws
// std::runtime_error if the kernel does not say.
Peer peer_of(int fd, bool tcp);

struct AccessOptions {
  std::size_t max_unix = 64;         // Unix connections at once
  std::size_t max_tcp = 16;          // TCP connections at once
  std::size_t max_per_peer = 16;     // per uid (Unix) or address (TCP)
  std::string read_token;            // TCP: reads
  std::string control_token;         // TCP: controls ("" = no TCP client controls)
  long control_gid = -1;             // Unix: this group's members control too (-1 = none)
  uid_t owner_uid = 0;               // the daemon's own user (controls)
  double requests_per_second = 200;  // per peer (and as many at once)
  double connects_per_second = 20;   // per peer (and twice as many at once)
};

// A token bucket: `rate` a second, up to `burst` at once (starts full).
struct RateBucket {
  double tokens = 0;
  std::uint64_t at_ns = 0;
  bool started = false;
  // Refills to `burst` at `rate` a second; true if at least one is there.
  bool refill(double rate, double burst, std::uint64_t now_ns);
  // How long until one is there, at `rate` (after refill).
  std::uint64_t wait_ns(double rate) const;
};

// Whether a local user is in a group: its primary group or a supplementary one.
bool user_in_group(uid_t uid, gid_t primary, gid_t group);

class ClientAccess {
 public:
  static constexpr std::uint64_t kFirstDelayMs = 250;
  static constexpr std::uint64_t kMaxDelayMs = 30'000;
  static constexpr std::size_t kMaxThrottled = 4096;  // addresses remembered

  explicit ClientAccess(AccessOptions options) : options_(std::move(options)) {}
  const AccessOptions& options() const { return options_; }

  // A new connection of a role (TCP: kRead until its hello; Unix: from the
  // peer): "" if it may stay (its slot is then counted; release it with the
  // same role when the connection ends), else why not.
  std::string admit(const Peer& peer, Role role);
  void release(const Peer& peer, Role role);
  std::size_t unix_clients() const { return unix_; }
  std::size_t unix_readers() const { return unix_readers_; }
  // The Unix slots only control may take: 4, or half of max_unix if that is fewer.
  std::size_t control_reserve() const;
  // TCP, at a hello that gives the reading role: "" if a reader may stay
  // (counted; release_tcp_reader() when it ends), else why not. With a
  // control token, readers hold at most max_tcp less min(4, max_tcp / 2).
  std::string admit_tcp_reader();
  void release_tcp_reader();
  std::size_t tcp_readers() const { return tcp_readers_; }
  std::size_t tcp_clients() const { return tcp_; }

  // The role of a Unix peer.
  Role unix_role(const Peer& peer) const;

  // Rates. take_connect: whether the peer may open a connection now (one is
  // counted). may_request: whether it may send a request now, else how long
  // until it may (wait_ns); count_request counts one.
  bool take_connect(const Peer& peer, std::uint64_t now_ns);
  bool may_request(const Peer& peer, std::uint64_t now_ns, std::uint64_t& wait_ns);
  void count_request(const Peer& peer);
  std::size_t rated_peers() const { return rates_.size(); }

  enum class Verdict { kRead, kControl, kWrong, kThrottled };
  // A TCP hello's token from `address` at `now_ns`. kThrottled: not looked
  // at, `wait_ms` says how long the address must still wait.
  Verdict check_token(const std::string& address, const std::string& token, std::uint64_t now_ns,
                      std::uint64_t& wait_ms);
  std::size_t throttled_addresses() const { return throttle_.size(); }

 private:
  AccessOptions options_;
  std::size_t unix_ = 0, tcp_ = 0, unix_readers_ = 0, tcp_readers_ = 0;
  std::map<std::string, std::size_t> per_peer_;
  struct Failures {
    unsigned count = 0;
    std::uint64_t until_ns = 0;  // no token looked at before this
  };
  std::map<std::string, Failures> throttle_;
  struct Rates {
    RateBucket requests, connects;
    std::uint64_t used_ns = 0;
  };
  std::map<std::string, Rates> rates_;
  Rates& rates_of(const Peer& peer, std::uint64_t now_ns);
};

}  // namespace tofmat::daemon
