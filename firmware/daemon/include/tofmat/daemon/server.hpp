// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// tofmatd's socket server: one thread polling the listening sockets (Unix,
// and TCP when configured), every client connection and a wake-up eventfd.
// It does the hello handshake (protocol version; the token on TCP), keeps
// each client's subscriptions, passes commands to the daemon's handler, and
// fans published events out to the subscribers. Every client has a bounded
// send queue: a client that does not read loses its oldest events (counted;
// replies are never dropped, a client that lets them pile up is closed), and
// never slows the pipeline or the other clients. A malformed message, a
// failed handshake or a hello that does not come in time closes that
// connection only. Serving is fair: each poll round a connection gets one
// bounded read and a bounded number of requests handled, so a client that
// pipelines requests without end delays nobody else's events; lines about
// clients are rate-limited per kind. Who may connect, how many at once and
// what each may do is ClientAccess's (roles, per-kind and per-peer slots,
// token throttling); a connection that after its hello neither asks nor
// subscribes, or stops taking what it is sent, is closed after the idle
// timeout.
#pragma once
#include <atomic>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include <spdlog/common.h>
#include <nlohmann/json.hpp>

#include "tofmat/daemon/client_access.hpp"
#include "tofmat/daemon/log_limiter.hpp"
#include "tofmat/protocol/messages.hpp"
#include "tofmat/protocol/socket.hpp"

namespace tofmat::daemon {

struct ServerOptions {
  std::string socket_path;  // "" = no Unix socket
  unsigned socket_mode = 0660;
  std::string tcp;               // "host:port" ("" = no TCP); needs a token
  std::string token;             // TCP: reads
  std::string control_token;     // TCP: controls ("" = no TCP client controls)
  long control_gid = -1;         // Unix: members of this group control too (the daemon's user and root always do)
  std::size_t max_clients = 64;  // Unix connections at once
  std::size_t max_tcp_clients = 16;
  std::size_t max_clients_per_peer = 16;    // per uid (Unix) or address (TCP)
  double peer_request_rate = 200;           // requests a second per peer (and as many at once)
  double peer_connect_rate = 20;            // new connections a second per peer (and twice as many at once)
  std::size_t max_queue_bytes = 16u << 20;  // per client
  int hello_timeout_ms = 5000;
  // After hello: no request and no subscription for this long, or queued
  // bytes the client has not taken for this long, closes it (0 = never).
  int idle_timeout_ms = 60000;
  std::string server_name = "tofmatd";
  std::vector<std::string> capabilities;
};

class Server {
 public:
  // All peers together, per listener: connections accepted a second (and as
  // many at once). Beyond it the listener is not watched until its budget
  // refills: new connects wait in the kernel (a Unix client in connect, for
  // at most the backlog's protocol::kUnixBacklog accepts), which costs the
  // server nothing, where accepting and closing a client that connects in a
  // loop cost the server thread half a core (docs/benchmarks.md).
  static constexpr double kAcceptsPerSecond = 1000;
  using Handler = std::function<protocol::Reply(const protocol::Request&)>;
  // Opens the listening sockets; throws protocol::SocketError / std::invalid_argument.
  Server(ServerOptions options, Handler handler);
  ~Server();

  // Any thread: queue a message for every subscriber of `stream`.
  void publish(const std::string& stream, const protocol::Message& message);
  // The same for a message already encoded (protocol::encode_label_wire):
  // kept as bytes for `latest` too, decoded only when a client polls.
  void publish(const std::string& stream, std::vector<std::uint8_t> wire);
  // Any thread: `latest` has no event of `stream` until the next is published
  // (after a reset or a new table, the last label is no longer what the
  // daemon would say).
  void forget(const std::string& stream);
  // Whether anyone is subscribed (cheap: the profile skips work nobody wants).
  bool has_subscribers(const std::string& stream) const;
  void run(const std::atomic<bool>& stop);
  void wake();
  std::uint16_t tcp_port() const { return tcp_port_; }
  nlohmann::json status() const;

 private:
  struct Connection;
  void accept_from(int listener, bool tcp);
  void read_from(Connection& c, bool readable);
  // A line about a client, rate-limited per kind (LogLimiter).
  void note(const char* kind, spdlog::level::level_enum level, const std::string& text);
  void handle(Connection& c, const protocol::Message& m);
  void reply(Connection& c, const protocol::Reply& r);
  void enqueue(Connection& c, std::shared_ptr<const std::vector<std::uint8_t>> bytes, bool event);
  // A published event's bytes: kept for `latest` (a pollable stream) and queued for its subscribers.
  void keep_and_queue(const std::string& stream, const std::shared_ptr<const std::vector<std::uint8_t>>& bytes);
  void write_to(Connection& c);
  void refresh_subscriptions();
  void count_clients();  // the counts status() reads (clients_, unix_clients_, tcp_clients_)

  ServerOptions options_;
  Handler handler_;
  protocol::Fd unix_, tcp_;
  protocol::WakeFd wake_fd_;
  std::pair<std::uint64_t, std::uint64_t> socket_file_{0, 0};  // (device, inode) of the socket file bound
  std::uint16_t tcp_port_ = 0;
  std::map<std::uint64_t, std::unique_ptr<Connection>> connections_;  // server thread only
  std::uint64_t next_id_ = 1;
  std::size_t rotation_ = 0;  // where a poll round starts among the connections (server thread only)
  // Published messages waiting for the server thread (bounded, oldest dropped).
  mutable std::mutex inbox_mutex_;
  std::vector<std::pair<std::string, std::shared_ptr<const std::vector<std::uint8_t>>>> inbox_;
  std::set<std::string> subscribed_;  // union of all clients' streams (under inbox_mutex_)
  // The last event of each pollable stream, as published (under inbox_mutex_).
  std::map<std::string, std::shared_ptr<const std::vector<std::uint8_t>>> latest_;
  // Counters.
  std::atomic<std::uint64_t> accepted_{0}, rejected_{0}, protocol_errors_{0}, auth_failures_{0}, auth_throttled_{0},
      not_permitted_{0}, idle_closed_{0}, dropped_events_{0}, inbox_dropped_{0};
  std::atomic<std::size_t> clients_{0}, unix_clients_{0}, unix_readers_{0}, tcp_clients_{0}, tcp_readers_{0};
  ClientAccess access_;                    // server thread only (after the constructor)
  LogLimiter log_limiter_;                 // server thread only
  RateBucket unix_accepts_, tcp_accepts_;  // connections accepted, all peers (server thread only)
  std::atomic<std::uint64_t> log_suppressed_{0};
};

}  // namespace tofmat::daemon
