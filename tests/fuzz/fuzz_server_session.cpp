// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// libFuzzer target: tofmatd's socket server (firmware/daemon/server.hpp) on
// sequences of requests, as one client sends them over a real connection:
// one Server, started once, on a Unix socket and on TCP 127.0.0.1 with a
// reading and a control token, answering every command it passes on with
// {"handled": true}. Each input is one connection:
//
//   byte 0 % 4: 0 Unix, the input does the hello itself;
//               1 Unix after this harness's hello (the daemon's user: control);
//               2 TCP after a hello with the reading token;
//               3 TCP after a hello with the control token
//   byte 1:     the size of the pieces the rest is sent in (1..256)
//   the rest:   bytes sent to the server as they are; then the write side is
//               shut and everything the server sends is read until it closes.
//
// Oracles:
//  - the server closes the connection once the client's side is shut (a
//    connection that hangs is a finding), and serves a new client after it;
//  - everything it sends parses, and after its hello is only replies;
//  - the replies answer the input's own requests (parsed here with the same
//    limits), in order, one each, until the connection ends;
//  - a reading connection's command that is not a reading one never reaches
//    the handler: its reply is the "permission" refusal;
//  - nothing reaches the handler before a successful hello.
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "tofmat/daemon/client_access.hpp"
#include "tofmat/daemon/server.hpp"
#include "tofmat/protocol/messages.hpp"
#include "tofmat/protocol/socket.hpp"
#include "tofmat/protocol/wire.hpp"

namespace {

using namespace tofmat::protocol;
using Bytes = std::vector<std::uint8_t>;

const std::string kReadToken = "fuzz-read-token-0123456789";
const std::string kControlToken = "fuzz-control-token-0123456789";
constexpr int kPatienceMs = 5000;

struct Harness {
  std::string dir, socket_path;
  std::unique_ptr<tofmat::daemon::Server> server;
  std::atomic<bool> stop{false};
  std::thread thread;

  Harness() {
    char tmpl[] = "/tmp/tofmat-fuzz-server-XXXXXX";
    if (!::mkdtemp(tmpl)) std::abort();
    dir = tmpl;
    socket_path = dir + "/s.sock";
    tofmat::daemon::ServerOptions o;
    o.socket_path = socket_path;
    o.tcp = "127.0.0.1:0";
    o.token = kReadToken;
    o.control_token = kControlToken;
    o.hello_timeout_ms = 2000;
    o.peer_request_rate = o.peer_connect_rate = 1e9;  // (one peer, this process, a thousand connections a second)
    server = std::make_unique<tofmat::daemon::Server>(o, [](const Request& r) {
      Reply rep;
      rep.id = r.id;
      rep.result = {{"handled", true}};
      return rep;
    });
    thread = std::thread([this] { server->run(stop); });
  }
  std::string tcp_address() const { return "127.0.0.1:" + std::to_string(server->tcp_port()); }
};

Harness& harness() {
  static Harness* h = new Harness();  // (lives for the whole run: the server must keep up across inputs)
  return *h;
}

// Reads messages from fd until the peer closes; traps on a hang or on bytes that do not parse.
std::vector<Message> read_until_closed(int fd) {
  std::vector<Message> out;
  MessageReader reader(kMaxPayloadBytes);
  for (;;) {
    if (!wait_readable(fd, kPatienceMs)) __builtin_trap();  // the server did not close
    std::uint8_t buf[65536];
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n == 0 || (n < 0 && errno == ECONNRESET)) break;
    if (n < 0) {
      if (errno == EINTR || errno == EAGAIN) continue;
      __builtin_trap();
    }
    reader.feed(buf, static_cast<std::size_t>(n));
    while (auto m = reader.next()) out.push_back(std::move(*m));  // a ProtocolError escapes: a finding
  }
  if (reader.buffered() != 0) __builtin_trap();  // half a message, then the close
  return out;
}

// The requests a server can make out of `bytes` (the same limits as its reader).
std::vector<std::optional<Request>> requests_in(const std::uint8_t* data, std::size_t size) {
  std::vector<std::optional<Request>> out;
  MessageReader reader(kMaxRequestPayloadBytes);
  try {
    reader.feed(data, size);
    while (auto m = reader.next()) {
      try {
        out.push_back(decode_request(*m));
      } catch (const ProtocolError&) {
        out.push_back(std::nullopt);  // the server closes here
        return out;
      }
    }
  } catch (const ProtocolError&) {
  }
  return out;
}

Bytes hello_request(const std::string& token) {
  Request r;
  r.id = 1;
  r.cmd = "hello";
  r.args = {{"protocol", kProtocolVersion}};
  if (!token.empty()) r.args["token"] = token;
  return encode(encode_request(r));
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 2) return 0;
  Harness& h = harness();
  const int mode = data[0] % 4;
  const std::size_t piece = 1 + data[1];
  data += 2;
  size -= 2;
  const bool tcp = mode >= 2;
  Fd fd = connect_to(parse_address(tcp ? h.tcp_address() : h.socket_path), kPatienceMs);
  Bytes prefix;
  if (mode == 1) prefix = hello_request("");
  if (mode == 2) prefix = hello_request(kReadToken);
  if (mode == 3) prefix = hello_request(kControlToken);
  try {
    if (!prefix.empty()) write_all(fd.get(), prefix.data(), prefix.size(), kPatienceMs);
    for (std::size_t at = 0; at < size; at += piece)
      write_all(fd.get(), data + at, std::min(piece, size - at), kPatienceMs);
  } catch (const SocketError&) {
    // The server closed early (a malformed request, a refused hello): what it sent still counts.
  }
  ::shutdown(fd.get(), SHUT_WR);
  const std::vector<Message> got = read_until_closed(fd.get());

  // Hello first, then replies only.
  if (got.empty() || got[0].type != MessageType::kHello) __builtin_trap();
  std::vector<Reply> replies;
  for (std::size_t i = 1; i < got.size(); ++i) {
    if (got[i].type != MessageType::kReply) __builtin_trap();
    replies.push_back(decode_reply(got[i]));
  }
  // The requests, the harness's hello first.
  std::vector<std::optional<Request>> sent;
  if (!prefix.empty()) sent.push_back(requests_in(prefix.data(), prefix.size())[0]);
  for (auto& r : requests_in(data, size)) sent.push_back(std::move(r));
  if (replies.size() > sent.size()) __builtin_trap();  // a reply nobody asked for
  bool ready = false;
  bool control = !tcp;  // (Unix: this process's own user)
  for (std::size_t i = 0; i < replies.size(); ++i) {
    const Reply& rep = replies[i];
    if (!sent[i]) __builtin_trap();  // answered a request that does not decode
    const Request& req = *sent[i];
    if (rep.id != req.id) __builtin_trap();
    const bool handled = rep.ok && rep.result.is_object() && rep.result.contains("handled");
    if (!ready) {
      if (handled) __builtin_trap();  // the handler before hello
      if (req.cmd == "hello" && rep.ok) {
        ready = true;
        if (tcp) control = rep.result.value("role", "") == "control";
        if (rep.result.value("role", "") != (control ? "control" : "read")) __builtin_trap();
      }
      continue;
    }
    if (!control && !tofmat::daemon::is_reading_command(req.cmd) && (handled || rep.code != codes::kPermission))
      __builtin_trap();
    if (control && req.cmd != "hello" && !tofmat::daemon::is_reading_command(req.cmd) && !handled) __builtin_trap();
  }
  // The server is still there for the next client.
  Fd again = connect_to(parse_address(h.socket_path), kPatienceMs);
  const Bytes hello = hello_request("");
  write_all(again.get(), hello.data(), hello.size(), kPatienceMs);
  ::shutdown(again.get(), SHUT_WR);
  if (read_until_closed(again.get()).size() != 2) __builtin_trap();
  return 0;
}
