// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The C++ client of tofmatd (what the Python tofmat.Client is built on):
// connects by Unix socket path or host:port, does the hello handshake (with
// the token over TCP), sends commands and waits for their replies, and hands
// out the events it subscribed to in order. Blocking, with timeouts; one
// thread at a time.
#pragma once
#include <cstdint>
#include <deque>
#include <optional>
#include <string>

#include "tofmat/protocol/messages.hpp"
#include "tofmat/protocol/socket.hpp"

namespace tofmat::protocol {

enum class ClientErrorKind {
  kRefused,   // nothing listens at the address (or the socket file is missing)
  kTimeout,   // no answer within the timeout
  kVersion,   // the daemon speaks another protocol version
  kAuth,      // the daemon refused the token (TCP)
  kProtocol,  // the daemon sent something the protocol does not allow
  kClosed,    // the connection went away (daemon stopped or restarted)
  kCommand,   // the daemon answered a command with an error (code())
};
const char* client_error_kind_name(ClientErrorKind kind);

class ClientError : public std::runtime_error {
 public:
  ClientError(ClientErrorKind kind, const std::string& what, std::string code = "")
      : std::runtime_error(what), kind_(kind), code_(std::move(code)) {}
  ClientErrorKind kind() const { return kind_; }
  const std::string& code() const { return code_; }  // kCommand: the reply's code

 private:
  ClientErrorKind kind_;
  std::string code_;
};

struct ClientOptions {
  std::string token;      // required by a daemon listening on TCP
  int timeout_ms = 5000;  // connect, handshake and each command
  // What the client keeps of the events that arrive while a command waits
  // for its reply (handed out later by next_event()): a peer that streams
  // events and never answers cannot grow the client past these. Beyond
  // either bound the oldest kept event is dropped and counted.
  std::size_t max_pending_events = 1024;
  std::size_t max_pending_bytes = 64u << 20;  // as held in memory (pending_bytes())
};

class Client {
 public:
  // Connects and completes the handshake. Throws ClientError.
  explicit Client(const std::string& address, ClientOptions options = {});
  // Completes the handshake on a socket that is already connected (one end
  // of a socketpair: tests and the client's fuzz target). Throws ClientError.
  Client(Fd connected, const Address& address, ClientOptions options = {});
  const Hello& hello() const { return hello_; }
  // What the daemon lets this connection do: "read" (subscribe, status) or
  // "control" (also profile, ROI, candidates, trigger, reset, load_table).
  // A daemon that does not say has no roles: every client controls.
  const std::string& role() const { return role_; }
  const Address& address() const { return address_; }
  // Sends a command and returns its result; events arriving meanwhile are
  // kept for next_event(). Throws ClientError (kCommand with the daemon's
  // code when it answered with an error).
  Json request(const std::string& cmd, const Json& args = Json::object());
  // The next event, or nothing after timeout_ms (< 0: wait forever).
  std::optional<Message> next_event(int timeout_ms);
  // The events kept while commands waited (the daemon drops for slow
  // clients and reports it in status; these are the client's own).
  std::size_t pending_events() const { return events_.size(); }
  // Their size in memory, as counted against max_pending_bytes: the blob
  // and 16 bytes per byte of metadata (a parsed JSON value's worst case).
  std::size_t pending_bytes() const { return pending_bytes_; }
  // Events dropped because the kept ones reached a bound.
  std::uint64_t dropped_events() const { return dropped_events_; }
  bool connected() const { return static_cast<bool>(fd_); }
  void close() { fd_.reset(); }

 private:
  // One message from the socket, or nothing after timeout_ms. Throws ClientError.
  std::optional<Message> read_message(int timeout_ms);
  void send(const Message& m);
  void handshake();
  // Keeps an event for next_event(), dropping the oldest past the bounds.
  void keep_event(Message&& m);

  Address address_;
  ClientOptions options_;
  Fd fd_;
  MessageReader reader_;
  Hello hello_;
  std::string role_ = "control";
  std::deque<Message> events_;
  std::size_t pending_bytes_ = 0;
  std::uint64_t dropped_events_ = 0;
  std::uint32_t next_id_ = 1;
};

}  // namespace tofmat::protocol
