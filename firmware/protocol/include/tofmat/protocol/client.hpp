// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// The C++ client of tofmatd (what the Python tofmat.Client is built on):
// connects by Unix socket path or host:port, does the hello handshake (with
// the token over TCP), sends commands and waits for their replies, and hands
// out the events it subscribed to in order. Blocking, with timeouts; one
// thread at a time.
#pragma once
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
};

class Client {
 public:
  // Connects and completes the handshake. Throws ClientError.
  explicit Client(const std::string& address, ClientOptions options = {});
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
  // Events dropped by the client side? None: the daemon drops for slow
  // clients and reports it in status; this is what is buffered here.
  std::size_t pending_events() const { return events_.size(); }
  bool connected() const { return static_cast<bool>(fd_); }
  void close() { fd_.reset(); }

 private:
  // One message from the socket, or nothing after timeout_ms. Throws ClientError.
  std::optional<Message> read_message(int timeout_ms);
  void send(const Message& m);

  Address address_;
  ClientOptions options_;
  Fd fd_;
  MessageReader reader_;
  Hello hello_;
  std::string role_ = "control";
  std::deque<Message> events_;
  std::uint32_t next_id_ = 1;
};

}  // namespace tofmat::protocol
