// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// ClientAccess: peer identification, roles from uid, group or token, connection slots and per-peer rate buckets.
#include "tofmat/daemon/client_access.hpp"

#include <arpa/inet.h>
#include <grp.h>
#include <netinet/in.h>
#include <pwd.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <stdexcept>
#include <system_error>
#include <vector>

namespace tofmat::daemon {
namespace {

// Compares without leaking where the first difference is.
bool same_token(const std::string& a, const std::string& b) {
  unsigned char diff = a.size() == b.size() ? 0 : 1;
  for (std::size_t i = 0; i < a.size(); ++i) diff |= static_cast<unsigned char>(a[i] ^ (i < b.size() ? b[i] : 0));
  return diff == 0 && !a.empty();
}

// A failure is forgotten this long after the address's wait ended.
constexpr std::uint64_t kForgetNs = 600'000'000'000ull;

// Room for one more entry in a map of at most `max` per-peer entries: those
// `stale` go first; if that is not enough, the `earlier` ones one by one.
template <typename Map, typename Stale, typename Earlier>
void make_room(Map& map, std::size_t max, Stale stale, Earlier earlier) {
  if (map.size() < max) return;
  for (auto it = map.begin(); it != map.end();) it = stale(it->second) ? map.erase(it) : std::next(it);
  while (map.size() >= max)
    map.erase(std::min_element(map.begin(), map.end(),
                               [&](const auto& a, const auto& b) { return earlier(a.second, b.second); }));
}

}  // namespace

const char* role_name(Role role) { return role == Role::kControl ? "control" : "read"; }

bool is_reading_command(const std::string& cmd) {
  return cmd == "hello" || cmd == "subscribe" || cmd == "unsubscribe" || cmd == "status" || cmd == "server_status" ||
         cmd == "latest";
}

std::string Peer::key() const { return tcp ? "tcp " + address : "uid " + std::to_string(uid); }

Peer peer_of(int fd, bool tcp) {
  Peer p;
  p.tcp = tcp;
  if (!tcp) {
    ucred cred{};
    socklen_t len = sizeof cred;
    if (::getsockopt(fd, SOL_SOCKET, SO_PEERCRED, &cred, &len) != 0)
      throw std::runtime_error(std::string("SO_PEERCRED: ") + std::generic_category().message(errno));
    p.uid = cred.uid;
    p.gid = cred.gid;
    return p;
  }
  sockaddr_in sa{};
  socklen_t len = sizeof sa;
  if (::getpeername(fd, reinterpret_cast<sockaddr*>(&sa), &len) != 0)
    throw std::runtime_error(std::string("getpeername: ") + std::generic_category().message(errno));
  char text[INET_ADDRSTRLEN] = {};
  if (!::inet_ntop(AF_INET, &sa.sin_addr, text, sizeof text)) throw std::runtime_error("inet_ntop failed");
  p.address = text;
  return p;
}

bool user_in_group(uid_t uid, gid_t primary, gid_t group) {
  if (primary == group) return true;
  // The user's supplementary groups, from the user database (a uid without
  // an entry has none).
  std::vector<char> buf(16384);
  passwd pw{};
  passwd* found = nullptr;
  if (::getpwuid_r(uid, &pw, buf.data(), buf.size(), &found) != 0 || !found) return false;
  int n = 64;
  std::vector<gid_t> groups(static_cast<std::size_t>(n));
  if (::getgrouplist(found->pw_name, primary, groups.data(), &n) < 0) {
    groups.resize(static_cast<std::size_t>(n));
    if (::getgrouplist(found->pw_name, primary, groups.data(), &n) < 0) return false;
  }
  groups.resize(static_cast<std::size_t>(n));
  return std::find(groups.begin(), groups.end(), group) != groups.end();
}

namespace {
// The slots of `max` that only control may take: 4, or half of them if that is fewer.
std::size_t reserve_for_control(std::size_t max) { return std::min<std::size_t>(4, max / 2); }
}  // namespace

std::size_t ClientAccess::control_reserve() const { return reserve_for_control(options_.max_unix); }

std::string ClientAccess::admit(const Peer& peer, Role role) {
  std::size_t& kind = peer.tcp ? tcp_ : unix_;
  const std::size_t max = peer.tcp ? options_.max_tcp : options_.max_unix;
  if (kind >= max) return std::to_string(kind) + (peer.tcp ? " TCP" : " Unix") + " clients connected already";
  const bool unix_reader = !peer.tcp && role == Role::kRead;
  if (unix_reader && unix_readers_ + control_reserve() >= max)
    return std::to_string(unix_readers_) + " reading Unix clients connected already (the last " +
           std::to_string(control_reserve()) + " slots are kept for control)";
  const auto it = per_peer_.find(peer.key());
  const std::size_t mine = it == per_peer_.end() ? 0 : it->second;
  if (mine >= options_.max_per_peer) return peer.key() + " has " + std::to_string(mine) + " connections already";
  ++per_peer_[peer.key()];
  ++kind;
  if (unix_reader) ++unix_readers_;
  return "";
}

std::string ClientAccess::admit_tcp_reader() {
  const std::size_t reserve = options_.control_token.empty() ? 0 : std::min<std::size_t>(4, options_.max_tcp / 2);
  if (tcp_readers_ + reserve >= options_.max_tcp)
    return std::to_string(tcp_readers_) + " reading TCP clients connected already (the last " +
           std::to_string(reserve) + " slots are kept for the control token)";
  ++tcp_readers_;
  return "";
}

void ClientAccess::release_tcp_reader() {
  if (tcp_readers_ > 0) --tcp_readers_;
}

void ClientAccess::release(const Peer& peer, Role role) {
  std::size_t& kind = peer.tcp ? tcp_ : unix_;
  if (kind > 0) --kind;
  if (!peer.tcp && role == Role::kRead && unix_readers_ > 0) --unix_readers_;
  auto it = per_peer_.find(peer.key());
  if (it == per_peer_.end()) return;
  if (--it->second == 0) per_peer_.erase(it);
}

Role ClientAccess::unix_role(const Peer& peer) const {
  if (peer.uid == 0 || peer.uid == options_.owner_uid) return Role::kControl;
  if (options_.control_gid >= 0 && user_in_group(peer.uid, peer.gid, static_cast<gid_t>(options_.control_gid)))
    return Role::kControl;
  return Role::kRead;
}

bool RateBucket::refill(double rate, double burst, std::uint64_t now_ns) {
  if (!started) {
    started = true;
    tokens = burst;
  } else if (now_ns > at_ns) {
    tokens = std::min(burst, tokens + rate * static_cast<double>(now_ns - at_ns) * 1e-9);
  }
  at_ns = std::max(at_ns, now_ns);
  return tokens >= 1.0;
}

std::uint64_t RateBucket::wait_ns(double rate) const {
  return tokens >= 1.0 ? 0 : static_cast<std::uint64_t>((1.0 - tokens) / rate * 1e9) + 1;
}

ClientAccess::Rates& ClientAccess::rates_of(const Peer& peer, std::uint64_t now_ns) {
  const std::string key = peer.key();
  auto it = rates_.find(key);
  if (it == rates_.end()) {
    // A peer idle for long enough has full buckets again: forgetting it changes nothing.
    make_room(
        rates_, kMaxThrottled, [&](const Rates& r) { return now_ns > r.used_ns + 10'000'000'000ull; },
        [](const Rates& a, const Rates& b) { return a.used_ns < b.used_ns; });
    it = rates_.emplace(key, Rates{}).first;
  }
  it->second.used_ns = now_ns;
  return it->second;
}

bool ClientAccess::take_connect(const Peer& peer, std::uint64_t now_ns) {
  RateBucket& b = rates_of(peer, now_ns).connects;
  if (!b.refill(options_.connects_per_second, 2 * options_.connects_per_second, now_ns)) return false;
  b.tokens -= 1.0;
  return true;
}

bool ClientAccess::may_request(const Peer& peer, std::uint64_t now_ns, std::uint64_t& wait_ns) {
  RateBucket& b = rates_of(peer, now_ns).requests;
  if (b.refill(options_.requests_per_second, options_.requests_per_second, now_ns)) return true;
  wait_ns = b.wait_ns(options_.requests_per_second);
  return false;
}

void ClientAccess::count_request(const Peer& peer) {
  auto it = rates_.find(peer.key());
  if (it != rates_.end()) it->second.requests.tokens -= 1.0;
}

ClientAccess::Verdict ClientAccess::check_token(const std::string& address, const std::string& token,
                                                std::uint64_t now_ns, std::uint64_t& wait_ms) {
  wait_ms = 0;
  auto it = throttle_.find(address);
  if (it != throttle_.end() && now_ns > it->second.until_ns + kForgetNs)
    it->second.count = 0;  // long quiet: a fresh start
  if (it != throttle_.end() && now_ns < it->second.until_ns) {
    wait_ms = (it->second.until_ns - now_ns + 999'999) / 1'000'000;
    return Verdict::kThrottled;
  }
  // (Both compared, whichever matches: the time taken says nothing of which.)
  const bool control = same_token(token, options_.control_token);
  const bool read = same_token(token, options_.read_token);
  if (control || read) {
    if (it != throttle_.end()) throttle_.erase(it);
    return control ? Verdict::kControl : Verdict::kRead;
  }
  if (it == throttle_.end()) {
    // (Still full of addresses failing at once: the one free soonest goes.)
    make_room(
        throttle_, kMaxThrottled, [&](const Failures& f) { return now_ns > f.until_ns + kForgetNs; },
        [](const Failures& a, const Failures& b) { return a.until_ns < b.until_ns; });
    it = throttle_.emplace(address, Failures{}).first;
  }
  Failures& f = it->second;
  f.count = std::min(f.count + 1, 32u);
  const std::uint64_t delay_ms = std::min(kFirstDelayMs << std::min(f.count - 1, 16u), kMaxDelayMs);
  f.until_ns = now_ns + delay_ms * 1'000'000ull;
  return Verdict::kWrong;
}

}  // namespace tofmat::daemon
