// SPDX-License-Identifier: LicenseRef-tofmat-proprietary
// Client: connecting, the hello handshake, requests with their replies, and the queue of subscribed events.
#include "tofmat/protocol/client.hpp"

#include <sys/socket.h>

#include <cerrno>
#include <chrono>

namespace tofmat::protocol {
namespace {

using Clock = std::chrono::steady_clock;

// A kept event's weight against max_pending_bytes: its blob, and its metadata
// at 16 bytes in memory per byte on the wire (nlohmann's values are 16 bytes;
// a "[0,0,...]" array's elements take 2 bytes each on the wire).
std::size_t held_bytes(const Message& m) {
  const std::size_t meta_wire = m.wire_bytes > m.blob.size() ? m.wire_bytes - m.blob.size() : 0;
  return m.blob.size() + 16 * meta_wire;
}

int ms_left(Clock::time_point deadline) {
  const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
  return left < 0 ? 0 : static_cast<int>(left);
}

}  // namespace

const char* client_error_kind_name(ClientErrorKind kind) {
  switch (kind) {
    case ClientErrorKind::kRefused: return "refused";
    case ClientErrorKind::kTimeout: return "timeout";
    case ClientErrorKind::kVersion: return "version";
    case ClientErrorKind::kAuth: return "auth";
    case ClientErrorKind::kProtocol: return "protocol";
    case ClientErrorKind::kClosed: return "closed";
    case ClientErrorKind::kCommand: return "command";
  }
  return "unknown";
}

Client::Client(const std::string& address, ClientOptions options) : options_(std::move(options)) {
  try {
    address_ = parse_address(address);
  } catch (const std::invalid_argument& e) {
    throw ClientError(ClientErrorKind::kRefused, e.what());
  }
  try {
    fd_ = connect_to(address_, options_.timeout_ms);
  } catch (const SocketError& e) {
    if (e.os_error() == ETIMEDOUT)
      throw ClientError(ClientErrorKind::kTimeout, std::string("tofmatd at ") + address_.describe() +
                                                       " did not accept the connection in time: " + e.what());
    throw ClientError(ClientErrorKind::kRefused, std::string("cannot connect to tofmatd at ") + address_.describe() +
                                                     " (is it running?): " + e.what());
  }
  handshake();
}

Client::Client(Fd connected, const Address& address, ClientOptions options)
    : address_(address), options_(std::move(options)), fd_(std::move(connected)) {
  handshake();
}

void Client::handshake() {
  const auto first = read_message(options_.timeout_ms);
  if (!first) throw ClientError(ClientErrorKind::kTimeout, "tofmatd at " + address_.describe() + " sent no hello");
  try {
    hello_ = decode_hello(*first);
  } catch (const ProtocolError& e) {
    throw ClientError(ClientErrorKind::kProtocol, std::string("bad hello from tofmatd: ") + e.what());
  }
  if (hello_.protocol != kProtocolVersion)
    throw ClientError(ClientErrorKind::kVersion, "tofmatd speaks protocol version " + std::to_string(hello_.protocol) +
                                                     ", this client " + std::to_string(kProtocolVersion));
  Json args = {{"protocol", kProtocolVersion}, {"client", "tofmat-client"}};
  if (!options_.token.empty()) args["token"] = options_.token;
  try {
    const Json result = request("hello", args);
    // The reply says the major again (docs/protocol.md, hello): it must be the one both sides framed with.
    if (result.contains("protocol") &&
        (!result["protocol"].is_number_unsigned() || result["protocol"].get<std::uint64_t>() != kProtocolVersion)) {
      fd_.reset();
      throw ClientError(ClientErrorKind::kVersion, "tofmatd's hello reply claims protocol version " +
                                                       printable(result["protocol"].dump()) + ", this client speaks " +
                                                       std::to_string(kProtocolVersion));
    }
    if (result.contains("role") && result["role"].is_string()) role_ = result["role"].get<std::string>();
  } catch (const ClientError& e) {
    if (e.kind() == ClientErrorKind::kCommand && e.code() == codes::kAuth)
      throw ClientError(ClientErrorKind::kAuth, e.what(), e.code());
    if (e.kind() == ClientErrorKind::kCommand && e.code() == codes::kVersion)
      throw ClientError(ClientErrorKind::kVersion, e.what(), e.code());
    if (e.kind() == ClientErrorKind::kCommand && e.code() == codes::kFull)  // (as a connection over a limit)
      throw ClientError(ClientErrorKind::kRefused, e.what(), e.code());
    throw;
  }
}

void Client::send(const Message& m) {
  if (!fd_) throw ClientError(ClientErrorKind::kClosed, "the connection to tofmatd is closed");
  const auto bytes = encode(m);
  try {
    write_all(fd_.get(), bytes.data(), bytes.size(), options_.timeout_ms);
  } catch (const SocketError& e) {
    fd_.reset();
    if (e.os_error() == ETIMEDOUT) throw ClientError(ClientErrorKind::kTimeout, e.what());
    throw ClientError(ClientErrorKind::kClosed, std::string("connection to tofmatd lost: ") + e.what());
  }
}

void Client::keep_event(Message&& m) {
  pending_bytes_ += held_bytes(m);
  events_.push_back(std::move(m));
  while (!events_.empty() &&
         (events_.size() > options_.max_pending_events || pending_bytes_ > options_.max_pending_bytes)) {
    pending_bytes_ -= held_bytes(events_.front());
    events_.pop_front();
    ++dropped_events_;
  }
}

std::optional<Message> Client::read_message(int timeout_ms) {
  const auto deadline =
      timeout_ms < 0 ? Clock::time_point::max() : Clock::now() + std::chrono::milliseconds(timeout_ms);
  for (;;) {
    try {
      if (auto m = reader_.next()) return m;
    } catch (const VersionError& e) {
      fd_.reset();
      throw ClientError(ClientErrorKind::kVersion, std::string("tofmatd: ") + e.what());
    } catch (const ProtocolError& e) {
      fd_.reset();
      throw ClientError(ClientErrorKind::kProtocol, std::string("malformed message from tofmatd: ") + e.what());
    }
    if (!fd_) throw ClientError(ClientErrorKind::kClosed, "the connection to tofmatd is closed");
    const int wait = timeout_ms < 0 ? -1 : ms_left(deadline);
    if (!wait_readable(fd_.get(), wait)) return std::nullopt;
    std::uint8_t buf[65536];
    const ssize_t n = ::recv(fd_.get(), buf, sizeof buf, 0);
    if (n == 0 || (n < 0 && errno != EAGAIN && errno != EINTR)) {
      fd_.reset();
      throw ClientError(ClientErrorKind::kClosed, "tofmatd closed the connection");
    }
    if (n > 0) reader_.feed(buf, static_cast<std::size_t>(n));
  }
}

Json Client::request(const std::string& cmd, const Json& args) {
  Request r;
  r.id = next_id_++;
  r.cmd = cmd;
  r.args = args;
  send(encode_request(r));
  const auto deadline = Clock::now() + std::chrono::milliseconds(options_.timeout_ms);
  const auto timed_out = [&] {
    return ClientError(ClientErrorKind::kTimeout, "tofmatd did not answer \"" + cmd + "\" in time");
  };
  for (;;) {
    // (checked here too: a peer that never stops sending would otherwise keep read_message() busy forever)
    if (Clock::now() >= deadline) throw timed_out();
    auto m = read_message(ms_left(deadline));
    if (!m) throw timed_out();
    if (m->type == MessageType::kEvent) {
      keep_event(std::move(*m));
      continue;
    }
    Reply reply;
    try {
      reply = decode_reply(*m);
    } catch (const ProtocolError& e) {
      fd_.reset();
      throw ClientError(ClientErrorKind::kProtocol, std::string("malformed reply from tofmatd: ") + e.what());
    }
    if (reply.id != r.id) continue;  // a late reply to a command that timed out
    if (!reply.ok) throw ClientError(ClientErrorKind::kCommand, cmd + ": " + printable(reply.error), reply.code);
    return reply.result;
  }
}

std::optional<Message> Client::next_event(int timeout_ms) {
  if (!events_.empty()) {
    Message m = std::move(events_.front());
    events_.pop_front();
    pending_bytes_ -= held_bytes(m);
    return m;
  }
  const auto deadline =
      timeout_ms < 0 ? Clock::time_point::max() : Clock::now() + std::chrono::milliseconds(timeout_ms);
  for (bool first = true;; first = false) {
    // (a stream of replies nobody waits for must not hold the wait past its deadline)
    if (!first && timeout_ms >= 0 && Clock::now() >= deadline) return std::nullopt;
    auto m = read_message(timeout_ms < 0 ? -1 : ms_left(deadline));
    if (!m) return std::nullopt;
    if (m->type == MessageType::kEvent) return m;
    // A reply nobody waits for any more: skip.
  }
}

}  // namespace tofmat::protocol
